"""Logging of the ecatsim commands (``run``, ``tmcl``, ``lin``): one ``--log-format`` option
and one structlog setup for all of them."""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from typing import Any, TextIO, TypeVar

import click
import structlog

from ecatsim.logqueue import LogQueue, holding_logger, timestamp

F = TypeVar("F", bound=Callable[..., Any])

#: ``--log-format auto|console|json`` (auto: console)
log_format_option: Callable[[F], F] = click.option(
    "--log-format",
    type=click.Choice(["auto", "console", "json"]),
    default="auto",
    show_default=True,
)


def configure_logging(fmt: str, level: int = logging.INFO, file: TextIO | None = None) -> LogQueue:
    """structlog: pretty on a TTY, JSON with --log-format json, plain text otherwise
    (``auto`` is ``console``), to ``file`` (standard error by default). Returns the queue
    that holds lines while a daemon serves frames (ecatsim/logqueue.py; inactive until the
    daemon sets it)."""
    queue = LogQueue()
    out = file if file is not None else sys.stderr
    processors: list[Any] = [
        structlog.contextvars.merge_contextvars,
        structlog.processors.add_log_level,
        timestamp,
    ]
    if fmt == "json":
        processors += [structlog.processors.dict_tracebacks, structlog.processors.JSONRenderer()]
    else:
        colors = fmt in ("console", "auto") and out.isatty()
        processors += [structlog.dev.ConsoleRenderer(colors=colors)]
    structlog.configure(
        processors=processors,
        wrapper_class=holding_logger(level, queue),
        logger_factory=structlog.PrintLoggerFactory(file=out),
        cache_logger_on_first_use=False,
    )
    return queue

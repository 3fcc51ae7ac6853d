"""Logging of the ecatsim commands (``run``, ``tmcl``, ``lin``): one ``--log-format`` option
and one structlog setup for all of them."""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from typing import Any, TypeVar

import click
import structlog

F = TypeVar("F", bound=Callable[..., Any])

#: ``--log-format auto|console|json`` (auto: console)
log_format_option: Callable[[F], F] = click.option(
    "--log-format",
    type=click.Choice(["auto", "console", "json"]),
    default="auto",
    show_default=True,
)


def configure_logging(fmt: str, level: int = logging.INFO) -> None:
    """structlog: pretty on a TTY, JSON with --log-format json, plain text otherwise
    (``auto`` is ``console``)."""
    processors: list[Any] = [
        structlog.contextvars.merge_contextvars,
        structlog.processors.add_log_level,
        structlog.processors.TimeStamper(fmt="iso", utc=True),
    ]
    if fmt == "json":
        processors += [structlog.processors.dict_tracebacks, structlog.processors.JSONRenderer()]
    else:
        colors = fmt in ("console", "auto") and sys.stderr.isatty()
        processors += [structlog.dev.ConsoleRenderer(colors=colors)]
    structlog.configure(
        processors=processors,
        wrapper_class=structlog.make_filtering_bound_logger(level),
        logger_factory=structlog.PrintLoggerFactory(file=sys.stderr),
        cache_logger_on_first_use=False,
    )

"""Log lines held while the daemon serves frames, written when it has nothing else to do.

Rendering and writing one structlog line costs 30-70 us. The firmware of a large segment
logs many at once: 128 drives enabled by the same cycle log 128 ``pds_state`` lines inside
one SYNC0 pulse, and a bring-up to OP logs an ``al_state`` line per slave. Written then,
they would hold a frame's reply for milliseconds. While the daemon serves
(:attr:`LogQueue.active`), a log call only keeps its arguments and its time (about 1 us);
the lines are rendered, in order and with the time of the call, by :meth:`LogQueue.drain`
after the replies, stopping for a frame that waits (decision P37). A call with
``exc_info`` (an exception's traceback, gone later) and every call while the daemon does
not serve are written at once, after the lines held before them.
"""

from __future__ import annotations

import datetime
import logging
import time
from collections import deque
from collections.abc import Callable, MutableMapping
from typing import Any

#: held lines beyond which a call writes them all at once rather than hold more (a flood
#: of lines with no idle time to write them in must not grow without bound)
MAX_HELD = 20_000
#: the key that carries a held call's time to the time stamp processor
HELD_AT = "_held_at"

#: the bound logger methods that may be held, with their levels
_LEVELS = {
    "debug": logging.DEBUG,
    "info": logging.INFO,
    "msg": logging.INFO,
    "warning": logging.WARNING,
    "warn": logging.WARNING,
    "error": logging.ERROR,
    "critical": logging.CRITICAL,
    "fatal": logging.CRITICAL,
}


class LogQueue:
    """The lines held while :attr:`active`, written by :meth:`drain`."""

    def __init__(self, limit: int = MAX_HELD) -> None:
        #: hold lines (the daemon serves frames)
        self.active = False
        self.limit = limit
        #: (bound logger, method name, event, keyword arguments) in call order
        self.held: deque[tuple[Any, str, str, dict[str, Any]]] = deque()
        #: the unbound methods that render and write a line, by name
        self.write: dict[str, Callable[..., Any]] = {}

    def __len__(self) -> int:
        return len(self.held)

    def drain(self, stop: Callable[[], bool] | None = None) -> int:
        """Write the held lines in order, until none is left or ``stop()`` is true (asked
        before each line: a frame waits). Returns how many were written."""
        held = self.held
        done = 0
        while held:
            if stop is not None and stop():
                break
            logger, name, event, kw = held.popleft()
            self.write[name](logger, event, **kw)
            done += 1
        return done


def holding_logger(level: int, queue: LogQueue) -> type:
    """structlog's filtering bound logger for ``level`` whose calls at or above it are
    held in ``queue`` while it is active (see the module docstring)."""
    import structlog

    base: Any = structlog.make_filtering_bound_logger(level)
    methods: dict[str, Callable[..., Any]] = {}
    for name, lvl in _LEVELS.items():
        if lvl < level:
            continue  # the base's method drops it: nothing to hold
        write = getattr(base, name)
        queue.write[name] = write
        methods[name] = _holding(name, write, queue)
    return type("HoldingBoundLogger", (base,), methods)


def _holding(name: str, write: Callable[..., Any], queue: LogQueue) -> Callable[..., Any]:
    def method(self: Any, event: str, *args: Any, **kw: Any) -> Any:
        if queue.active and not args and "exc_info" not in kw:
            held = queue.held
            if len(held) < queue.limit:
                kw[HELD_AT] = time.time()
                held.append((self, name, event, kw))
                return None
        if queue.held:
            queue.drain()  # the lines before this one first
        return write(self, event, *args, **kw)

    method.__name__ = name
    return method


def timestamp(_logger: Any, _name: str, event_dict: MutableMapping[str, Any]) -> Any:
    """The ISO 8601 UTC time of the call (a held line's own), as structlog's
    ``TimeStamper(fmt="iso", utc=True)`` writes it."""
    t = event_dict.pop(HELD_AT, None)
    now = (
        datetime.datetime.now(tz=datetime.UTC)
        if t is None
        else datetime.datetime.fromtimestamp(t, tz=datetime.UTC)
    )
    event_dict["timestamp"] = now.isoformat().replace("+00:00", "Z")
    return event_dict

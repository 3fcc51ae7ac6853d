"""The LIN bus: the nodes behind one parser, and the pseudo-terminal a master opens.

Every node sees every frame, as on the single wire (TMC211 §6.2). Two nodes answering
the same header drive the wire together: the bus carries the wired-AND of their bits
(dominant 0 wins), and a node that reads back another bit than it sent stops and records
a bit error (§6.7). The bus is inactive when no byte moved for 25000 bit times: that is
the LIN timeout that sends the nodes to their secure position and to sleep (§5.1.12,
§6.11.15).
"""

from __future__ import annotations

import contextlib
import errno
import os
import tty
from pathlib import Path

import structlog

from ecatsim.errors import UserError
from ecatsim.lin.frame import LinError, Parser, response
from ecatsim.lin.node import Node
from ecatsim.lin.tables import Event

log = structlog.get_logger("ecatsim.lin")

#: bus inactivity that counts as LIN loss, in bit times (§5.1.12: 1.30 s at 19.2 kbit/s)
LIN_TIMEOUT_BITS = 25000


class LinBus:
    """Nodes on one wire, fed with the bytes the master writes."""

    def __init__(self, nodes: list[Node], baud: int, now_ns: int) -> None:
        self.nodes = nodes
        self.baud = baud
        self.parser = Parser(self, baud)
        self.timeout_ns = LIN_TIMEOUT_BITS * 1_000_000_000 // baud
        self.last_activity_ns = now_ns
        self.timed_out = False
        self.collisions = 0
        self.timeouts = 0

    # --- FrameHandler ------------------------------------------------------------------

    def on_header(self, ident: int, now_ns: int) -> bytes | None:
        for n in self.nodes:
            n.header(ident, now_ns)
        answers = [(n, n.publish(ident, now_ns)) for n in self.nodes if n.publishes(ident)]
        sent = [(n, response(data)) for n, data in answers if data is not None]
        if not sent:
            return None
        if len(sent) == 1:
            node, wire = sent[0]
            node.sent(ident, True, now_ns)
            return wire
        self.collisions += 1
        return self._arbitrate(ident, sent, now_ns)

    def _arbitrate(self, ident: int, sent: list[tuple[Node, bytes]], now_ns: int) -> bytes:
        """Several nodes answer at once. Bit by bit, least significant first (UART order),
        the wire carries the AND of what they send (dominant 0 wins); a node that sends a
        recessive 1 and reads a 0 stops with a bit error (LIN 1.3; TMC211 §6.7)."""
        active = list(sent)
        out = bytearray()
        for i in range(max(len(w) for _, w in sent)):
            active = [(n, w) for n, w in active if i < len(w)]
            if not active:
                break
            byte = 0
            for bit in range(8):
                level = 1
                for _, w in active:
                    level &= w[i] >> bit & 1
                byte |= level << bit
                if not level:
                    for n, w in active:
                        if w[i] >> bit & 1:
                            n.sent(ident, False, now_ns)
                    active = [(n, w) for n, w in active if not w[i] >> bit & 1]
            out.append(byte)
        for n, _ in active:
            n.sent(ident, True, now_ns)
        return bytes(out)

    def on_frame(self, ident: int, data: bytes, now_ns: int) -> None:
        for n in self.nodes:
            n.receive(ident, data, now_ns)

    def on_error(self, error: LinError, now_ns: int) -> None:
        for n in self.nodes:
            n.lin_error(error)

    # --- bytes and time ----------------------------------------------------------------

    def feed(self, data: bytes, now_ns: int) -> bytes:
        """The master's bytes; returns the bytes the nodes put on the bus."""
        if not data:
            return b""
        self.service(now_ns)
        self.last_activity_ns = now_ns
        self.timed_out = False
        return self.parser.feed(data, now_ns)

    def service(self, now_ns: int) -> None:
        """Advance the nodes; drop an overdue frame; fire the LIN timeout once."""
        self.parser.expire(now_ns)
        if not self.timed_out and now_ns - self.last_activity_ns >= self.timeout_ns:
            at = self.last_activity_ns + self.timeout_ns
            self.timed_out = True
            self.timeouts += 1
            for n in self.nodes:
                n.advance(at)
                n.event(Event.SLEEP, at)
        for n in self.nodes:
            n.advance(now_ns)

    def deadline_ns(self) -> int | None:
        ds = [n.deadline_ns() for n in self.nodes]
        ds.append(self.parser.deadline_ns())
        if not self.timed_out:
            ds.append(self.last_activity_ns + self.timeout_ns)
        known = [d for d in ds if d is not None]
        return min(known) if known else None


class Pty:
    """A pseudo-terminal in raw mode whose slave end is linked at ``link``.

    The slave end stays open here too, so the master side never sees a hang-up when the
    LIN master closes and reopens the link."""

    def __init__(self, link: Path) -> None:
        self.link = link
        if link.is_symlink():
            link.unlink()  # left by an earlier run
        elif link.exists():
            raise UserError(
                f"--pty {link}: exists and is not a symlink; give a free path such as /tmp/lin0"
            )
        self.fd, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line discipline: bytes as a UART sees them
        os.set_blocking(self.fd, False)
        self.name = os.ttyname(self._slave)
        try:
            link.symlink_to(self.name)
        except OSError as exc:
            self._close_fds()
            raise UserError(f"--pty {link}: cannot create the link ({exc.strerror})") from exc
        #: bytes answered, and bytes the pty could not take
        self.written = 0
        self.dropped = 0

    def read(self) -> bytes:
        try:
            return os.read(self.fd, 4096)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if exc.errno == errno.EIO:
                return b""
            raise

    def write(self, data: bytes) -> None:
        """Answer bytes; what the pty cannot take (no reader) is dropped and counted."""
        try:
            n = os.write(self.fd, data)
        except (BlockingIOError, OSError):
            n = 0
        self.written += n
        self.dropped += len(data) - n

    def _close_fds(self) -> None:
        for fd in (self.fd, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            if os.readlink(self.link) == self.name:
                self.link.unlink()
        self._close_fds()

"""The SPI frames on a unix stream socket, and the IRQ line beside it.

A message is one chip-select frame: the client sends a 2-byte little-endian length ``n``
and ``n`` MOSI bytes; the daemon answers with exactly ``n`` MISO bytes. One client at a
time: a second connection is closed at once. The IRQ socket (``PATH.irq``) carries the
byte 0x01 each time the interrupt line rises. Both sockets are created mode 0600.
"""

from __future__ import annotations

import contextlib
import os
import socket
import stat
from collections.abc import Callable
from pathlib import Path

import structlog

from ecatsim.errors import UserError

log = structlog.get_logger("ecatsim.pdi_spi")

LEN_BYTES = 2
#: what a client may queue unanswered before it is dropped
MAX_PENDING = 1 << 20
IRQ_RISE = b"\x01"


def _listen(path: Path, what: str) -> socket.socket:
    """A listening unix stream socket at ``path``, mode 0600 (a stale socket file is
    replaced; any other file is an error)."""
    try:
        if stat.S_ISSOCK(path.lstat().st_mode):
            path.unlink()
    except FileNotFoundError:
        pass
    except OSError as exc:
        raise UserError(f"{what}: {path}: {exc.strerror}") from exc
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    old = os.umask(0o177)
    try:
        s.bind(str(path))
    except OSError as exc:
        s.close()
        raise UserError(
            f"{what}: cannot create the socket {path} ({exc.strerror}); "
            "check the directory exists and no other file has that name"
        ) from exc
    finally:
        os.umask(old)
    s.listen(1)
    s.setblocking(False)
    return s


class _OneClient:
    """A listening socket that serves one connected client at a time."""

    def __init__(self, path: Path, what: str) -> None:
        self.path = path
        self.server = _listen(path, what)
        self.client: socket.socket | None = None
        self.refused = 0

    def fds(self) -> list[int]:
        out = [self.server.fileno()]
        if self.client is not None:
            out.append(self.client.fileno())
        return out

    def accept(self) -> bool:
        """Accept a connection; True if it became the client."""
        try:
            conn, _ = self.server.accept()
        except (BlockingIOError, InterruptedError):
            return False
        if self.client is not None:
            self.refused += 1
            conn.close()
            return False
        conn.setblocking(False)
        self.client = conn
        return True

    def drop(self) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None

    def close(self) -> None:
        self.drop()
        self.server.close()
        with contextlib.suppress(OSError):
            self.path.unlink()


class SpiSocket:
    """One SPI interface of the chip on a socket; ``transfer`` answers each frame."""

    def __init__(self, path: Path, transfer: Callable[[bytes], bytes], what: str) -> None:
        self.spi = _OneClient(path, what)
        self.irq = _OneClient(Path(f"{path}.irq"), what)
        self._transfer = transfer
        self._buf = bytearray()
        self.frames = 0
        self.dropped = 0
        #: frames whose transfer failed inside ecatsim (answered with zeros, counted)
        self.failures = 0

    def fds(self) -> list[int]:
        return self.spi.fds() + self.irq.fds()

    def on_ready(self, fd: int) -> None:
        if fd == self.spi.server.fileno():
            if self.spi.accept():
                self._buf.clear()
        elif fd == self.irq.server.fileno():
            self.irq.accept()
        elif self.irq.client is not None and fd == self.irq.client.fileno():
            self._irq_readable()
        elif self.spi.client is not None and fd == self.spi.client.fileno():
            self._spi_readable(self.spi.client)

    def _irq_readable(self) -> None:
        """The IRQ client only listens: anything it sends is discarded, EOF drops it."""
        assert self.irq.client is not None
        try:
            if not self.irq.client.recv(4096):
                self.irq.drop()
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            self.irq.drop()

    def _spi_readable(self, conn: socket.socket) -> None:
        try:
            got = conn.recv(65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            got = b""
        if not got:  # the client went away, perhaps mid-frame: the frame never happened
            self.spi.drop()
            self._buf.clear()
            return
        self._buf += got
        out = bytearray()
        buf = self._buf
        p = 0
        while len(buf) - p >= LEN_BYTES:
            n = buf[p] | (buf[p + 1] << 8)
            if len(buf) - p - LEN_BYTES < n:
                break
            mosi = bytes(buf[p + LEN_BYTES : p + LEN_BYTES + n])
            p += LEN_BYTES + n
            out += self._answer(mosi)
            self.frames += 1
        del buf[:p]
        if len(buf) > MAX_PENDING:  # pragma: no cover - a frame is at most 64 KiB
            self.dropped += 1
            self.spi.drop()
            buf.clear()
            return
        if out:
            self._send(conn, bytes(out))

    def _answer(self, mosi: bytes) -> bytes:
        """MISO for one frame. A failure inside ecatsim never stalls the client: the frame
        is answered with zeros (as the SPI data line reads when nothing drives it), counted
        and logged once per kind, and the frames after it are served."""
        try:
            return self._transfer(mosi)
        except Exception as exc:
            self.failures += 1
            if self.failures == 1 or self.failures & (self.failures - 1) == 0:
                log.error(
                    "spi_transfer_failed",
                    socket=str(self.spi.path),
                    error=repr(exc),
                    count=self.failures,
                    exc_info=exc,
                )
            return bytes(len(mosi))

    def _send(self, conn: socket.socket, data: bytes) -> None:
        """Answer; a client that does not read its answers is dropped, never waited for."""
        try:
            sent = conn.send(data)
        except (BlockingIOError, InterruptedError):
            sent = 0
        except OSError:
            self.spi.drop()
            return
        if sent < len(data):
            self.dropped += 1
            log.warning("spi_client_dropped", socket=str(self.spi.path), reason="not reading")
            self.spi.drop()

    def raise_irq(self) -> None:
        """The interrupt line rose: tell the IRQ client, if one listens."""
        c = self.irq.client
        if c is None:
            return
        try:
            c.send(IRQ_RISE)
        except (BlockingIOError, InterruptedError):
            pass  # the client has unread rises queued: it will see the line is high
        except OSError:
            self.irq.drop()

    def status(self) -> dict[str, object]:
        return {
            "socket": str(self.spi.path),
            "client": self.spi.client is not None,
            "irq_client": self.irq.client is not None,
            "frames": self.frames,
            "failures": self.failures,
            "refused": self.spi.refused + self.irq.refused,
        }

    def close(self) -> None:
        self.spi.close()
        self.irq.close()

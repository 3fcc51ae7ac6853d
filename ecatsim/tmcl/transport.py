"""Where TMCL bytes come from: TCP listeners and their clients, pseudo-terminals.

``tcp://HOST:PORT`` carries the 9-byte stream as Ethernet-to-serial converters (and
pytrinamic's ``socket_serial_tmcl`` interface) do; ``pty:PATH`` makes a pseudo-terminal
whose slave end is linked at PATH, for serial clients (pytrinamic's ``serial_tmcl``, a
terminal program). Every connection is one line of the RS485-style bus.

Nothing a client does can block the server: sockets are non-blocking, a client that
does not read its replies is cut off once :data:`MAX_BACKLOG` bytes wait for it.
"""

from __future__ import annotations

import errno
import os
import socket
import tty
from pathlib import Path
from urllib.parse import urlsplit

from ecatsim.errors import UserError
from ecatsim.tmcl.protocol import SERIAL_GAP_NS

#: reply bytes one line may owe before the client is cut off (TCP) or bytes dropped (pty)
MAX_BACKLOG = 65536
READ_SIZE = 4096


class Line:
    """One byte stream: a TCP client or a pty master."""

    name = "line"
    #: the pause that drops a partial telegram (decision T3); None: the stream has no
    #: timing, as over TCP (decision T25)
    gap_ns: int | None = SERIAL_GAP_NS

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.out = bytearray()
        self.closed = False
        #: the peer is gone or does not read: the server drops the line (and closes it)
        self.dead = False
        self.dropped_out = 0

    def fileno(self) -> int:
        return self.fd

    def read(self) -> bytes | None:
        """What arrived; b"" when nothing did; None when the peer is gone."""
        raise NotImplementedError

    def send(self, data: bytes) -> None:
        self.out += data
        self.flush()

    def flush(self) -> None:
        while self.out and not self.closed and not self.dead:
            try:
                n = self._write(bytes(self.out[:READ_SIZE]))
            except BlockingIOError:
                break
            except OSError:
                self.out.clear()
                self._gone()
                return
            del self.out[:n]
        if len(self.out) > MAX_BACKLOG:
            self._backlog()

    def _write(self, data: bytes) -> int:
        raise NotImplementedError

    def _gone(self) -> None:
        self.dead = True

    def _backlog(self) -> None:
        self.out.clear()
        self.dead = True

    def close(self) -> None:
        raise NotImplementedError


class TcpLine(Line):
    """A TCP client. TCP delivers a byte stream in segments of its own choosing (Nagle, a
    host writing byte by byte): a telegram is its next 9 bytes however long they take."""

    gap_ns = None

    def __init__(self, sock: socket.socket, peer: str) -> None:
        super().__init__(sock.fileno())
        self.sock = sock
        self.name = f"tcp:{peer}"

    def read(self) -> bytes | None:
        try:
            data = self.sock.recv(READ_SIZE)
        except BlockingIOError:
            return b""
        except OSError:
            return None
        return data or None

    def _write(self, data: bytes) -> int:
        return self.sock.send(data)

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.sock.close()


class TcpListener:
    """A listening socket; :meth:`accept` gives the new lines."""

    def __init__(self, host: str, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.sock.bind((host, port))
        except OSError as exc:
            self.sock.close()
            raise UserError(
                f"tcp://{host}:{port}: cannot listen ({exc.strerror}); pick another port"
            ) from exc
        self.sock.listen(8)
        self.sock.setblocking(False)
        self.host = host
        self.port = self.sock.getsockname()[1]

    @property
    def url(self) -> str:
        return f"tcp://{self.host}:{self.port}"

    def fileno(self) -> int:
        return self.sock.fileno()

    def accept(self) -> TcpLine | None:
        try:
            conn, addr = self.sock.accept()
        except (BlockingIOError, OSError):
            return None
        conn.setblocking(False)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return TcpLine(conn, f"{addr[0]}:{addr[1]}")

    def close(self) -> None:
        self.sock.close()


class PtyLine(Line):
    """A pseudo-terminal in raw mode; PATH links to its slave end.

    The server keeps the slave end open itself, so a client that closes the port does not
    hang the line up: the next one that opens PATH finds it as the last one left it."""

    def __init__(self, path: Path) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        super().__init__(master)
        self.slave = slave
        self.path = path
        self.name = f"pty:{path}"
        slave_name = os.ttyname(slave)
        try:
            if path.is_symlink() or path.exists():
                if not path.is_symlink():
                    raise UserError(f"pty:{path}: exists and is not a link; pick another path")
                path.unlink()
            path.symlink_to(slave_name)
        except OSError as exc:
            os.close(master)
            os.close(slave)
            raise UserError(f"pty:{path}: cannot link the terminal ({exc.strerror})") from exc

    def read(self) -> bytes | None:
        try:
            return os.read(self.fd, READ_SIZE)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if exc.errno == errno.EIO:  # no slave open: nothing to read
                return b""
            return b""

    def _write(self, data: bytes) -> int:
        return os.write(self.fd, data)

    def _gone(self) -> None:
        pass

    def _backlog(self) -> None:
        """Nobody reads the terminal: forget the oldest replies, keep serving."""
        excess = len(self.out) - MAX_BACKLOG
        self.dropped_out += excess
        del self.out[:excess]

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        for fd in (self.fd, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass
        try:
            if self.path.is_symlink():
                self.path.unlink()
        except OSError:
            pass


def parse_listen(url: str, base: Path | None = None) -> tuple[str, str, int]:
    """``tcp://HOST:PORT`` -> ("tcp", host, port); ``pty:PATH`` -> ("pty", path, 0).
    ValueError with the fix for anything else."""
    if url.startswith("pty:"):
        raw = url[4:]
        if not raw:
            raise ValueError(f"{url!r}: expected pty:PATH, e.g. pty:/tmp/tmcm1311")
        path = Path(raw)
        if base is not None and not path.is_absolute():
            path = base / path
        return ("pty", str(path), 0)
    if url.startswith("tcp://"):
        parts = urlsplit(url)
        try:
            port = parts.port
        except ValueError as exc:
            raise ValueError(f"{url!r}: bad port ({exc})") from exc
        if port is None:
            raise ValueError(f"{url!r}: expected tcp://HOST:PORT, e.g. tcp://127.0.0.1:2323")
        return ("tcp", parts.hostname or "0.0.0.0", port)
    raise ValueError(f"{url!r}: expected tcp://HOST:PORT or pty:PATH")

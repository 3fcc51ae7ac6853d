"""EtherCAT over UDP: the UDP payload starts with the EtherCAT header; replies go to the
sender of the last datagram. Ref: ETG.1000.4 §5.3.2 (UDP port 0x88A4 = 34980)."""

from __future__ import annotations

import errno
import socket

from ecatsim.link.errors import LinkError

UDP_PORT = 0x88A4


class UdpLink:
    """A UDP socket serving EtherCAT frames."""

    ethernet = False

    def __init__(self, host: str, port: int = UDP_PORT) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((host, port))
        except OSError as exc:
            self.sock.close()
            raise LinkError(
                f"cannot bind UDP {host}:{port} ({exc.strerror}): pick a free port"
            ) from exc
        self.sock.setblocking(False)
        self.peer: tuple[str, int] | None = None

    @property
    def address(self) -> tuple[str, int]:
        a = self.sock.getsockname()
        return str(a[0]), int(a[1])

    def fileno(self) -> int:
        return self.sock.fileno()

    def recv_into(self, buf: bytearray) -> int:
        try:
            n, addr = self.sock.recvfrom_into(buf)
        except BlockingIOError:
            return 0
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EINTR, errno.ECONNREFUSED):
                return 0
            raise
        self.peer = addr
        return n

    def send(self, frame: memoryview) -> None:
        if self.peer is not None:
            try:
                self.sock.sendto(frame, self.peer)
            except OSError as exc:
                if exc.errno not in (errno.EAGAIN, errno.ENOBUFS, errno.ECONNREFUSED):
                    raise

    def close(self) -> None:
        self.sock.close()

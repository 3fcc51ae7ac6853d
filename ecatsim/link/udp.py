"""EtherCAT over UDP: the UDP payload starts with the EtherCAT header (no Ethernet header).

The link answers whoever sent the last datagram, so a master may use any source port.
IPv4 and IPv6 hosts both work (the address family follows ``host``).

Ref: ETG.1000.4 (EtherCAT frame in a UDP/IP datagram, UDP port 0x88A4 = 34980).
"""

from __future__ import annotations

import errno
import socket

from ecatsim.link.errors import LinkError

UDP_PORT = 0x88A4
_RCVBUF = 1 << 20


class UdpLink:
    """A UDP socket serving EtherCAT frames to the sender of the last datagram."""

    ethernet = False
    rx_ns = 0

    def __init__(self, host: str, port: int = UDP_PORT) -> None:
        if not 0 <= port <= 0xFFFF:
            raise LinkError(f"UDP port {port} out of range: use 0..65535 (EtherCAT: 34980)")
        try:
            infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
        except socket.gaierror as exc:
            raise LinkError(f"cannot resolve UDP host {host!r}: {exc.strerror}") from exc
        family, _t, _p, _c, addr = infos[0]
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, _RCVBUF)
            sock.bind(addr)
        except OSError as exc:
            sock.close()
            raise LinkError(
                f"cannot bind UDP {host}:{port} ({exc.strerror}): pick a free port or address"
            ) from exc
        sock.setblocking(False)
        self.sock = sock
        #: Address of the sender of the last received datagram; replies go there.
        self.peer: tuple[str, int] | tuple[str, int, int, int] | None = None

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port); useful with port 0."""
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
            # ECONNREFUSED: an ICMP port-unreachable for an earlier reply (master gone).
            if exc.errno in (errno.EAGAIN, errno.EINTR, errno.ECONNREFUSED):
                return 0
            raise
        self.peer = addr
        return n

    def send(self, frame: memoryview) -> None:
        if self.peer is None:
            return
        try:
            self.sock.sendto(frame, self.peer)
        except OSError as exc:
            if exc.errno not in (errno.EAGAIN, errno.ENOBUFS, errno.ECONNREFUSED):
                raise

    def close(self) -> None:
        self.sock.close()

"""A link over a datagram socket pair, for tests of the compiled responder (decision P9):
like a raw socket, one receive is one frame and one send one reply, so the responder can
serve it, and the test plays the master on the other end."""

from __future__ import annotations

import socket


class SocketLink:
    """The daemon's end of an AF_UNIX datagram socket pair; the test holds the other."""

    ethernet = True
    rx_ns = 0
    raw_socket = True

    def __init__(self) -> None:
        self.sock, self.master = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.master.setblocking(False)

    def fileno(self) -> int:
        return self.sock.fileno()

    def recv_into(self, buf: bytearray) -> int:
        try:
            return self.sock.recv_into(buf)
        except BlockingIOError:
            return 0

    def send(self, frame: memoryview) -> None:
        self.sock.send(frame)

    def master_send(self, frame: bytes) -> None:
        self.master.send(frame)

    def master_recv(self) -> bytes | None:
        try:
            return self.master.recv(4096)
        except BlockingIOError:
            return None

    def close(self) -> None:
        self.sock.close()
        self.master.close()

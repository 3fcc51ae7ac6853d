"""TAP link: a TAP device created by the daemon; EtherType 0x88A4 frames only.

Ref: Linux tuntap (IFF_TAP | IFF_NO_PI); ETG.1000.4 §5.3; IEEE 802.1Q.
"""

from __future__ import annotations

import errno
import fcntl
import os
import struct
import subprocess

from ecatsim.link.errors import LinkError
from ecatsim.wire.frame import ecat_offset

TUNSETIFF = 0x400454CA
IFF_TAP = 0x0002
IFF_NO_PI = 0x1000


class TapLink:
    """A TAP device; frames that are not EtherCAT are ignored."""

    ethernet = True

    def __init__(self, name: str) -> None:
        if not name or len(name) > 15:
            raise LinkError(f"TAP name {name!r}: use 1..15 characters, e.g. --tap ecattap0")
        try:
            fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK)
        except OSError as exc:
            raise LinkError(
                f"cannot open /dev/net/tun ({exc.strerror}): load the tun module and run as root "
                "(CAP_NET_ADMIN)"
            ) from exc
        try:
            fcntl.ioctl(fd, TUNSETIFF, struct.pack("16sH", name.encode(), IFF_TAP | IFF_NO_PI))
        except OSError as exc:
            os.close(fd)
            raise LinkError(
                f"cannot create TAP device {name} ({exc.strerror}): needs CAP_NET_ADMIN"
            ) from exc
        self.fd = fd
        self.name = name
        subprocess.run(
            ["ip", "link", "set", name, "up"], check=False, capture_output=True, timeout=5
        )

    def fileno(self) -> int:
        return self.fd

    def recv_into(self, buf: bytearray) -> int:
        while True:
            try:
                n = os.readv(self.fd, [buf])
            except BlockingIOError:
                return 0
            except OSError as exc:
                if exc.errno in (errno.EAGAIN, errno.EINTR, errno.EIO):
                    return 0
                raise
            if n <= 0:
                return 0
            if ecat_offset(buf, n, True) >= 0:
                return n

    def send(self, frame: memoryview) -> None:
        try:
            os.write(self.fd, frame)
        except OSError as exc:
            if exc.errno not in (errno.EAGAIN, errno.EIO, errno.ENOBUFS):
                raise

    def close(self) -> None:
        os.close(self.fd)

"""TAP link: a TAP device the daemon creates; only EtherType 0x88A4 frames are delivered.

The master (or a bridge) sends into the TAP device's kernel side; each ``read`` on the
character device returns one whole Ethernet frame (``IFF_NO_PI``: no packet-info prefix).
Frames that are not EtherCAT, plain or behind one 802.1Q tag, are ignored: the kernel
sends IPv6 router solicitations and the like into any interface that comes up.

Ref: Linux Documentation/networking/tuntap.rst (TUNSETIFF, IFF_TAP, IFF_NO_PI);
ETG.1000.4 (EtherCAT frames, EtherType 0x88A4); IEEE 802.1Q (VLAN tag).
"""

from __future__ import annotations

import errno
import fcntl
import os
import struct
import subprocess

from ecatsim.link.errors import LinkError

TUNSETIFF = 0x400454CA
IFF_TAP = 0x0002
IFF_NO_PI = 0x1000
ETH_P_ECAT = 0x88A4
ETH_P_8021Q = 0x8100
_IFREQ = struct.Struct("16sH")


def is_ecat_frame(buf: bytearray | memoryview, n: int) -> bool:
    """True if the Ethernet frame in ``buf[:n]`` carries EtherType 0x88A4 (VLAN aware)."""
    if n < 16:
        return False
    etype = (buf[12] << 8) | buf[13]
    if etype == ETH_P_ECAT:
        return True
    return etype == ETH_P_8021Q and n >= 20 and ((buf[16] << 8) | buf[17]) == ETH_P_ECAT



def open_tap(name: str, error: type[Exception], what: str) -> int:
    """A non-blocking descriptor of the TAP device ``name`` (made if it does not exist),
    frames without a packet-info prefix; a failure is ``error`` with one line (prefixed
    by ``what``) naming the cause and the fix."""
    try:
        fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        raise error(
            f"{what}cannot open /dev/net/tun ({exc.strerror}): load the tun module "
            "(modprobe tun) and run as root (CAP_NET_ADMIN)"
        ) from exc
    try:
        fcntl.ioctl(fd, TUNSETIFF, _IFREQ.pack(name.encode(), IFF_TAP | IFF_NO_PI))
    except OSError as exc:
        os.close(fd)
        raise error(
            f"{what}cannot create TAP device {name} ({exc.strerror}): run as root "
            "(CAP_NET_ADMIN) and pick a name that is not another kind of interface"
        ) from exc
    return fd

class TapLink:
    """A TAP device created (or attached to, if it is persistent) under ``name``."""

    ethernet = True
    rx_ns = 0

    def __init__(self, name: str) -> None:
        if not name or len(name) > 15:
            raise LinkError(f"TAP name {name!r}: use 1..15 characters, e.g. --tap ecattap0")
        fd = open_tap(name, LinkError, "")
        self.fd = fd
        self.name = name
        try:
            r = subprocess.run(
                ["ip", "link", "set", name, "up"], check=False, capture_output=True, timeout=5
            )
        except (OSError, subprocess.SubprocessError) as exc:
            os.close(fd)
            raise LinkError(
                f"cannot bring TAP device {name} up: {exc} (is iproute2 installed?)"
            ) from exc
        if r.returncode != 0:
            os.close(fd)
            msg = r.stderr.decode(errors="replace").strip()
            raise LinkError(f"cannot bring TAP device {name} up: {msg}")

    def fileno(self) -> int:
        return self.fd

    def recv_into(self, buf: bytearray) -> int:
        """One EtherCAT frame into ``buf``; 0 if none is waiting (other frames are dropped)."""
        while True:
            try:
                n = os.readv(self.fd, [buf])
            except BlockingIOError:
                return 0
            except OSError as exc:
                # EIO: the interface is down (nobody reads the other side).
                if exc.errno in (errno.EAGAIN, errno.EINTR, errno.EIO):
                    return 0
                raise
            if n <= 0:
                return 0
            if is_ecat_frame(buf, n):
                return n

    def send(self, frame: memoryview) -> None:
        try:
            os.write(self.fd, frame)
        except OSError as exc:
            if exc.errno not in (errno.EAGAIN, errno.EIO, errno.ENOBUFS):
                raise

    def close(self) -> None:
        os.close(self.fd)

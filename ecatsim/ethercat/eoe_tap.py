"""The network side of an EoE slave: a TAP device in the daemon's network namespace.

Frames the master tunnels to the slave come out of the TAP device's kernel side (where a
test answers pings or runs a server); every frame the kernel sends into it goes back to
the master over EoE. Addresses are set with ioctl(2) on a socket (no helper programs), so
an address the master sets later needs only CAP_NET_ADMIN, which the daemon keeps for it
(docs/security.md). Served as a front door of the daemon loop (ecatsim/doors/host.py,
ecatsim/doors/from_config.py).

Ref: Linux Documentation/networking/tuntap.rst (TUNSETIFF, IFF_TAP, IFF_NO_PI);
netdevice(7) (SIOCSIFADDR, SIOCSIFNETMASK, SIOCSIFHWADDR, SIOCGIFHWADDR, SIOCSIFFLAGS);
ETG.1000.6 §5.7 (EoE).
"""

from __future__ import annotations

import errno
import fcntl
import os
import socket
import struct
from typing import Any

import structlog

from ecatsim.errors import UserError
from ecatsim.link.tap import open_tap
from ecatsim.slave.eoe import EoeService
from ecatsim.wire.eoe import IpParams

log = structlog.get_logger("ecatsim.eoe")

SIOCGIFFLAGS = 0x8913
SIOCSIFFLAGS = 0x8914
SIOCSIFADDR = 0x8916
SIOCSIFNETMASK = 0x891C
SIOCSIFHWADDR = 0x8924
SIOCGIFHWADDR = 0x8927
IFF_UP = 0x1
ARPHRD_ETHER = 1
#: frames read per readable wake-up before the loop serves the link again
READ_BURST = 32
MAX_FRAME = 2048


def _ifreq(name: str, payload: bytes) -> bytes:
    return struct.pack("16s", name.encode()) + payload.ljust(24, b"\x00")


def _sockaddr_in(addr: bytes) -> bytes:
    return struct.pack("<H", socket.AF_INET) + b"\x00\x00" + addr + bytes(8)


class EoeTap:
    """The TAP device ``name`` for the EoE service of slave ``position``."""

    def __init__(self, name: str, service: EoeService, position: int, what: str) -> None:
        self.name = name
        self.eoe = service
        self.position = position
        self.read_errors = 0
        fd = open_tap(name, UserError, f"{what}: ")
        self.fd = fd
        try:
            self.apply(service.params)
            self._up()
            if service.params.mac is None:
                service.params = _with_mac(service.params, self.mac())
        except OSError as exc:
            os.close(fd)
            raise UserError(f"{what}: cannot configure TAP device {name} ({exc.strerror})") from exc
        service.side = self

    # ----------------------------------------------------------------- interface

    def _ioctl(self, request: int, payload: bytes) -> bytes:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            return fcntl.ioctl(s.fileno(), request, _ifreq(self.name, payload))

    def _up(self) -> None:
        flags = struct.unpack_from("<H", self._ioctl(SIOCGIFFLAGS, b""), 16)[0]
        self._ioctl(SIOCSIFFLAGS, struct.pack("<H", flags | IFF_UP))

    def mac(self) -> bytes:
        """The interface's MAC address."""
        return self._ioctl(SIOCGIFHWADDR, b"")[18:24]

    def apply(self, params: IpParams) -> None:
        """Give the TAP device these addresses (MAC, IPv4 address, mask)."""
        if params.mac is not None:
            self._ioctl(SIOCSIFHWADDR, struct.pack("<H", ARPHRD_ETHER) + params.mac)
        if params.ip is not None:
            self._ioctl(SIOCSIFADDR, _sockaddr_in(params.ip))
            if params.subnet is not None:
                self._ioctl(SIOCSIFNETMASK, _sockaddr_in(params.subnet))

    def write(self, frame: bytes) -> bool:
        """A frame from the master into the TAP device (the slave's network)."""
        try:
            os.write(self.fd, frame)
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EIO, errno.ENOBUFS, errno.EINVAL):
                return False
            raise
        return True

    # ----------------------------------------------------------------- front door

    def fds(self) -> list[int]:
        return [self.fd]

    def on_ready(self, fd: int) -> None:
        """Frames the kernel sent into the TAP device: on to the master over EoE."""
        for _ in range(READ_BURST):
            try:
                frame = os.read(self.fd, MAX_FRAME)
            except BlockingIOError:
                return
            except OSError as exc:
                if exc.errno in (errno.EAGAIN, errno.EINTR, errno.EIO):
                    return
                self.read_errors += 1
                raise
            if not frame:
                return
            self.eoe.push(frame)

    def service(self, now_ns: int) -> None:
        """Nothing runs on a timer here."""

    def deadline_ns(self) -> int | None:
        return None

    def status(self) -> dict[str, Any]:
        """The door's line in ``ctl status`` (the counters are in the slave's ``eoe``)."""
        return {"slave": self.position, "tap": self.name, "ip": self.eoe.status()["ip"] or "-"}

    def ctl(self, command: str, args: list[str]) -> dict[str, Any]:
        if command == "status":
            return self.status()
        raise ValueError(f"{command!r}: an EoE door answers 'status' only")

    def close(self) -> None:
        try:
            os.close(self.fd)
        except OSError:
            pass


def _with_mac(params: IpParams, mac: bytes) -> IpParams:
    return IpParams(mac, params.ip, params.subnet, params.gateway, params.dns_ip, params.dns_name)

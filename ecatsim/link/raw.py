"""Raw AF_PACKET link bound to EtherType 0x88A4 on one interface.

Own outgoing frames (PACKET_OUTGOING) are ignored. Frames are received into the caller's
buffer and the same buffer is sent back. Ref: packet(7); ETG.1000.4 §5.3 (EtherType 0x88A4).
"""

from __future__ import annotations

import errno
import json
import socket
import subprocess

from ecatsim.link.errors import LinkError

ETH_P_ECAT = 0x88A4
PACKET_OUTGOING = 4
SOL_PACKET = 263
PACKET_QDISC_BYPASS = 20


def iface_exists(iface: str) -> bool:
    try:
        socket.if_nametoindex(iface)
    except OSError:
        return False
    return True


def iface_ipv4_addresses(iface: str) -> list[str]:
    """IPv4 addresses configured on ``iface`` (empty if none or unknown)."""
    try:
        out = subprocess.run(
            ["ip", "-j", "-4", "addr", "show", "dev", iface],
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        ).stdout
        data = json.loads(out or "[]")
    except (OSError, ValueError, subprocess.SubprocessError):
        return []
    addrs: list[str] = []
    for link in data:
        for a in link.get("addr_info", []):
            if a.get("family") == "inet" and a.get("local"):
                addrs.append(str(a["local"]))
    return addrs


class RawLink:
    """AF_PACKET/SOCK_RAW on one interface, EtherType 0x88A4 only."""

    ethernet = True

    def __init__(self, iface: str) -> None:
        if not iface_exists(iface):
            raise LinkError(
                f"interface {iface!r} does not exist: create it (e.g. ip link add {iface} type "
                "veth peer name <peer>) or pass an existing --iface"
            )
        self.iface = iface
        try:
            sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ECAT))
        except PermissionError as exc:
            raise LinkError(
                f"opening a raw socket on {iface} needs CAP_NET_RAW: run as root or grant it "
                "(setcap cap_net_raw+ep on the Python interpreter)"
            ) from exc
        try:
            sock.bind((iface, ETH_P_ECAT))
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
            try:
                sock.setsockopt(SOL_PACKET, PACKET_QDISC_BYPASS, 1)
            except OSError:
                pass
        except OSError as exc:
            sock.close()
            raise LinkError(f"cannot bind a raw socket to {iface}: {exc.strerror}") from exc
        sock.setblocking(False)
        self.sock = sock
        self._up(iface)

    @staticmethod
    def _up(iface: str) -> None:
        try:
            with open(f"/sys/class/net/{iface}/operstate") as f:
                state = f.read().strip()
        except OSError:
            return
        if state == "down":
            subprocess.run(["ip", "link", "set", iface, "up"], check=False, timeout=5)

    def fileno(self) -> int:
        return self.sock.fileno()

    def recv_into(self, buf: bytearray) -> int:
        """One frame into ``buf``; 0 if none waiting or it was our own outgoing frame."""
        while True:
            try:
                n, addr = self.sock.recvfrom_into(buf)
            except BlockingIOError:
                return 0
            except OSError as exc:
                if exc.errno in (errno.EAGAIN, errno.EINTR, errno.ENETDOWN):
                    return 0
                raise
            if addr[2] != PACKET_OUTGOING:
                return n

    def send(self, frame: memoryview) -> None:
        try:
            self.sock.send(frame)
        except OSError as exc:
            if exc.errno not in (errno.ENOBUFS, errno.EAGAIN, errno.ENETDOWN, errno.ENXIO):
                raise

    def close(self) -> None:
        self.sock.close()

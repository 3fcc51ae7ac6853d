"""Raw AF_PACKET link that receives only EtherCAT frames (0x88A4, optionally 802.1Q-tagged).

The socket listens to all protocols with a classic BPF filter in the kernel that keeps
EtherType 0x88A4 (and 0x8100 + 0x88A4) and drops our own outgoing frames, so VLAN tags the
kernel moves into packet metadata come back through PACKET_AUXDATA and the reply keeps its
tag. Frames are received into the caller's buffer and the same buffer is sent back.
Ref: packet(7), filter(7); ETG.1000.4 §5.3 (EtherType 0x88A4); IEEE 802.1Q.
"""

from __future__ import annotations

import ctypes
import errno
import json
import socket
import struct
import subprocess

from ecatsim.link.errors import LinkError

ETH_P_ECAT = 0x88A4
ETH_P_ALL = 0x0003
SO_ATTACH_FILTER = 26
#: (code, jt, jf, k): keep 0x88A4 and 0x8100/0x88A4, drop PACKET_OUTGOING. Ref: filter(7).
ECAT_FILTER = (
    (0x20, 0, 0, 0xFFFFF004),  # ld  pkttype (SKF_AD_OFF + SKF_AD_PKTTYPE)
    (0x15, 6, 0, 4),  # jeq PACKET_OUTGOING -> drop
    (0x28, 0, 0, 12),  # ldh [12]
    (0x15, 3, 0, ETH_P_ECAT),  # jeq 0x88A4 -> accept
    (0x15, 0, 3, 0x8100),  # jne 0x8100 -> drop
    (0x28, 0, 0, 16),  # ldh [16]
    (0x15, 0, 1, ETH_P_ECAT),  # jne 0x88A4 -> drop
    (0x06, 0, 0, 0xFFFF),  # accept
    (0x06, 0, 0, 0),  # drop
)
PACKET_OUTGOING = 4
SOL_PACKET = 263
PACKET_QDISC_BYPASS = 20
PACKET_AUXDATA = 8
TP_STATUS_VLAN_VALID = 0x10
TP_STATUS_VLAN_TPID_VALID = 0x40
#: struct tpacket_auxdata. Ref: linux/if_packet.h.
AUXDATA = struct.Struct("=IIIHHHH")
_VLAN_TAG = struct.Struct(">HH")


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


def attach_filter(sock: socket.socket, prog: tuple[tuple[int, int, int, int], ...]) -> None:
    """Attach a classic BPF program (SO_ATTACH_FILTER). Ref: filter(7)."""
    raw = b"".join(struct.pack("=HBBI", *ins) for ins in prog)
    buf = ctypes.create_string_buffer(raw)
    fprog = struct.pack("HL", len(prog), ctypes.addressof(buf))
    sock.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER, fprog)


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
            sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
        except PermissionError as exc:
            raise LinkError(
                f"opening a raw socket on {iface} needs CAP_NET_RAW: run as root or grant it "
                "(setcap cap_net_raw+ep on the Python interpreter)"
            ) from exc
        try:
            attach_filter(sock, ECAT_FILTER)
            sock.bind((iface, ETH_P_ALL))
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
            # The kernel strips an 802.1Q tag into metadata before delivering the frame to
            # a socket bound to 0x88A4; auxdata returns it so the reply keeps its tag.
            sock.setsockopt(SOL_PACKET, PACKET_AUXDATA, 1)
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
                n, anc, _flags, addr = self.sock.recvmsg_into([buf], 64)
            except BlockingIOError:
                return 0
            except OSError as exc:
                if exc.errno in (errno.EAGAIN, errno.EINTR, errno.ENETDOWN):
                    return 0
                raise
            if addr[2] == PACKET_OUTGOING:
                continue
            for level, typ, data in anc:
                if level == SOL_PACKET and typ == PACKET_AUXDATA and len(data) >= AUXDATA.size:
                    status, _l, _s, _m, _n, tci, tpid = AUXDATA.unpack_from(data)
                    if status & TP_STATUS_VLAN_VALID and n + 4 <= len(buf):
                        if not status & TP_STATUS_VLAN_TPID_VALID:
                            tpid = 0x8100
                        buf[16 : n + 4] = buf[12:n]
                        _VLAN_TAG.pack_into(buf, 12, tpid, tci)
                        n += 4
            return n

    def send(self, frame: memoryview) -> None:
        try:
            self.sock.send(frame)
        except OSError as exc:
            if exc.errno not in (errno.ENOBUFS, errno.EAGAIN, errno.ENETDOWN, errno.ENXIO):
                raise

    def close(self) -> None:
        self.sock.close()

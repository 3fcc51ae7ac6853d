"""Raw AF_PACKET link on one interface that delivers only EtherCAT frames (EtherType 0x88A4).

Why the socket is bound with ETH_P_ALL plus a kernel filter rather than with 0x88A4: the
receiving kernel moves an 802.1Q tag into packet metadata and, for a socket bound to one
EtherType, clears it before delivery (checked on Linux 6.x: the frame arrives untagged and
PACKET_AUXDATA carries no VLAN). Only ETH_P_ALL sockets get the tag back through
PACKET_AUXDATA, and the reply must carry the master's tag. A classic BPF program attached
before the bind keeps EtherType 0x88A4 (plain or behind 0x8100) and drops our own outgoing
frames, so nothing else ever reaches user space; ``recv_into`` checks the packet type
(PACKET_OUTGOING) once more. Frames land in the caller's buffer (``recvmsg_into``) and the
same buffer is sent back, so the hot path copies no frame.

Ref: packet(7) (AF_PACKET, PACKET_AUXDATA, PACKET_QDISC_BYPASS), filter(7) (SO_ATTACH_FILTER),
netdevice(7) (SIOCGIFFLAGS/SIOCSIFFLAGS); ETG.1000.4 (EtherCAT frames, EtherType 0x88A4);
IEEE 802.1Q (VLAN tag).
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import json
import socket
import struct
import subprocess
import time

from ecatsim.link.errors import LinkError

ETH_P_ECAT = 0x88A4
ETH_P_8021Q = 0x8100
ETH_P_ALL = 0x0003
#: ``recvfrom`` address tuple index 2 is the packet type. Ref: packet(7) sll_pkttype.
PACKET_OUTGOING = 4
SOL_PACKET = 263
PACKET_AUXDATA = 8
PACKET_QDISC_BYPASS = 20
SO_ATTACH_FILTER = 26
TP_STATUS_VLAN_VALID = 0x10
TP_STATUS_VLAN_TPID_VALID = 0x40
SIOCGIFFLAGS = 0x8913
SIOCSIFFLAGS = 0x8914
IFF_UP = 0x1
#: the interface is up and has carrier (operational). Ref: netdevice(7)
IFF_RUNNING = 0x40
#: Receive/send buffer: room for a few hundred full frames without hogging memory.
SOCK_BUF = 1 << 20
#: (code, jt, jf, k): keep 0x88A4 and 0x8100/0x88A4, drop PACKET_OUTGOING. Ref: filter(7).
ECAT_FILTER: tuple[tuple[int, int, int, int], ...] = (
    (0x20, 0, 0, 0xFFFFF004),  # ld  pkttype (SKF_AD_OFF + SKF_AD_PKTTYPE)
    (0x15, 6, 0, PACKET_OUTGOING),  # jeq PACKET_OUTGOING -> drop
    (0x28, 0, 0, 12),  # ldh [12]
    (0x15, 3, 0, ETH_P_ECAT),  # jeq 0x88A4 -> accept
    (0x15, 0, 3, ETH_P_8021Q),  # jne 0x8100 -> drop
    (0x28, 0, 0, 16),  # ldh [16]
    (0x15, 0, 1, ETH_P_ECAT),  # jne 0x88A4 -> drop
    (0x06, 0, 0, 0xFFFF),  # ret accept
    (0x06, 0, 0, 0),  # ret drop
)
#: struct tpacket_auxdata. Ref: linux/if_packet.h.
AUXDATA = struct.Struct("=IIIHHHH")
_VLAN_TAG = struct.Struct(">HH")
_IFREQ_FLAGS = struct.Struct("16sH")
#: SO_TIMESTAMPNS: the kernel's receive time (CLOCK_REALTIME) as struct timespec
SO_TIMESTAMPNS = 35
TIMESPEC = struct.Struct("=qq")
#: a receive time stamp older than this means the wall clock was stepped meanwhile
MAX_RX_AGE_NS = 1_000_000_000
_ANC_SIZE = socket.CMSG_SPACE(AUXDATA.size) + socket.CMSG_SPACE(TIMESPEC.size)


def iface_exists(iface: str) -> bool:
    """True if ``iface`` exists in this network namespace."""
    try:
        socket.if_nametoindex(iface)
    except OSError:
        return False
    return True


def iface_ipv4_addresses(iface: str) -> list[str]:
    """IPv4 addresses configured on ``iface`` (empty if none, or if ``ip`` cannot tell).

    The daemon refuses an interface with an address unless ``--allow-ip-iface``, so a
    production NIC is never taken over by mistake. Ref: ip-address(8) (``-j`` JSON output).
    """
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
    if not isinstance(data, list):
        return addrs
    for link in data:
        for a in link.get("addr_info", []) if isinstance(link, dict) else []:
            if a.get("family") == "inet" and a.get("local"):
                addrs.append(str(a["local"]))
    return addrs


def attach_filter(sock: socket.socket, prog: tuple[tuple[int, int, int, int], ...]) -> None:
    """Attach a classic BPF program (``SO_ATTACH_FILTER``). Ref: filter(7)."""
    raw = b"".join(struct.pack("=HBBI", *ins) for ins in prog)
    buf = ctypes.create_string_buffer(raw, len(raw))
    fprog = struct.pack("HL", len(prog), ctypes.addressof(buf))
    sock.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER, fprog)


def ensure_up(iface: str) -> None:
    """Bring ``iface`` administratively up if it is down (needs CAP_NET_ADMIN).

    A down interface we may not bring up is a LinkError naming the fix. A missing carrier
    (e.g. the veth peer is down) is not an error: frames flow once the peer comes up.
    Ref: netdevice(7) SIOCGIFFLAGS/SIOCSIFFLAGS.
    """
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        req = _IFREQ_FLAGS.pack(iface.encode(), 0)
        try:
            _name, flags = _IFREQ_FLAGS.unpack_from(fcntl.ioctl(s, SIOCGIFFLAGS, req))
        except OSError as exc:
            raise LinkError(f"cannot read the flags of {iface}: {exc.strerror}") from exc
        if flags & IFF_UP:
            return
        try:
            fcntl.ioctl(s, SIOCSIFFLAGS, _IFREQ_FLAGS.pack(iface.encode(), flags | IFF_UP))
        except OSError as exc:
            raise LinkError(
                f"interface {iface} is down and bringing it up needs CAP_NET_ADMIN: "
                f"run 'ip link set {iface} up' as root ({exc.strerror})"
            ) from exc


def has_carrier(iface: str) -> bool:
    """``iface`` is up with carrier (a veth whose peer is up, a NIC with a cable to a
    powered port); False also when it cannot be read. Ref: netdevice(7) IFF_RUNNING."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        req = _IFREQ_FLAGS.pack(iface.encode(), 0)
        try:
            _name, flags = _IFREQ_FLAGS.unpack_from(fcntl.ioctl(s, SIOCGIFFLAGS, req))
        except OSError:
            return False
    return bool(flags & IFF_UP and flags & IFF_RUNNING)


def _monotonic(stamp_ns: int) -> int:
    """A receive time stamp (CLOCK_REALTIME ns) on the monotonic clock: now minus how long
    ago it was; 0 (use now) without a stamp or if the wall clock was stepped."""
    if not stamp_ns:
        return 0
    age = time.time_ns() - stamp_ns
    if 0 <= age < MAX_RX_AGE_NS:
        return time.monotonic_ns() - age
    return 0


class RawLink:
    """AF_PACKET/SOCK_RAW on one interface; only EtherType 0x88A4 frames are delivered.

    An 802.1Q tag the kernel moved into metadata is put back into the buffer, so the
    caller sees (and replies with) the frame exactly as the master sent it.
    """

    ethernet = True
    rx_ns = 0
    #: fileno() is a packet socket: one recvmsg(2) is one frame, one send(2) one reply, so
    #: the daemon's compiled responder (decision P9) may use it directly
    raw_socket = True

    def __init__(self, iface: str, *, qdisc_bypass: bool = True, bring_up: bool = True) -> None:
        if not iface or len(iface) > 15:
            raise LinkError(f"interface name {iface!r}: use 1..15 characters, e.g. --iface ecat1")
        if not iface_exists(iface):
            raise LinkError(
                f"interface {iface!r} does not exist: create it (ip link add {iface} type veth "
                "peer name <peer>) or pass an existing --iface"
            )
        self.iface = iface
        try:
            # Protocol 0: the socket receives nothing until bind(), so no unfiltered frame
            # can be queued before the filter is attached.
            sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, 0)
        except PermissionError as exc:
            raise LinkError(
                f"opening a raw socket on {iface} needs CAP_NET_RAW: run as root or "
                "setcap cap_net_raw+ep on the Python interpreter"
            ) from exc
        try:
            attach_filter(sock, ECAT_FILTER)
            sock.setsockopt(SOL_PACKET, PACKET_AUXDATA, 1)
            sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCK_BUF)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SOCK_BUF)
            if qdisc_bypass:
                try:
                    sock.setsockopt(SOL_PACKET, PACKET_QDISC_BYPASS, 1)
                except OSError:
                    pass  # kernel < 3.14: the qdisc path works as well, a little slower
            sock.bind((iface, ETH_P_ALL))
        except OSError as exc:
            sock.close()
            if exc.errno == errno.ENODEV:
                raise LinkError(
                    f"interface {iface!r} does not exist: create it (ip link add ...) or pass "
                    "an existing --iface"
                ) from exc
            raise LinkError(f"cannot bind a raw socket to {iface}: {exc.strerror}") from exc
        sock.setblocking(False)
        self.sock = sock
        self._fd = sock.fileno()
        self._anc_size = _ANC_SIZE
        self.rx_ns = 0
        if bring_up:
            try:
                ensure_up(iface)
            except LinkError:
                sock.close()
                raise

    def fileno(self) -> int:
        return self.sock.fileno()

    def recv_into(self, buf: bytearray) -> int:
        """One frame into ``buf``; 0 if none was waiting (or it was our own outgoing one).
        The daemon's compiled responder receives the same way (ecatsim/ethercat/responder.pyx,
        decision P4); tests/unit/link/test_links.py runs both."""
        while True:
            try:
                n, anc, _flags, addr = self.sock.recvmsg_into([buf], self._anc_size)
            except BlockingIOError:
                return 0
            except OSError as exc:
                if exc.errno in (errno.EAGAIN, errno.EINTR, errno.ENETDOWN):
                    return 0
                raise
            if addr[2] == PACKET_OUTGOING:
                continue
            self.rx_ns = 0
            for level, typ, data in anc:
                if level == socket.SOL_SOCKET and typ == SO_TIMESTAMPNS:
                    sec, nsec = TIMESPEC.unpack_from(data)
                    self.rx_ns = _monotonic(sec * 1_000_000_000 + nsec)
                elif level == SOL_PACKET and typ == PACKET_AUXDATA and len(data) >= AUXDATA.size:
                    status, _l, _s, _m, _n, tci, tpid = AUXDATA.unpack_from(data)
                    if status & TP_STATUS_VLAN_VALID and n >= 12 and n + 4 <= len(buf):
                        if not status & TP_STATUS_VLAN_TPID_VALID:
                            tpid = ETH_P_8021Q
                        with memoryview(buf) as mv:
                            mv[16 : n + 4] = mv[12:n]  # memmove, no copy of the frame
                        _VLAN_TAG.pack_into(buf, 12, tpid, tci)
                        n += 4
            return n

    def send(self, frame: memoryview) -> None:
        """Send ``frame`` as is; a full queue or a vanished link drops it, as a wire would."""
        try:
            self.sock.send(frame)
        except OSError as exc:
            if exc.errno not in (errno.ENOBUFS, errno.EAGAIN, errno.ENETDOWN, errno.ENXIO):
                raise

    def close(self) -> None:
        self.sock.close()

"""EoE over the mailbox: Ethernet frames tunnelled both ways, and the IP parameter services.

The master's fragments are reassembled and handed to the slave's Ethernet side (a TAP
device, ecatsim/ethercat/eoe_tap.py); frames from that side wait here and are fragmented as
the master reads the mailbox, interleaved with CoE/FoE replies by the mailbox engine.
Control requests always get their EoE response type and a result code, never a mailbox
error reply (a master blocked in Set IP cannot handle one).
Ref: ETG.1000.6 §5.7 (EoE: fragments, Set IP Parameter, Get IP Parameter, Set Address
Filter, result codes).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import fields
from typing import Any, Protocol

import structlog

from ecatsim.slave.eoe_frag import FragCounters, Fragmenter, Reassembler
from ecatsim.slave.mailbox import MailboxEngine, MailboxError, Request
from ecatsim.wire.eoe import (
    EOE_HEADER_LEN,
    MAX_FRAME,
    EoeResult,
    EoeType,
    IpParams,
    control_header,
    decode_header,
    decode_ip_params,
    encode_ip_params,
)
from ecatsim.wire.mailbox import MbxError, MbxType

log = structlog.get_logger("ecatsim.eoe")

#: frames from the Ethernet side waiting for the mailbox; more are dropped (counted)
QUEUE_FRAMES = 32
#: the most address filter entries kept (the MACs of a Set Address Filter request)
MAX_FILTERS = 16


class EthernetSide(Protocol):
    """The slave's own network interface, as the EoE service uses it."""

    def write(self, frame: bytes) -> bool:
        """Hand one Ethernet frame to the interface; False if it was not taken."""
        ...

    def apply(self, params: IpParams) -> None:
        """Give the interface these addresses (raises OSError if it cannot)."""
        ...


class EoeService:
    """The EoE endpoint of one slave (one port, port 0)."""

    def __init__(self, mbx: MailboxEngine, params: IpParams | None = None) -> None:
        self.mbx = mbx
        self.params = params or IpParams()
        #: the slave's network interface; None: frames from the master are dropped
        self.side: EthernetSide | None = None
        #: run when frames from the Ethernet side wait (the firmware serves the mailbox)
        self.kick: Callable[[], None] | None = None
        self.rx = Reassembler()  # master -> slave
        self.tx = FragCounters()  # slave -> master
        self.queue: deque[bytes] = deque()
        self.current: Fragmenter | None = None
        self.frame_no = 0
        self.filters: tuple[bytes, ...] = ()
        #: control requests served, and those answered with a result other than success
        self.requests = 0
        self.refused = 0
        self.rx_undelivered = 0
        mbx.register(MbxType.EOE, self.handle)
        mbx.add_source(self)

    # ----------------------------------------------------------------- master -> slave

    def handle(self, req: Request) -> list[tuple[int, bytes]]:
        """One EoE mailbox. Ref: ETG.1000.6 §5.7."""
        data = req.data
        if len(data) < EOE_HEADER_LEN:
            raise MailboxError(MbxError.SIZE_TOO_SHORT)  # not even an EoE header
        h = decode_header(data)
        body = bytes(data[EOE_HEADER_LEN:])
        if h.ftype == EoeType.FRAGMENT:
            frame = self.rx.feed(h, body)
            if frame is not None:
                side = self.side
                if side is None or not side.write(frame):
                    self.rx_undelivered += 1
            return []
        self.requests += 1
        if h.ftype == EoeType.SET_IP_REQ:
            return self._answer(EoeType.SET_IP_RESP, self._set_ip(body), h.port)
        if h.ftype == EoeType.GET_IP_REQ:
            return self._answer(EoeType.GET_IP_RESP, EoeResult.SUCCESS, h.port,
                                encode_ip_params(self.params))  # fmt: skip
        if h.ftype == EoeType.SET_FILTER_REQ:
            return self._answer(EoeType.SET_FILTER_RESP, self._set_filter(body), h.port)
        # anything else (Get Address Filter, a response type, a reserved type): refused
        # with its response type (the request type + 1; a response type answered as is)
        rtype = h.ftype + 1 if h.ftype % 2 == 0 and h.ftype < 15 else h.ftype
        return self._answer(rtype, EoeResult.UNSUPPORTED_FRAME_TYPE, h.port)

    def _answer(
        self, rtype: int, result: int, port: int, data: bytes = b""
    ) -> list[tuple[int, bytes]]:
        if result != EoeResult.SUCCESS:
            self.refused += 1
        return [(MbxType.EOE, control_header(rtype, result, port) + data)]

    def _set_ip(self, body: bytes) -> int:
        """Set IP Parameter: the included fields replace the current ones; a new address
        or mask is given to the interface. Ref: ETG.1000.6 §5.7 (Set IP Parameter)."""
        p = decode_ip_params(body)
        if p is None:
            return EoeResult.UNSPECIFIED_ERROR
        new = IpParams(
            *(
                getattr(p, f.name)
                if getattr(p, f.name) is not None
                else getattr(self.params, f.name)
                for f in fields(IpParams)
            )
        )
        side = self.side
        if side is not None and (p.ip is not None or p.subnet is not None or p.mac is not None):
            try:
                side.apply(new)
            except OSError as exc:
                log.warning("eoe_set_ip_failed", slave=self.mbx.pdi.position, error=exc.strerror)
                return EoeResult.UNSPECIFIED_ERROR
        self.params = new
        log.info("eoe_ip_set", slave=self.mbx.pdi.position, ip=_dotted(new.ip))
        return EoeResult.SUCCESS

    def _set_filter(self, body: bytes) -> int:
        """Set Address Filter: the MAC filter entries are kept (and reported in status);
        the interface passes every frame. Ref: ETG.1000.6 §5.7 (Set Address Filter)."""
        if len(body) < 2:
            return EoeResult.UNSPECIFIED_ERROR
        count = body[0] & 0x0F
        macs = body[2 : 2 + 6 * count]
        if len(macs) < 6 * count or count > MAX_FILTERS:
            return EoeResult.UNSPECIFIED_ERROR
        self.filters = tuple(macs[i : i + 6] for i in range(0, len(macs), 6))
        return EoeResult.SUCCESS

    # ----------------------------------------------------------------- slave -> master

    def push(self, frame: bytes) -> None:
        """A frame from the Ethernet side, to go to the master."""
        if len(frame) > MAX_FRAME or len(self.queue) >= QUEUE_FRAMES:
            self.tx.dropped += 1
            return
        self.queue.append(frame)
        if self.kick is not None:
            self.kick()

    def pending(self) -> bool:
        """Fragments wait for the mailbox (the engine's source interface)."""
        return self.current is not None or bool(self.queue)

    def next_reply(self, max_body: int) -> tuple[int, bytes] | None:
        """The next fragment for SM1, fitting ``max_body`` bytes after the mailbox header."""
        while self.current is None:
            if not self.queue:
                return None
            frame = self.queue.popleft()
            try:
                self.current = Fragmenter(frame, self.frame_no, max_body - EOE_HEADER_LEN)
            except ValueError:
                self.tx.dropped += 1  # the mailbox is too small for any fragment
                continue
            self.frame_no = (self.frame_no + 1) & 0x0F
        body = self.current.next()
        self.tx.fragments += 1
        if self.current.done:
            self.tx.frames += 1
            self.current = None
        return (MbxType.EOE, body)

    def reset(self) -> None:
        """Mailbox start (IP/IB): frames in transit either way are forgotten."""
        if self.current is not None or self.queue:
            self.tx.dropped += len(self.queue) + (self.current is not None)
        self.queue.clear()
        self.current = None
        if self.rx.expect > 0:
            self.rx.counters.dropped += 1
        self.rx.expect = 0
        self.rx.buf = bytearray()

    # ----------------------------------------------------------------- status

    def status(self) -> dict[str, Any]:
        """Counters for ``ecatsim ctl status``: frames each way, fragments, drops."""
        return {
            "to_slave_frames": self.rx.counters.frames,
            "to_slave_fragments": self.rx.counters.fragments,
            "to_slave_dropped": self.rx.counters.dropped + self.rx_undelivered,
            "to_master_frames": self.tx.frames,
            "to_master_fragments": self.tx.fragments,
            "to_master_dropped": self.tx.dropped,
            "requests": self.requests,
            "refused": self.refused,
            "ip": _dotted(self.params.ip),
        }


def _dotted(ip: bytes | None) -> str:
    return ".".join(str(b) for b in ip) if ip is not None else ""


def find_eoe(mbx: object) -> EoeService | None:
    """The EoE service among a mailbox engine's sources, if the slave has one."""
    for src in getattr(mbx, "sources", ()):
        if isinstance(src, EoeService):
            return src
    return None

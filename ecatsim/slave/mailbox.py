"""The mailbox engine: SM0 in, SM1 out, counters, repeat requests and error replies.

Protocol handlers (CoE, FoE, EoE) get the mailbox data and return reply bodies;
mailbox-level problems become an error reply (type 0) in one place. A protocol with its
own traffic (EoE frames from the slave's network) is a *source*: asked for its next reply
only when SM1 is free, taking turns with the queued replies. Counters are given as a
reply goes into SM1.
Ref: ETG.1000.4 §5.6 (mailbox header, counter, error reply Table 30), §6.7.4 (repeat);
TMC8460 §5.49 Tables 90/91 (repeat request/ack).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import structlog

from ecatsim.esc.pdi import Pdi
from ecatsim.wire.mailbox import MBX_HEADER, MBX_HEADER_LEN, MbxError, MbxType, mbx_header

log = structlog.get_logger("ecatsim.mailbox")

SM_OUT = 0  # master -> slave
SM_IN = 1  # slave -> master
QUEUE_DEPTH = 16


@dataclass(frozen=True, slots=True)
class Request:
    """A received mailbox: type, counter and data after the 6-byte header."""

    mtype: int
    counter: int
    address: int
    channel: int
    data: bytes


class MailboxError(Exception):
    """A mailbox-level failure that becomes an error reply."""

    def __init__(self, code: MbxError) -> None:
        super().__init__(code.name)
        self.code = code


#: A protocol handler: request -> list of (type, reply data) to send back.
Handler = Callable[[Request], list[tuple[int, bytes]]]


class Source(Protocol):
    """A protocol with replies of its own, handed out one at a time as SM1 frees up."""

    def pending(self) -> bool: ...

    def next_reply(self, max_body: int) -> tuple[int, bytes] | None: ...

    def reset(self) -> None: ...


class MailboxEngine:
    """Serves SM0/SM1 for one slave through its PDI."""

    #: fixed attributes (compiled: the typed fields of mailbox.pxd)
    __slots__ = (
        "_turn",
        "accept",
        "counter",
        "drop_next",
        "error_next",
        "errors",
        "handlers",
        "held",
        "last_in_counter",
        "last_sent",
        "log",
        "out",
        "pdi",
        "repeat_ack",
        "sources",
        "stale_counter_next",
    )

    def __init__(self, pdi: Pdi) -> None:
        self.pdi = pdi
        self.handlers: dict[int, Handler] = {}
        #: which mailbox types are served now (BOOT serves FoE only)
        self.accept: Callable[[int], bool] = lambda mtype: True
        #: queued replies (type, data), framed when they go into SM1
        self.out: deque[tuple[int, bytes]] = deque()
        #: protocols with their own traffic, served in turn with ``out``
        self.sources: list[Source] = []
        self._turn = 0
        #: the framed reply waiting for SM1 to be free
        self.held: bytes | None = None
        self.last_sent = b""
        self.counter = 0
        self.last_in_counter = 0
        self.repeat_ack = False
        self.errors = 0
        #: injected faults: the next N requests get no reply; the next request gets this
        #: error reply; the next N replies repeat the previous counter
        self.drop_next = 0
        self.error_next: MbxError | None = None
        self.stale_counter_next = 0
        self.log = log.bind(slave=pdi.position)

    def reset(self) -> None:
        """Mailbox start (IP/IB): queues and counters cleared. Ref: ETG.1000.4 §5.6."""
        self.out.clear()
        self.held = None
        for src in self.sources:
            src.reset()
        self.last_sent = b""
        self.counter = 0
        self.last_in_counter = 0
        self.repeat_ack = self.pdi.sm_repeat_request(SM_IN)
        self.pdi.sm_repeat_ack(SM_IN, self.repeat_ack)

    def register(self, mtype: MbxType, handler: Handler) -> None:
        self.handlers[int(mtype)] = handler

    def add_source(self, src: Source) -> None:
        self.sources.append(src)

    def queued(self) -> bool:
        """Replies of the engine's own queue wait for SM1 (not asking the sources)."""
        return bool(self.out) or self.held is not None

    def pending(self) -> bool:
        """Replies wait for SM1 (the firmware then wants the SM1 event). Asked at every
        firmware service: a plain loop, not ``any()`` over a generator (decision P22), and
        compiled, a C call from the firmware (decision P41)."""
        if self.out or self.held is not None:  # queued(), inline: asked every cycle
            return True
        for src in self.sources:  # noqa: SIM110 (a generator per call costs 3 k instructions)
            if src.pending():
                return True
        return False

    # ----------------------------------------------------------------- receive

    def receive(self) -> None:
        """Read SM0 if full and dispatch it."""
        raw = self.pdi.sm_read(SM_OUT)
        if raw is None:
            return
        self.dispatch(raw)

    def dispatch(self, raw: bytes) -> None:
        """Serve one mailbox as read from SM0 (the header and the rest of the buffer)."""
        try:
            req = self._parse(raw)
            if req is None:
                return
            if self.drop_next:
                self.drop_next -= 1
                return
            if self.error_next is not None:
                code, self.error_next = self.error_next, None
                raise MailboxError(code)
            handler = self.handlers.get(req.mtype)
            if handler is None or not self.accept(req.mtype):
                raise MailboxError(MbxError.UNSUPPORTED_PROTOCOL)
            for mtype, body in handler(req):
                self.post(mtype, body)
        except MailboxError as exc:
            self.error_reply(exc.code)

    def _parse(self, raw: bytes) -> Request | None:
        """Validate the header. Ref: ETG.1000.4 §5.6 Table 28, error codes Table 30."""
        length, address, chan, tc = MBX_HEADER.unpack_from(raw)
        mtype = tc & 0x0F
        counter = (tc >> 4) & 0x07
        if length < 2:
            raise MailboxError(MbxError.SIZE_TOO_SHORT)
        if length > len(raw) - MBX_HEADER_LEN:
            raise MailboxError(MbxError.INVALID_SIZE)
        if chan & 0x3F:
            raise MailboxError(MbxError.INVALID_CHANNEL)
        if tc & 0x80:
            raise MailboxError(MbxError.INVALID_HEADER)
        if mtype == MbxType.ERR:
            raise MailboxError(MbxError.SYNTAX)  # a master never sends an error reply
        if counter and counter == self.last_in_counter:
            return None  # a repeated mailbox: already served
        self.last_in_counter = counter
        return Request(mtype, counter, address, chan, raw[MBX_HEADER_LEN : MBX_HEADER_LEN + length])

    # ----------------------------------------------------------------- send

    def error_reply(self, code: MbxError) -> None:
        """The one place a mailbox problem becomes an error reply (type 0, service 1).

        Ref: ETG.1000.4 §5.6 Table 30.
        """
        self.errors += 1
        self.log.info("mailbox_error", code=code.name)
        self.post(MbxType.ERR, (0x0001).to_bytes(2, "little") + int(code).to_bytes(2, "little"))

    def post(self, mtype: int, body: bytes) -> None:
        """Queue one reply; sent at once if SM1 is empty. A full queue answers with the
        'no more memory' error instead (the last place kept free for it)."""
        if len(self.out) >= QUEUE_DEPTH:
            self.log.warning("mailbox_queue_full")
            return
        if len(self.out) == QUEUE_DEPTH - 1 and mtype != MbxType.ERR:
            mtype = MbxType.ERR
            body = (0x0001).to_bytes(2, "little") + int(MbxError.NO_MORE_MEMORY).to_bytes(
                2, "little"
            )
        self.out.append((mtype, body))
        self.flush()

    def _frame(self, mtype: int, body: bytes) -> bytes:
        """Header and data, with the next counter. Ref: ETG.1000.4 §5.6 Table 28."""
        if self.stale_counter_next and self.counter:
            self.stale_counter_next -= 1  # injected: the previous counter again
        else:
            self.counter = self.counter % 7 + 1
        return mbx_header(len(body), mtype, self.counter) + body

    def _next(self) -> tuple[int, bytes] | None:
        """The next reply: the queue and each source in turn, so none starves another."""
        n = 1 + len(self.sources)
        for k in range(n):
            i = (self._turn + k) % n
            item: tuple[int, bytes] | None = None
            if i == 0:
                if self.out:
                    item = self.out.popleft()
            elif self.sources[i - 1].pending():
                item = self.sources[i - 1].next_reply(self.max_body())
            if item is not None:
                self._turn = (i + 1) % n
                return item
        return None

    def flush(self) -> None:
        """Write the next reply into SM1 if it is empty."""
        if self.held is None and not self.pending():
            return  # nothing to send: leave the SM registers (and their events) alone
        size = self.pdi.sm_settings(SM_IN).length
        while self.held is None:
            item = self._next()
            if item is None:
                return
            mtype, body = item
            if MBX_HEADER_LEN + len(body) > size:
                self.log.warning(
                    "mailbox_reply_too_large", size=MBX_HEADER_LEN + len(body), sm=size
                )
                continue
            self.held = self._frame(mtype, body)
        if self.pdi.sm_write(SM_IN, self.held):
            self.last_sent = self.held
            self.held = None

    def max_body(self) -> int:
        """Largest reply body that fits SM1 as the master configured it."""
        return self.pdi.sm_settings(SM_IN).length - MBX_HEADER_LEN

    def repeat(self) -> None:
        """Repeat request on SM1: put the last reply back and toggle the ack.

        Ref: ETG.1000.4 §6.7.4; TMC8460 §5.49 Tables 90, 91.
        """
        req = self.pdi.sm_repeat_request(SM_IN)
        if req == self.repeat_ack:
            return
        if self.last_sent:
            self.pdi.sm_write(SM_IN, self.last_sent)
        self.repeat_ack = req
        self.pdi.sm_repeat_ack(SM_IN, req)

"""Ports are wires: how a segment's ESCs are cabled, and the route a frame takes.

Each ESC's ports 0-3 connect to a port of another ESC, to nothing, or to an interface
(the daemon's own, where the master is, or ``--out-iface``, which leads out of the
process: the next daemon, a real slave, or the master's second NIC). A frame that enters
a port goes around the ESC's ports in the order 0 -> processing unit -> 3 -> 1 -> 2 -> 0:
an open port sends it out on its cable and the frame comes back in at that port, a
closed port passes it on to the next port inside the ESC. Only a frame coming in at port
0, or one passed on by a closed port 0, goes through the processing unit; one coming in
at port 1 from behind (cable redundancy) travels on unprocessed. Port 0 stays open when
every other port is closed.

The route is computed here when the cabling, a link or a loop setting changes
(``Segment`` keeps it), never per frame: the ESCs whose processing unit the frame passes
in order (their auto-increment positions), the interface it leaves on, whether an ESC
with a closed port 0 marks it circulating, and when it reaches each port (for the DC
receive times).
Ref: TMC8460 §5.17 Table 28 (0x0100 loop control: a closed port forwards to the next
open port), §5.19 (DL status), §5.50.1 (receive times), §5.50.2 Table 103; ETG.1000.4
§5.4 (circulating bit); the EtherCAT slave controller frame processing order.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

#: a port's cable: to nothing, to the daemon's interface (the master side), to the out
#: interface; otherwise ``4 * esc + port`` of the ESC port at its other end
NONE = -1
MAIN = -2
OUT = -3
#: where a route leaves: the daemon's interface, the out interface, nowhere (lost)
EXIT_MAIN = 0
EXIT_OUT = 1
EXIT_LOST = -1
#: the port after port p in the ESC's forwarding order 0 -> 3 -> 1 -> 2 -> 0
NEXT_PORT = (3, 2, 0, 1)
#: DcUnit.port_ns values: no stamp; stamped by a later frame (the port leads out)
NO_STAMP = -1
LATER = -2


class _Dc(Protocol):
    hop_ns: int
    turnaround_ns: int


class PortEsc(Protocol):
    """What the route needs of an ESC (ecatsim.esc.core.Esc)."""

    ports_link: int
    ports_open: int
    port0_closed: bool

    @property
    def dc(self) -> _Dc: ...


class Route:
    """The way a frame entering at one port goes through the segment."""

    __slots__ = ("circulating", "exit", "order", "port_ns", "stamps", "unit_ns")

    def __init__(self) -> None:
        #: ESC indices whose processing unit the frame passes, in order
        self.order: list[int] = []
        #: EXIT_MAIN, EXIT_OUT or EXIT_LOST (the frame is destroyed after the processing
        #: units in ``order`` saw it, as on the wire)
        self.exit = EXIT_LOST
        #: an ESC with a closed port 0 processes the frame (ETG.1000.4 §5.4)
        self.circulating = False
        #: per ESC processed: ns after entry the frame reaches its processing unit
        self.unit_ns: dict[int, int] = {}
        #: per ESC processed: ns after entry it comes back in at ports 0-3 (NO_STAMP, LATER)
        self.port_ns: dict[int, list[int]] = {}
        #: every (esc, port, ns after entry) the frame comes in at, in order
        self.stamps: list[tuple[int, int, int]] = []


def linear(n: int, out: bool = False) -> list[list[int]]:
    """The cabling of a line of ``n`` slaves: port 1 of each to port 0 of the next, port 0
    of the first to the daemon's interface, port 1 of the last to the out interface
    (``out``) or nothing."""
    wiring = []
    for i in range(n):
        up = MAIN if i == 0 else 4 * (i - 1) + 1
        down = 4 * (i + 1) if i + 1 < n else (OUT if out else NONE)
        wiring.append([up, down, NONE, NONE])
    return wiring


def out_port(wiring: Sequence[Sequence[int]]) -> tuple[int, int] | None:
    """The (esc, port) cabled to the out interface, if any."""
    for i, ports in enumerate(wiring):
        for p, w in enumerate(ports):
            if w == OUT:
                return i, p
    return None


def wired_mask(ports: Sequence[int], out_up: bool) -> int:
    """The ports (bit p) with a cable; the out interface's only while it has carrier."""
    mask = 0
    for p, w in enumerate(ports):
        if w >= 0 or w == MAIN or (w == OUT and out_up):
            mask |= 1 << p
    return mask


def check(wiring: Sequence[Sequence[int]]) -> None:
    """Every cable has two ends that name each other; ValueError otherwise."""
    for i, ports in enumerate(wiring):
        for p, w in enumerate(ports):
            if w >= 0:
                j, q = divmod(w, 4)
                if j >= len(wiring) or wiring[j][q] != 4 * i + p:
                    raise ValueError(f"slave {i} port {p}: the cable's other end does not match")


def trace(escs: Sequence[PortEsc], wiring: Sequence[Sequence[int]], i: int, p: int) -> Route:
    """The route of a frame entering ESC ``i`` at port ``p`` from an interface."""
    r = Route()
    if not escs[i].ports_link & (1 << p):
        return r  # no link: the frame is lost at the door
    t = 0
    turned = False  # the frame left the processing unit and no other port yet
    #: the ports the frame went out of downstream and has not come back in at yet
    away: list[tuple[int, int]] = []
    for _ in range(8 * len(escs) + 8):
        esc = escs[i]
        r.stamps.append((i, p, t))
        if away and away[-1] == (i, p):
            away.pop()
        if p and i in r.port_ns:
            r.port_ns[i][p] = t
        if p == 0:
            if i in r.unit_ns:
                return r  # a second pass: the circulating frame is destroyed (EXIT_LOST)
            r.order.append(i)
            r.unit_ns[i] = t
            r.port_ns[i] = [t, NO_STAMP, NO_STAMP, NO_STAMP]
            if esc.port0_closed:
                r.circulating = True
            turned = True
        q = NEXT_PORT[p]
        while q and not esc.ports_open & (1 << q):
            q = NEXT_PORT[q]  # a closed port passes the frame on to the next
        if q == 0:
            if not esc.ports_open & 1 and esc.ports_open & 0xE:
                p = 0  # a closed port 0 passes it on into the processing unit
                continue
            if turned:
                t += esc.dc.turnaround_ns  # it turns back at the end of a line
        turned = False
        if not esc.ports_link & (1 << q):
            return r  # sent out of an open port without a link: lost after processing
        w = wiring[i][q]
        if w in (MAIN, OUT):
            r.exit = EXIT_MAIN if w == MAIN else EXIT_OUT
            if w == OUT:  # these ports see the frame again when it comes back in at OUT
                for j, k in (*away, (i, q)):
                    if j in r.port_ns:
                        r.port_ns[j][k] = LATER
            return r
        if w < 0:
            return r
        if q:
            away.append((i, q))
        t += esc.dc.hop_ns
        i, p = divmod(w, 4)
    return r  # more hops than the cabling allows: a loop of cables (EXIT_LOST)


def describe(wiring: Sequence[Sequence[int]], names: Sequence[str]) -> list[str]:
    """The cabling as lines of text, one line per chain: the main line from the master,
    then each branch from its junction port. ``names``: a label per ESC."""
    lines: list[str] = []
    starts: list[tuple[str, int]] = [("master", 0)] if wiring else []
    seen: set[int] = set()
    while starts:
        head, i = starts.pop(0)
        parts = [head]
        while i >= 0 and i not in seen:
            seen.add(i)
            parts.append(names[i])
            for q in (3, 2):
                w = wiring[i][q]
                if w >= 0:
                    starts.append((f"{names[i]}.port{q}", w // 4))
                elif w == OUT:
                    starts.append((f"{names[i]}.port{q}", -1))
            w = wiring[i][1]
            if w == OUT:
                parts.append("out")
            i = w // 4 if w >= 0 else -1
        if head != "master" and len(parts) == 1:
            parts.append("out")
        lines.append(" - ".join(parts))
    return lines

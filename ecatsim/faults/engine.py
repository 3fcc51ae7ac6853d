"""The fault engine: arms faults, fires their triggers, and acts on the segment.

The daemon asks it three things, and only while something is armed (``active``): after
each frame (``after_frame``: counts frames, starts faults, fires one-shot and condition
faults), before each reply while a wire fault is live (``on_reply``), and at its timers
(``next_deadline``/``poll``: time windows, power returning after a power cycle). With no
fault armed the frame path checks one attribute.

Triggers (one of): at once, ``after_frames`` N (the first N frames pass untouched),
``after_s`` T after arming, ``on_state`` (the target slave, or for a segment fault every
reachable slave, reaches the AL state). ``probability`` gates each frame once started,
from ``random.Random(seed)``; ``for_s`` ends the fault that long after it started.
Ref: issue "reliability"; docs/decisions.md R1-R6.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from typing import Any

import structlog

from ecatsim.device.drive import Drive
from ecatsim.esc import regs
from ecatsim.ethercat.segment import Segment
from ecatsim.faults.spec import Family, FaultSpec, FaultSpecError
from ecatsim.faults.wire import patch
from ecatsim.slave.al import RANK, AlState
from ecatsim.slave.firmware import Firmware
from ecatsim.wire.mailbox import MbxError

log = structlog.get_logger("ecatsim.faults")

NS = 1_000_000_000


def fall_target(state: AlState) -> AlState:
    """Where an ``al_fall`` leaves a slave in ``state``: the lower of ``state`` and SAFEOP
    (a local error never raises the state; INIT, PREOP and BOOT keep theirs).

    Ref: ETG.1000.6 §6.4.1.4 (local error: the slave goes to a lower state and sets the
    error indication).
    """
    return state if RANK[state] <= RANK[AlState.SAFEOP] else AlState.SAFEOP


@dataclass(slots=True)
class Armed:
    """One armed fault and its progress."""

    id: int
    spec: FaultSpec
    target: int | None
    armed_ns: int
    armed_frame: int
    rng: random.Random | None
    started: bool = False
    start_ns: int = 0
    fired: int = 0
    held: bool = False
    done: bool = False

    def status(self) -> dict[str, Any]:
        out = {"id": self.id, **self.spec.describe(), "started": self.started}
        out["fired"] = self.fired
        if self.target is not None:
            out["slave"] = self.target
        return out


@dataclass(slots=True)
class PowerReturn:
    due_ns: int
    position: int


@dataclass
class FaultEngine:
    """The armed faults of one segment."""

    segment: Segment
    faults: list[Armed] = field(default_factory=list)
    powered_off: list[PowerReturn] = field(default_factory=list)
    frames: int = 0
    fired_total: int = 0
    #: anything armed or pending: the daemon calls after_frame / poll
    active: bool = False
    #: a started wire fault: the daemon calls on_reply before sending
    wire_live: bool = False
    _next_id: int = 1

    # ----------------------------------------------------------------- arming

    def add(self, spec: FaultSpec, now_ns: int) -> int:
        """Arm a fault; it may start at once. Returns its id."""
        target = self._resolve(spec)
        self._check_applies(spec, target)
        rng = random.Random(spec.seed) if spec.probability is not None else None
        a = Armed(self._next_id, spec, target, now_ns, self.frames, rng)
        self._next_id += 1
        self.faults.append(a)
        log.info("fault_armed", id=a.id, **spec.describe())
        self._evaluate(a, now_ns, frame=False)
        self._refresh()
        return a.id

    def clear(self, fault_id: int | None, now_ns: int, kind: str | None = None) -> int:
        """Remove faults (all, one id, or every fault of a kind); undo held conditions."""
        n = 0
        for a in self.faults:
            if (fault_id is None or a.id == fault_id) and (kind is None or a.spec.kind == kind):
                self._end(a)
                n += 1
        self._refresh()
        return n

    def _check_applies(self, spec: FaultSpec, pos: int | None) -> None:
        """Refuse, when it is armed, a fault its slave cannot have: an AL fault needs
        ecatsim's firmware, a mailbox fault a mailbox."""
        if pos is None or pos >= len(self.segment.firmware):
            return
        fw = self.segment.firmware[pos]
        if spec.kind in ("al_refuse", "al_fall") and not isinstance(fw, Firmware):
            raise FaultSpecError(
                f"slave: slave {pos} has no ecatsim firmware to {spec.kind.removeprefix('al_')}"
                " an AL state (its AL status follows the ESC or external firmware)"
            )
        if spec.kind.startswith(("mbx_", "sdo_")) and getattr(fw, "mbx", None) is None:
            raise FaultSpecError(f"slave: slave {pos} has no mailbox for {spec.kind}")

    def _resolve(self, spec: FaultSpec) -> int | None:
        escs = self.segment.escs
        if spec.alias is not None:
            for i, esc in enumerate(escs):
                m = esc.mem
                if m[regs.STATION_ALIAS] | (m[regs.STATION_ALIAS + 1] << 8) == spec.alias:
                    return i
            raise FaultSpecError(f"alias: no slave has the alias {spec.alias:#06x}")
        if spec.slave is not None and spec.slave >= len(escs):
            raise FaultSpecError(f"slave: no slave {spec.slave} (the segment has {len(escs)})")
        return spec.slave

    # ----------------------------------------------------------------- the daemon's hooks

    def after_frame(self, now_ns: int) -> None:
        """Count a frame (its reply has gone), then start and fire what is due."""
        self.frames += 1
        self._poll(now_ns, frame=True)

    def poll(self, now_ns: int) -> None:
        """Timers: windows ending, delayed starts, power returning."""
        self._poll(now_ns, frame=False)

    def on_reply(self, buf: bytearray, off: int, n: int) -> tuple[int, int]:
        """Apply live wire faults to the reply: (copies to send, delay in ns)."""
        copies, delay_ns = 1, 0
        for a in self.faults:
            if a.done or not a.started or a.spec.family is not Family.WIRE:
                continue
            if a.rng is not None and a.rng.random() >= (a.spec.probability or 0.0):
                continue
            spec = a.spec
            if spec.kind == "delay":
                delay_ns += spec.value * 1000
            else:
                copies *= patch(spec.kind, spec.value, buf, off, n)
            self._fired(a)
        if any(a.done for a in self.faults):
            self._refresh()
        return copies, delay_ns

    def next_deadline(self) -> int | None:
        """The earliest time-based event (ns), or None."""
        ds = [p.due_ns for p in self.powered_off]
        for a in self.faults:
            s = a.spec
            if not a.started and s.after_s is not None:
                ds.append(a.armed_ns + int(s.after_s * NS))
            elif a.started and s.for_s is not None:
                ds.append(a.start_ns + int(s.for_s * NS))
        return min(ds) if ds else None

    def status(self) -> list[dict[str, Any]]:
        return [a.status() for a in self.faults]

    # ----------------------------------------------------------------- evaluation

    def _poll(self, now_ns: int, frame: bool) -> None:
        if self.powered_off:
            for p in [p for p in self.powered_off if p.due_ns <= now_ns]:
                self.powered_off.remove(p)
                self._power_on(p.position)
        for a in self.faults:
            if not a.done:
                self._evaluate(a, now_ns, frame)
        self._refresh()

    def _evaluate(self, a: Armed, now_ns: int, frame: bool) -> None:
        s = a.spec
        if not a.started:
            if not self._due(a, now_ns):
                return
            a.started = True
            a.start_ns = now_ns
            log.info("fault_started", id=a.id, kind=s.kind)
            frame = True  # a one-shot may fire on the event that started it
        if s.for_s is not None and now_ns - a.start_ns >= int(s.for_s * NS):
            self._end(a)
            return
        if s.family is Family.WIRE or not frame:
            return
        if a.rng is not None and a.rng.random() >= (s.probability or 0.0):
            return
        if s.family is Family.CONDITION:
            if not a.held:
                a.held = True
                self._condition(a, True)
                a.fired += 1
                self.fired_total += 1
            return
        # a one-shot: with a probability one unit per firing, else all of count at once
        units = 1 if a.rng is not None else (s.count or 1)
        self._once(a, units, now_ns)
        a.fired += units - 1
        self._fired(a, force_done=a.rng is None)

    def _due(self, a: Armed, now_ns: int) -> bool:
        s = a.spec
        if s.after_frames is not None:
            return self.frames - a.armed_frame >= s.after_frames
        if s.after_s is not None:
            return now_ns - a.armed_ns >= int(s.after_s * NS)
        if s.on_state is not None:
            return self._in_state(a.target, s.on_state)
        return True

    def _in_state(self, target: int | None, state: AlState) -> bool:
        seg = self.segment
        escs = seg.chain if target is None else [seg.escs[target]]
        return bool(escs) and all((e.mem[regs.AL_STATUS] & 0x0F) == state for e in escs)

    def _fired(self, a: Armed, force_done: bool = False) -> None:
        a.fired += 1
        self.fired_total += 1
        if force_done or (a.spec.count is not None and a.fired >= a.spec.count):
            a.done = True

    def _end(self, a: Armed) -> None:
        if a.held:
            a.held = False
            self._condition(a, False)
        if not a.done:
            log.info("fault_ended", id=a.id, kind=a.spec.kind, fired=a.fired)
        a.done = True

    def _refresh(self) -> None:
        self.faults = [a for a in self.faults if not a.done]
        self.wire_live = any(a.started and a.spec.family is Family.WIRE for a in self.faults)
        self.active = bool(self.faults or self.powered_off)

    # ----------------------------------------------------------------- actions

    def _condition(self, a: Armed, on: bool) -> None:
        """Hold (or release) a condition fault on its slave."""
        s, pos = a.spec, a.target
        assert pos is not None
        if s.kind == "link_down":
            self.set_cable(pos, s.port, not on)
        else:
            drive = getattr(self.segment.firmware[pos], "device", None)
            if not isinstance(drive, Drive):
                raise FaultSpecError(f"slave: slave {pos} has no drive for {s.kind}")
            drive.inject(s.kind, on)

    def _once(self, a: Armed, units: int, now_ns: int) -> None:
        """Perform a one-shot fault on its slave. Ref: ETG.1000.6 §6.4.1.4 (AL), ETG.1000.4
        §5.6 (mailbox), ETG.1000.6 §5.6.2 (SDO)."""
        s, pos = a.spec, a.target
        assert pos is not None
        seg = self.segment
        fw: Any = seg.firmware[pos] if pos < len(seg.firmware) else None
        if s.kind == "power_cycle":
            self._power_off(pos, now_ns, now_ns + s.value * 1_000_000)
        elif s.kind == "al_refuse":  # the slave has ecatsim's firmware (_check_applies)
            fw.refuse_next = s.code
        elif s.kind == "al_fall":  # a fall goes down, never up (decision O2)
            fw.fail(fall_target(fw.state), s.code, now_ns)
        else:
            mbx = getattr(fw, "mbx", None)
            if mbx is None:
                raise FaultSpecError(f"slave: slave {pos} has no mailbox for {s.kind}")
            if s.kind == "mbx_drop":
                mbx.drop_next += units
            elif s.kind == "mbx_error":
                mbx.error_next = MbxError(s.code)
            elif s.kind == "mbx_counter":
                mbx.stale_counter_next += units
            else:
                sdo = getattr(getattr(fw, "coe", None), "sdo", None)
                if sdo is None:
                    raise FaultSpecError(f"slave: slave {pos} has no SDO server for {s.kind}")
                if s.kind == "sdo_abort":
                    sdo.forced_aborts[s.index] = (s.sub, s.code)
                else:
                    sdo.toggle_error_next = True
        log.info("fault_fired", id=a.id, kind=s.kind, slave=pos)

    def set_cable(self, pos: int, port: int, up: bool) -> None:
        """The cable at ``pos``'s ``port`` (0-3) goes down or up: both ends see it (one end
        only where the cable leads to an interface). Ref: TMC8460 §5.19 (DL status),
        §5.38 (lost link counter)."""
        seg = self.segment
        seg.escs[pos].set_link(port, up)
        peer = seg.peer(pos, port)
        if peer is not None:
            seg.escs[peer[0]].set_link(peer[1], up)

    def _power_off(self, pos: int, now_ns: int, due_ns: int) -> None:
        """No power: both cables are dead until the slave powers up again, and the device
        behind the PDI stops as it does leaving OP."""
        fw: Any = self.segment.firmware[pos] if pos < len(self.segment.firmware) else None
        app = getattr(fw, "app", None)
        if app is not None:
            app.al_state_changed(AlState.INIT, now_ns)
        self.segment.escs[pos].dc.reset_sync()  # no power, no SYNC pulses
        self.segment.ctx.timers_dirty = True
        self.set_cable(pos, 0, False)
        self.set_cable(pos, 1, False)
        self.powered_off.append(PowerReturn(due_ns, pos))
        self.active = True

    def _power_on(self, pos: int) -> None:
        """Power returns: registers back to reset, EEPROM reloaded, the firmware and the
        device restart. Ref: TMC8460 §5 (reset values), §5.45 (EEPROM load after reset)."""
        esc = self.segment.escs[pos]
        esc.hardware_reset()
        self.set_cable(pos, 0, True)
        self.set_cable(pos, 1, True)
        log.info("power_returned", slave=pos)

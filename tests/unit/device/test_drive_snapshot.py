"""``Drive._snapshot`` reads only the mode's OD values where that is exact (decision P82).

Enabled in csp, csv or cst the steady demand reads only the mode's targets; the others are
read (``_snapshot_all``) before a ramp's demand or before a stop's fault, EMCY, log or
index pulse. Twin drives, one reading every value every time (a subclass whose _snapshot
is _snapshot_all), go through the same random walk of modes, controlwords, targets far
enough to trip the following error window and the current limit, quick stop options and
deceleration written between cycles, injected faults and AL changes, with the encoder's
index wired, and end every step alike: the object dictionary, the drive's fields, the
servo, the logs, the EMCYs and the index pulses.

Ref: CiA 402-2 §8 (FSA), §10-§12 (modes); TMC8670 §5.1.14 (encoder index).
"""

from __future__ import annotations

import random

import pytest

from ecatsim.device.description import default_description
from ecatsim.device.drive import CSP, CST, CSV, HM, PP, PV, Drive
from ecatsim.slave.al import AlState
from ecatsim.slave.od_build import build_od
from tests.support.drive_twins import Log, drive_state, perturb

MS = 1_000_000


class FullSnapshot(Drive):
    """The reference: every OD value the substeps use, read at every advance()."""

    def _snapshot(self) -> None:
        self._bind()  # the OD's entries (looked up once; binding again finds the same)
        self._snapshot_all()


def make(cls: type[Drive]) -> tuple[Drive, list[object]]:
    seen: list[object] = []
    d = cls(
        build_od(default_description()),
        None,
        lambda c, r, b: seen.append(("emcy", c, r, b)),
        lambda: seen.append("clear"),
    )
    d.log = Log(seen)
    d.index_output = lambda level, t: seen.append(("index", level, t))
    d.al_state_changed(AlState.OP, 0)
    return d, seen


def state_of(d: Drive) -> tuple[object, ...]:
    return drive_state(d)


@pytest.mark.parametrize("seed", range(16))
def test_the_modes_own_snapshot_is_the_full_snapshot(seed: int) -> None:
    rng = random.Random(seed)
    lazy, seen_a = make(Drive)
    full, seen_b = make(FullSnapshot)
    t = 0
    cw = 0x0F
    mode = rng.choice([CSP, CSV, CST])
    target = 0
    partial = 0
    for step in range(800):
        t += rng.choice([MS, MS, MS // 3, 2 * MS, 7 * MS])
        if step % 20 < 5:  # fault reset, then enable: back to Operation enabled
            cw = (0x00, 0x80, 0x06, 0x07, 0x0F)[step % 20]
        elif rng.random() < 0.03:
            cw = rng.choice([0x06, 0x07, 0x0B, 0x80, 0x10F, 0x1F, 0x00])
        if rng.random() < 0.06:
            mode = rng.choice([CSP, CSP, CSP, CSV, CSV, CST, CST, PV, PP, HM])
        target += rng.choice([0, 0, 0, 40, -40, 300, -300])
        if rng.random() < 0.03:
            target += 60000  # far: a following error where a window is set
        sets = {
            0x6040: cw,
            0x6060: mode,
            0x607A: target,
            0x60FF: rng.choice([0, 100, -800, 3000]),
            0x6071: rng.choice([0, 50, -300, 1000]),
        }
        if rng.random() < 0.1:
            sets[0x6085] = rng.choice([2, 500, 2000, 50000, 50000])  # quick stop deceleration
        if rng.random() < 0.1:
            sets[0x605A] = rng.choice([0, 2, 5, 6])
        if rng.random() < 0.1:
            sets[0x6065] = rng.choice([50, 1000, 5000, 0xFFFFFFFF, 0])
        if rng.random() < 0.05:
            sets[0x60B0] = rng.randint(-100, 100)
            sets[0x60B1] = rng.randint(-50, 50)
            sets[0x60B2] = rng.randint(-20, 20)
        if rng.random() < 0.05:
            sets[0x6083] = rng.choice([1, 1000, 100000])
            sets[0x6084] = rng.choice([1, 1000, 100000])
        fault = rng.random()
        al = rng.random()
        for d in (lazy, full):
            perturb(d, sets, fault, al, t, release=0.1)
        if lazy.state.name == "OPERATION_ENABLED" and lazy.mode in (CSP, CSV, CST):
            partial += 1
        late = t + rng.choice([0, MS // 2])
        for d in (lazy, full):
            d.outputs_applied(t)
            d.update_inputs(late)
        t = late
        assert state_of(lazy) == state_of(full), f"step {step}"
        assert seen_a == seen_b, f"step {step}"
    assert partial > 20, partial  # the mode's own snapshot ran
    kinds = {x[0] if isinstance(x, tuple) else x for x in seen_a}
    assert {"emcy", "index"} <= kinds, kinds  # stops with faults and index pulses ran


@pytest.mark.parametrize("seed", range(4))
def test_the_kept_state_bits_follow_every_state(seed: int) -> None:
    """_publish keeps the statusword bits of the state it saw last (decision P83): after
    every change of state, by controlword, fault, fault reset or AL change, bits 0-3, 5
    and 6 are those of the new state. Ref: CiA 402-2 §8.1.3 (Table 30); TMC8670 Table 80."""
    from ecatsim.device import cia402

    rng = random.Random(seed)
    d, _ = make(Drive)
    t = 0
    states = set()
    for step in range(400):
        t += MS
        if rng.random() < 0.8:
            cw = (0x80, 0x06, 0x07, 0x0F, 0x0F, 0x0F)[step % 6]  # fault reset, enable
        else:
            cw = rng.choice([0x00, 0x02, 0x06, 0x07, 0x0B])
        d.od.set(0x6040, 0, cw)
        r = rng.random()
        if r < 0.02:
            d.inject("overcurrent")
        elif r < 0.2:
            d.inject("overcurrent", False)
        elif r < 0.23:
            d.al_state_changed(rng.choice([AlState.OP, AlState.SAFEOP]), t)
        d.outputs_applied(t)
        d.update_inputs(t)
        states.add(d.state)
        mask = 0x6F
        assert int(d.od.value(0x6041)) & mask == cia402.STATUS_BITS[d.state] & mask, d.state
    assert len(states) >= 5, states

"""The compiled core's drive against the same source run as Python (drive.py): two drives
take the same random controlwords, modes, targets, faults and time steps, and must agree
on every OD value and every piece of state after each step. Ref: ecatsim/device/drive.py;
decisions P2, P5."""

from __future__ import annotations

import random
from typing import Any

import pytest

from ecatsim.device import drive
from ecatsim.device.description import default_description
from ecatsim.device.drive import CSP, CST, CSV, HM, PP, PV
from ecatsim.slave.al import AlState
from ecatsim.slave.od_build import build_od
from tests.support.core import require_compiled, source_twin

MS = 1_000_000
STATE = (
    "state",
    "mode",
    "prev_cw",
    "t_ns",
    "p_demand",
    "v_demand_rpm",
    "v_ff_rpm",
    "last_target",
    "last_t_ns",
    "set_point_ack",
    "homing_done",
    "homing_active",
    "fault_code",
    "q_60ff",
    "q_607a",
    "q_6071",
    "q_6065",
)
#: the controlword that leads from a state towards Operation enabled (CiA 402-2 §8)
RECOVER = {"FAULT": 0x80, "SWITCH_ON_DISABLED": 0x06, "READY_TO_SWITCH_ON": 0x07}
SERVO = ("angle", "omega", "iq_ma", "iq_integ", "integ", "iq_ref_ma", "i_limit_ma")


@pytest.fixture(autouse=True)
def _require_compiled() -> None:
    require_compiled(drive)


def make(module: Any) -> tuple[Any, list[int]]:
    """A drive of ``module`` in AL OP, and the emergency codes it sends."""
    emcys: list[int] = []
    d = module.Drive(build_od(default_description()), None, lambda c, r, b: emcys.append(c))
    d.al_state_changed(AlState.OP, 0)
    return d, emcys


def snapshot(d: Any) -> tuple[object, ...]:
    od = d.od
    d.pub_flush()  # the values the drive keeps for its entries, as any OD read sees them
    values = [(o.index, s, e.value) for o in od.objects.values() for s, e in o.entries.items()]
    return (
        values,
        [getattr(d, k) for k in STATE],
        [getattr(d.servo, k) for k in SERVO],
        sorted(d.active_faults),
    )


def run(seed: int, drives: list[Any], check: Any) -> None:
    """Drive ``drives`` through the same random run; ``check()`` after every step."""
    rng = random.Random(seed)
    t = 0
    mode = CSP
    for step in range(300):
        t += rng.choice([MS, MS, MS // 4, 3 * MS, 7 * MS // 3])
        sets: dict[int, int] = {}
        r = rng.random()
        if step < 3:
            cw = (0x06, 0x07, 0x0F)[step]
            sets[0x6060] = mode
        elif r < 0.05:
            mode = rng.choice([PP, PV, HM, CSP, CSV, CST])
            sets[0x6060] = mode
            cw = 0x0F
        elif r < 0.09:
            cw = rng.choice([0x00, 0x02, 0x06, 0x07, 0x80, 0x0B, 0x1F, 0x5F, 0x10F])
        else:  # steady, or back to enabled along the state machine
            cw = RECOVER.get(drives[0].state.name) or rng.choice([0x0F, 0x0F, 0x1F])
        sets[0x607A] = rng.randint(-20000, 20000) + step * 40
        sets[0x60FF] = rng.randint(-1500, 1500)
        sets[0x6071] = rng.randint(-800, 800)
        if rng.random() < 0.02:
            sets[0x6065] = rng.choice([5, 50, 0xFFFFFFFF])
        fault = rng.random() < 0.01
        for d in drives:
            for index, value in sets.items():
                d.od.set(index, 0, value)
            d.od.set(0x6040, 0, cw)
            if fault:
                d.inject("overcurrent")
                d.inject("overcurrent", False)
            d.outputs_applied(t)
            d.update_inputs(t)
        check(step)


@pytest.mark.parametrize("seed", range(12))
def test_compiled_drive_matches_its_source(seed: int) -> None:
    a, emcy_a = make(drive)
    b, emcy_b = make(source_twin(drive))
    assert type(a) is not type(b)

    def same(step: int) -> None:
        assert snapshot(a) == snapshot(b), f"step {step}"
        assert emcy_a == emcy_b

    run(seed, [a, b], same)


def test_the_runs_reach_every_mode_and_the_fault_states() -> None:
    """The comparison above covers each mode enabled, the quick stop and the fault path."""
    seen: set[tuple[str, int]] = set()
    for seed in range(12):
        d, _ = make(drive)
        run(seed, [d], lambda step, d=d: seen.add((d.state.name, d.mode)))
    enabled = {mode for state, mode in seen if state == "OPERATION_ENABLED"}
    assert enabled >= {PP, PV, HM, CSP, CSV, CST}
    states = {state for state, _ in seen}
    assert {"QUICK_STOP_ACTIVE", "FAULT", "SWITCH_ON_DISABLED"} <= states

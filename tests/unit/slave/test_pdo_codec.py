"""The one-struct process image codec gives exactly the bytes of the per-entry path.
Ref: ETG.1000.6 §5.6.7.4 (PDO mapping), Table 64 (data types)."""

from __future__ import annotations

import struct

from ecatsim.device.description import default_description
from ecatsim.device.drive import Drive
from ecatsim.slave.od_build import build_od
from ecatsim.slave.pdo import CycleDevice, Field, PdoImage, Plan, codec, compile_plan


class Quiet:
    def outputs_applied(self, now_ns: int) -> None: ...

    def update_inputs(self, now_ns: int) -> None: ...

    def al_state_changed(self, state: object, now_ns: int) -> None: ...


def slow(plan: Plan) -> Plan:
    return Plan(plan.rx, plan.tx, plan.rx_size, plan.tx_size)


def test_default_images_have_a_codec_and_it_matches_the_slow_path() -> None:
    od = build_od(default_description())
    img = PdoImage(od, Quiet())  # type: ignore[arg-type]
    plan = img.plan
    assert plan.rx_codec is not None and plan.rx_codec.st.format == "<Hihi"
    assert plan.tx_codec is not None and plan.tx_codec.st.format == "<HbihiI"
    out = struct.pack("<HihI", 0x1F, -123456, -300, 0xFFFFFF38)
    img.set_outputs(out, 0)
    fast_rx = [od.value(i, 0) for i in (0x6040, 0x607A, 0x6071, 0x60FF)]
    assert fast_rx == [0x1F, -123456, -300, -200]
    img.plan = slow(plan)
    img.set_outputs(out, 0)
    assert [od.value(i, 0) for i in (0x6040, 0x607A, 0x6071, 0x60FF)] == fast_rx
    img.plan = plan
    for index, value in ((0x6041, 0x1637), (0x6061, -3), (0x6064, -99), (0x6077, 12)):
        od.set(index, 0, value)
    fast = img.get_inputs(0)
    img.plan = slow(plan)
    assert img.get_inputs(0) == fast
    od.set(0x6077, 0, 1 << 20)  # out of INTEGER16 range: the masked per-entry encoding
    img.plan = plan
    masked = img.get_inputs(0)
    img.plan = slow(plan)
    assert img.get_inputs(0) == masked


def test_no_codec_for_types_struct_cannot_carry() -> None:
    od = build_od(default_description())
    e = od.entry(0x1008, 0)  # a VISIBLE_STRING
    assert codec((Field(0, 4, e),), 4) is None
    assert codec((Field(0, 2, None), Field(2, 2, od.entry(0x6040, 0))), 6) is not None
    assert compile_plan(od).tx_size == 17


class Recorder(CycleDevice):
    """A CycleDevice: the compiled process image calls its overrides in C (P32)."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, int]] = []

    def outputs_applied(self, now_ns: int) -> None:
        self.calls.append(("out", now_ns))

    def update_inputs(self, now_ns: int) -> None:
        self.calls.append(("in", now_ns))


def test_the_cycle_reaches_a_cycle_device_and_a_plain_one_alike() -> None:
    od = build_od(default_description())
    rec = Recorder()
    img = PdoImage(od, rec)
    assert img.device is rec
    img.set_outputs(bytes(12), 5)
    img.get_inputs(7)
    assert rec.calls == [("out", 5), ("in", 7)]

    class Plain(Quiet):
        def __init__(self) -> None:
            self.calls: list[tuple[str, int]] = []

        def outputs_applied(self, now_ns: int) -> None:
            self.calls.append(("out", now_ns))

        def update_inputs(self, now_ns: int) -> None:
            self.calls.append(("in", now_ns))

    plain = Plain()
    img.device = plain  # type: ignore[assignment]  # replaced: the new one is called
    img.set_outputs(bytes(12), 9)
    img.get_inputs(11)
    assert plain.calls == [("out", 9), ("in", 11)] and rec.calls == [("out", 5), ("in", 7)]
    img.device = rec
    img.get_inputs(13)
    assert rec.calls[-1] == ("in", 13)


def test_the_drive_is_a_cycle_device() -> None:
    assert issubclass(Drive, CycleDevice)
    assert not isinstance(Quiet(), CycleDevice)

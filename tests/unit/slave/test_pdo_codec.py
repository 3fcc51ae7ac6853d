"""The one-struct process image codec gives exactly the bytes of the per-entry path.
Ref: ETG.1000.6 §5.6.7.4 (PDO mapping), Table 64 (data types)."""

from __future__ import annotations

import random
import struct
from dataclasses import replace

from ecatsim.device.description import default_description
from ecatsim.device.drive import Drive
from ecatsim.slave.al import AlState
from ecatsim.slave.od import ObjectDictionary
from ecatsim.slave.od_build import build_od
from ecatsim.slave.pdo import CycleDevice, Field, PdoImage, Plan, codec, compile_plan
from tests.support.pdo_mappings import every_mapping, set_mapping


class Quiet:
    def outputs_applied(self, now_ns: int) -> None: ...

    def update_inputs(self, now_ns: int) -> None: ...

    def al_state_changed(self, state: object, now_ns: int) -> None: ...


def slow(plan: Plan) -> Plan:
    return Plan(plan.rx, plan.tx, plan.rx_size, plan.tx_size)


def test_default_images_have_a_codec_and_it_matches_the_slow_path() -> None:
    od = build_od(default_description())
    img = PdoImage(od, Quiet())
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


class Calls:
    """Records the cycle's calls to a device."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, int]] = []

    def outputs_applied(self, now_ns: int) -> None:
        self.calls.append(("out", now_ns))

    def update_inputs(self, now_ns: int) -> None:
        self.calls.append(("in", now_ns))

    def al_state_changed(self, state: object, now_ns: int) -> None: ...


class Recorder(Calls, CycleDevice):
    """A CycleDevice: the compiled process image calls its overrides in C (P32)."""


def test_the_cycle_reaches_a_cycle_device_and_a_plain_one_alike() -> None:
    od = build_od(default_description())
    rec = Recorder()
    img = PdoImage(od, rec)
    assert img.device is rec
    img.set_outputs(bytes(12), 5)
    img.get_inputs(7)
    assert rec.calls == [("out", 5), ("in", 7)]

    class Plain(Calls, Quiet):
        """A device that is not a CycleDevice: called through Python."""

    plain = Plain()
    img.device = plain  # replaced: the new one is called
    img.set_outputs(bytes(12), 9)
    img.get_inputs(11)
    assert plain.calls == [("out", 9), ("in", 11)] and rec.calls == [("out", 5), ("in", 7)]
    img.device = rec
    img.get_inputs(13)
    assert rec.calls[-1] == ("in", 13)


def test_the_drive_is_a_cycle_device() -> None:
    assert issubclass(Drive, CycleDevice)
    assert not isinstance(Quiet(), CycleDevice)


def _edges(bits: int, signed: bool) -> list[int]:
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    return [lo, hi, lo - 1, hi + 1, 0, -1, 1, 1 << 40, -(1 << 70), 1 << 64, True, 7]


def test_the_c_codec_is_the_struct_and_the_per_entry_path_for_every_mapping() -> None:
    """Every mapping the TMC8670 allows: outputs decoded from random bytes, inputs
    encoded from each field type's edges, values beyond its range (masked), negative
    values of unsigned fields, values beyond 64 bits and a bool: the C codec (P33), the
    struct and the per-entry path give the same values and bytes."""
    rnd = random.Random(33)
    od = build_od(default_description())
    img = PdoImage(od, Quiet())
    for rx in (True, False):
        for mapping in every_mapping(od, rx):
            set_mapping(od, 0x1600 if rx else 0x1A00, mapping)
            plan = compile_plan(od)
            codec_ = plan.rx_codec if rx else plan.tx_codec
            assert codec_ is not None and codec_.layout is not None
            img.plan = plan
            fields = plan.rx if rx else plan.tx
            entries = [f.entry for f in fields if f.entry is not None]
            if rx:
                for _ in range(20):
                    data = rnd.randbytes(plan.rx_size)
                    got = []
                    for p in (plan, replace(plan, rx_codec=replace(codec_, layout=None)),
                              slow(plan)):  # fmt: skip
                        img.plan = p
                        img.set_outputs(data, 0)
                        got.append([e.value for e in entries])
                    assert got[0] == got[1] == got[2], (mapping, data.hex())
                continue
            kinds = [(f.size * 8, f.entry.dtype.startswith("INTEGER")) for f in fields if f.entry]
            for trial in range(60):
                for e, (bits, signed) in zip(entries, kinds, strict=True):
                    edges = _edges(bits, signed)
                    e.value = (
                        edges[rnd.randrange(len(edges))]
                        if trial % 3
                        else rnd.choice([*edges[:2], 0, 1])
                    )
                packed = []
                for p in (plan, replace(plan, tx_codec=replace(codec_, layout=None)),
                          slow(plan)):  # fmt: skip
                    img.plan = p
                    packed.append(img.pack_inputs())
                assert packed[0] == packed[1] == packed[2], (mapping, trial)
                img.plan = plan
                assert img.pack_inputs() == packed[0]  # the buffer's earlier bytes overwritten
                assert len(packed[0]) == plan.tx_size


def test_unsigned_outputs_with_the_top_bit_set_decode_as_the_struct_does() -> None:
    """An UNSIGNED8/16/32 output (an ESI slave's digital outputs) with its top bit set is
    positive in the C codec too: each byte is shifted as a C long long (P51; a byte shifted
    as a C int made bit 31 a sign). Ref: ETG.1000.6 Table 64."""
    od = build_od(default_description())
    img = PdoImage(od, Quiet())
    e = od.entry(0x60FD, 0)  # UNSIGNED32
    assert e.dtype == "UNSIGNED32"
    fields = (Field(0, 4, e),)
    plan = Plan(fields, (), 4, 0, codec(fields, 4))
    assert plan.rx_codec is not None and plan.rx_codec.layout is not None
    for value in (0x80000001, 0xFFFFFFFF, 0x7FFFFFFF, 0x00800000, 0):
        got = []
        for p in (plan, replace(plan, rx_codec=replace(plan.rx_codec, layout=None)), slow(plan)):
            img.plan = p
            img.set_outputs(struct.pack("<I", value), 0)
            got.append(e.value)
        assert got == [value] * 3, hex(value)


def _enabled_drive(od: ObjectDictionary) -> tuple[Drive, PdoImage]:
    """A drive in OP, enabled in csp, behind its process image."""
    d = Drive(od)
    img = PdoImage(od, d)
    d.al_state_changed(AlState.OP, 0)
    od.set(0x6060, 0, 8)  # csp
    for k, cw in enumerate((0x06, 0x07, 0x0F)):
        img.set_outputs(struct.pack("<HihI", cw, 0, 0, 0), (k + 1) * 1_000_000)
        img.get_inputs((k + 1) * 1_000_000 + 500_000)
    assert d.state.name == "OPERATION_ENABLED"
    return d, img


def test_every_reader_of_the_od_sees_the_values_the_txpdo_carries() -> None:
    """The drive keeps its published values as C integers and the TxPDO takes them from
    there (P38): after every cycle the SDO upload, complete access, the OD's accessors and
    the per-entry image (which reads the entries) give exactly the TxPDO's values; a value
    set into a published entry between cycles is read back until the next cycle
    publishes over it, as when every cycle wrote the entries."""
    od = build_od(default_description())
    d, img = _enabled_drive(od)
    plan = img.plan
    fields = {f.entry.name: f for f in plan.tx if f.entry is not None}
    for k in range(4, 40):
        t = k * 1_000_000
        target = (k % 7) * 150 - k * 40  # moving without a following error
        img.set_outputs(struct.pack("<HihI", 0x0F, target, 0, 0), t)
        inputs = img.get_inputs(t + 500_000)
        assert d.pub_pending  # the entries wait: nothing has read the OD since
        for index in (0x6041, 0x6061, 0x6064, 0x6077, 0x606C):
            e = od.objects[index].entries[0]
            f = fields[e.name]
            carried = inputs[f.offset : f.offset + f.size]
            sdo = od.read(index, 0)
            assert sdo[: f.size] == carried, (k, hex(index))  # 6077h maps its low 16 bits
            assert od.value(index) == e.decode(sdo) and e.encode() == sdo
        assert not d.pub_pending
        img.plan = slow(plan)  # the per-entry path: the entries themselves
        assert img.pack_inputs() == inputs
        img.plan = plan
        assert img.pack_inputs() == inputs
    od.set(0x6064, 0, 12345)
    assert od.value(0x6064) == 12345 and od.read(0x6064, 0) == (12345).to_bytes(4, "little")
    inputs = img.get_inputs(41_000_000)
    assert od.value(0x6064) == int.from_bytes(inputs[3:7], "little", signed=True) != 12345


def test_every_published_value_in_any_mapping_is_the_entry_path() -> None:
    """Each TxPDO mapping the TMC8670 allows, behind a moving drive: the bytes taken from
    the drive's C values are the bytes of the struct and per-entry paths (P38)."""
    od = build_od(default_description())
    d, img = _enabled_drive(od)
    t = 4_000_000
    for mapping in every_mapping(od, False):
        set_mapping(od, 0x1A00, mapping)
        plan = compile_plan(od)
        assert plan.tx_codec is not None
        for _ in range(3):
            img.plan = plan
            img.set_outputs(struct.pack("<HihI", 0x0F, t // 50, 0, 0), t)
            fast = img.get_inputs(t + 500_000)
            t += 1_000_000
            assert d.pub_pending or not any(
                f.entry is not None and f.entry.name == "Statusword" for f in plan.tx
            )
            packed = [fast]
            for p in (replace(plan, tx_codec=replace(plan.tx_codec, layout=None)), slow(plan)):
                img.plan = p
                packed.append(img.pack_inputs())
            assert packed[0] == packed[1] == packed[2], mapping

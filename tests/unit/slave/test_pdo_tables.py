"""The process image's layout tables read through kept pointers (decision P89) and the
device's slots in them: twin images, one with the C layout and one without (the struct
and per-entry paths), give the same entry values, of the same type, and the same input
bytes, in SM3's buffer too, over random walks. Run against the compiled core and the
pure-Python one alike.

Ref: ETG.1000.6 §5.6.7.4 (PDO mapping), Table 64 (data types); TMC8460 §5.49 (PDI side
of a 3-buffer SM).
"""

from __future__ import annotations

import random
from array import array

import pytest

from ecatsim.device.description import default_description
from ecatsim.slave.od import Entry
from ecatsim.slave.od_build import build_od
from ecatsim.slave.pdo import CycleDevice, PdoImage, compile_plan
from tests.support.pdo_mappings import every_mapping, set_mapping
from tests.support.pdo_twins import Quiet, rx_twins, value_range, without_layout
from tests.support.pdo_twins import fits as pdo_fits


class Keeper(CycleDevice):
    """A device that keeps values for some TxPDO entries (P38) at the slots it is given,
    by the entry's ``id``."""

    def __init__(self, slots: dict[int, int], size: int) -> None:
        self.slots = slots
        self.pub_values = array("q", [0] * size)
        self.pub_pending = False

    def outputs_applied(self, now_ns: int) -> None: ...

    def update_inputs(self, now_ns: int) -> None: ...

    def al_state_changed(self, state: object, now_ns: int) -> None: ...

    def tx_slots(self, entries: tuple[Entry, ...]) -> tuple[int, ...] | None:
        return tuple([self.slots.get(id(e), -1) for e in entries])


def test_repeated_outputs_leave_the_values_of_the_full_decoder() -> None:
    """Every RxPDO mapping the TMC8670 allows, a random walk of output images that repeat
    (as a master's cyclic outputs do) while the entries are also written between cycles
    (an SDO download, a bool, an equal int that is another object): after each cycle the
    image with the C decoder (its layout table: P89) and its twin without a layout hold
    the same values, of the same type."""
    rnd = random.Random(91)
    for t in rx_twins():
        mapping, plan, fast, full = t.mapping, t.plan, t.fast, t.full
        ea, eb = t.fast_entries, t.full_entries
        data = bytearray(rnd.randbytes(plan.rx_size))
        for step in range(40):
            roll = rnd.random()
            if roll < 0.3:  # another output image
                data = bytearray(rnd.randbytes(plan.rx_size))
            elif roll < 0.45:  # one byte changes
                data[rnd.randrange(len(data))] = rnd.randrange(256)
            if rnd.random() < 0.3:  # something else writes an entry between cycles
                k = rnd.randrange(len(ea))
                now = ea[k].value
                other = rnd.choice([now, int(str(now)) if isinstance(now, int) else 0, 1,
                                    True, 0, -(1 << 40)])  # fmt: skip
                ea[k].value = other
                eb[k].value = other
            src = bytes(data) if step % 2 else data
            fast.set_outputs(src, step)
            full.set_outputs(bytes(data), step)
            for a, b in zip(ea, eb, strict=True):
                assert type(a.value) is type(b.value) and a.value == b.value, (mapping, step)


def test_an_entry_written_to_the_decoded_value_as_a_bool_becomes_an_int() -> None:
    """The C decoder assigns every cycle: a bool True in the entry where the output
    decodes to 1 is replaced by the int, as a full decode does (P33, P89)."""
    od = build_od(default_description())
    img = PdoImage(od, Quiet())
    plan = img.plan
    assert plan.rx_codec is not None and plan.rx_codec.layout is not None
    first = plan.rx[0]
    assert first.entry is not None
    e = first.entry
    data = bytearray(plan.rx_size)
    data[first.offset] = 1
    img.set_outputs(data, 0)
    assert type(e.value) is int and e.value == 1
    e.value = True
    img.set_outputs(data, 2)
    assert type(e.value) is int and e.value == 1
    data[first.offset] = 0x34
    data[first.offset + 1] = 0x12
    img.set_outputs(data, 3)
    assert e.value == 0x1234
    e.value = 7
    img.set_outputs(data, 4)
    assert e.value == 0x1234


def test_inputs_from_the_device_slots_are_the_entry_path() -> None:
    """Every TxPDO mapping the TMC8670 allows, a device keeping values for some entries at
    random slots (P38, the slots in the layout table: P89): with and without its values
    pending, in and out of the fields' ranges, the C encoder's bytes (``pack_inputs`` and
    ``fill`` into an SM buffer) are the bytes of the entries' path after the device's
    values are written into the entries; a fill that declines leaves the buffer as it was."""
    rnd = random.Random(89)
    od = build_od(default_description())
    from_slots = 0
    for mapping in every_mapping(od, False):
        set_mapping(od, 0x1A00, mapping)
        plan = compile_plan(od)
        assert plan.tx_codec is not None and plan.tx_codec.layout is not None
        fields = [f for f in plan.tx if f.entry is not None]
        ks = rnd.sample(range(12), len(fields))  # low and high slots alike
        slots = {id(f.entry): k for f, k in zip(fields, ks, strict=True) if rnd.random() < 0.7}
        dev = Keeper(slots, 12)
        img = PdoImage(od, dev)
        img.plan = plan
        for step in range(80):
            for f in fields:
                assert f.entry is not None
                lo, hi = value_range(f.entry, f.size)
                f.entry.value = rnd.randint(lo, hi)
            wild = step % 5 == 4
            for f in fields:
                assert f.entry is not None
                k = slots.get(id(f.entry), -1)
                if k >= 0:
                    lo, hi = value_range(f.entry, f.size)
                    dev.pub_values[k] = (
                        rnd.choice([lo - 1, hi + 1]) if wild else rnd.randint(lo, hi)
                    )
            dev.pub_pending = rnd.random() < 0.7
            mem = bytearray(rnd.randbytes(plan.tx_size + 8))
            before = bytes(mem)
            filled = img.fill(mem, 4, plan.tx_size)
            from_slots += filled and dev.pub_pending
            fast = img.pack_inputs() if filled else None
            if dev.pub_pending:  # the entries as the device keeps them
                for f in fields:
                    assert f.entry is not None
                    k = slots.get(id(f.entry), -1)
                    if k >= 0:
                        f.entry.value = dev.pub_values[k]
                dev.pub_pending = False
            # an entry mapped twice holds one value, which may not fit its shorter field
            fits = pdo_fits(fields)
            assert filled == fits, (mapping, step)
            img.plan = without_layout(plan)
            full = img.pack_inputs()
            img.plan = plan
            if filled:
                assert fast == full and bytes(mem[4 : 4 + plan.tx_size]) == full, mapping
                assert mem[:4] == before[:4] and mem[4 + plan.tx_size :] == before[-4:]
            else:
                assert mem == before, mapping
    assert from_slots > 100  # the walk filled SM3 from the device's values that often


def test_slots_that_do_not_fit_the_image_or_the_values_are_refused() -> None:
    """A device's tx_slots must give one slot per TxPDO entry, each -1 or below 255 (the
    table's byte); a device keeping fewer values than its slots need is an error when the
    inputs are encoded, in both cores (P89), not a read beyond its values."""
    od = build_od(default_description())
    n = len([f for f in compile_plan(od).tx if f.entry is not None])

    class Short(Keeper):
        def tx_slots(self, entries: tuple[Entry, ...]) -> tuple[int, ...] | None:
            return tuple(range(len(entries) - 1))

    class Wide(Keeper):
        def tx_slots(self, entries: tuple[Entry, ...]) -> tuple[int, ...] | None:
            return (255,) * len(entries)

    with pytest.raises(ValueError):
        PdoImage(od, Short({}, n))
    with pytest.raises(ValueError):
        PdoImage(od, Wide({}, n))
    dev = Keeper({id(od.entry(0x6041, 0)): n + 3}, n + 4)
    img = PdoImage(od, dev)
    dev.pub_pending = True
    assert len(img.pack_inputs()) == img.plan.tx_size
    dev.pub_values = array("q", [0] * (n + 3))
    with pytest.raises(IndexError):
        img.pack_inputs()
    dev.pub_pending = False  # the entries' own values: no slot read
    assert len(img.pack_inputs()) == img.plan.tx_size

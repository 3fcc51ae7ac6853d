"""A layout row's field range read from the spec tables (decision P95): the C encoder
accepts exactly the values its field's struct code packs, and the C decoder gives the
values the struct unpacks, at each field's edges (lowest, highest, one beyond each, zero,
minus one and the sign bit's byte patterns), for every TxPDO and RxPDO mapping of the
TMC8670: twin images, one with the layout and one without (the struct and per-entry
paths); and the latched outputs as a bytearray of any length (P70) decode as their
bytes do, through the decoder that returns a C int (decision P96). Run against the
compiled core and the pure-Python one alike.

Ref: ETG.1000.6 §5.6.7.4 (PDO mapping), Table 64 (data types).
"""

from __future__ import annotations

import random
import struct

from ecatsim.device.description import default_description
from ecatsim.slave import pdo
from ecatsim.slave.od_build import build_od
from ecatsim.slave.pdo import PdoImage, compile_plan
from tests.support.pdo_mappings import every_mapping, set_mapping
from tests.support.pdo_twins import Quiet, rx_twins, value_range, without_layout
from tests.support.pdo_twins import fits as pdo_fits

_CODE = {(1, False): "B", (1, True): "b", (2, False): "H", (2, True): "h",
         (4, False): "I", (4, True): "i"}  # fmt: skip


def test_the_spec_tables_are_the_struct_codes_ranges() -> None:
    """For every row spec a layout can hold (1, 2 or 4 bytes, signed or not) the table's
    range (the lists the module's C arrays are set from) is the range the struct code
    packs: its edges pack, one beyond each does not."""
    los, his = pdo._spec_bounds(False), pdo._spec_bounds(True)
    assert len(los) == len(his) == 16
    for (n, signed), code in _CODE.items():
        spec = n | signed << 3
        lo, hi = los[spec], his[spec]
        st = struct.Struct("<" + code)
        assert st.unpack(st.pack(lo))[0] == lo and st.unpack(st.pack(hi))[0] == hi
        for beyond in (lo - 1, hi + 1):
            try:
                st.pack(beyond)
            except struct.error:
                continue
            raise AssertionError((spec, beyond))
    for spec in (0, 8):  # no row holds 0 bytes: an empty range
        assert los[spec] > his[spec]


def _edges(lo: int, hi: int) -> list[int]:
    return [lo, lo + 1, hi - 1, hi, lo - 1, hi + 1, 0, -1, 1]


def test_inputs_at_the_fields_edges_are_the_struct_path() -> None:
    """Every TxPDO mapping, each field's value at its edges and one beyond (the others
    random within their ranges): the layout image fills SM3 with the bytes of its twin
    without a layout where every value fits, and declines, leaving the buffer as it was,
    where one does not."""
    rnd = random.Random(95)
    od = build_od(default_description())
    img = PdoImage(od, Quiet())
    fills = declines = 0
    for mapping in every_mapping(od, False):
        set_mapping(od, 0x1A00, mapping)
        plan = compile_plan(od)
        assert plan.tx_codec is not None and plan.tx_codec.layout is not None
        fields = [f for f in plan.tx if f.entry is not None]
        for f in fields:
            assert f.entry is not None
            for v in _edges(*value_range(f.entry, f.size)):
                for g in fields:
                    assert g.entry is not None
                    g.entry.value = rnd.randint(*value_range(g.entry, g.size))
                f.entry.value = v
                img.plan = plan
                mem = bytearray(rnd.randbytes(plan.tx_size + 8))
                before = bytes(mem)
                filled = img.fill(mem, 4, plan.tx_size)
                img.plan = without_layout(plan)
                full = img.pack_inputs()
                fits = pdo_fits(fields)
                assert filled == fits, (mapping, f.offset, v)
                if filled:
                    fills += 1
                    assert bytes(mem[4 : 4 + plan.tx_size]) == full
                    assert mem[:4] == before[:4] and mem[4 + plan.tx_size :] == before[-4:]
                else:
                    declines += 1
                    assert mem == before
    assert fills > 100 and declines > 50


def test_outputs_at_the_fields_edges_are_the_struct_path() -> None:
    """Every RxPDO mapping, each field's bytes at its edges (the sign bit alone, all ones,
    zero, the highest positive, one), the other bytes random: the C decoder and its twin
    without a layout hold the same values, of the same type."""
    rnd = random.Random(96)
    for t in rx_twins():
        mapping, plan, fast, full = t.mapping, t.plan, t.fast, t.full
        ea, eb = t.fast_entries, t.full_entries
        for f in plan.rx:
            if f.entry is None:
                continue
            n = f.size
            for raw in (1 << (8 * n - 1), (1 << 8 * n) - 1, 0, (1 << (8 * n - 1)) - 1, 1):
                data = bytearray(rnd.randbytes(plan.rx_size))
                data[f.offset : f.offset + n] = raw.to_bytes(n, "little")
                fast.set_outputs(data, 0)
                full.set_outputs(bytes(data), 0)
                for a, b in zip(ea, eb, strict=True):
                    assert type(a.value) is type(b.value) and a.value == b.value, (mapping, raw)


def test_outputs_of_any_length_as_bytearray_are_those_as_bytes() -> None:
    """The latched outputs as a bytearray (P70), decoded by ``_rx_decode`` returning a C
    int (decision P96): over a random walk of output images shorter than the struct (the
    per-entry path decodes what is there), as long and longer, a bytearray gives the
    values its bytes give, on the image with a layout and on its twin without one."""
    rnd = random.Random(97)
    ods = [build_od(default_description()) for _ in range(3)]
    imgs = [PdoImage(od, Quiet()) for od in ods]
    for mapping in every_mapping(ods[0], True)[:6]:
        for od in ods:
            set_mapping(od, 0x1600, mapping)
        plans = [compile_plan(od) for od in ods]
        imgs[0].plan, imgs[1].plan = plans[0], plans[1]
        imgs[2].plan = without_layout(plans[2])
        entries = [[f.entry for f in p.rx if f.entry is not None] for p in plans]
        size = plans[0].rx_size
        for _ in range(30):
            n = rnd.choice([size, size, size + rnd.randrange(1, 5), rnd.randrange(size)])
            data = rnd.randbytes(n)
            imgs[0].set_outputs(bytearray(data), 0)
            imgs[1].set_outputs(data, 0)
            imgs[2].set_outputs(bytearray(data), 0)
            for a, b, c in zip(*entries, strict=True):
                assert type(a.value) is type(b.value) is type(c.value), mapping
                assert a.value == b.value == c.value, (mapping, n)

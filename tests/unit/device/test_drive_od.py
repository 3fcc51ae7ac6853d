"""The drive's object dictionary view on its own (ecatsim/device/drive_od.py), in the
compiled core and in Python alike: each entry with its integer range, writes clamped to it,
the controls bound once, and the published values kept as C integers reaching their
entries when, and only when, something reads the object dictionary.
Ref: CiA 402-2 §6 (objects), TMC8670 Tables 80-83; decisions P34, P38, P52."""

from __future__ import annotations

from ecatsim.device.description import default_description
from ecatsim.device.drive_od import CONTROLS, PUBLISHED, DriveOd
from ecatsim.slave.od import ObjectDictionary
from ecatsim.slave.od_build import build_od


def view() -> tuple[DriveOd, ObjectDictionary]:
    od = build_od(default_description())
    return DriveOd(od), od


def test_an_entry_comes_with_the_range_of_its_data_type() -> None:
    d, od = view()
    assert d._entry(0x6041, 0) == (od.entry(0x6041, 0), 0, 0xFFFF)  # UNSIGNED16
    assert d._entry(0x6064, 0) == (od.entry(0x6064, 0), -(1 << 31), (1 << 31) - 1)  # INTEGER32
    assert d._entry(0x6061, 0) == (od.entry(0x6061, 0), -128, 127)  # INTEGER8
    assert d._entry(0x5FFF, 0) is None  # not in the OD
    assert d._entry(0x6041, 0) is d._entry(0x6041, 0)  # looked up once


def test_a_write_is_clamped_to_the_entrys_range_and_an_absent_entry_reads_zero() -> None:
    d, od = view()
    d._set(0x6041, 70_000)
    assert od.entry(0x6041, 0).value == 0xFFFF
    d._set(0x6041, -5)
    assert od.entry(0x6041, 0).value == 0
    d._set(0x6061, -200)
    assert od.entry(0x6061, 0).value == -128
    d._set(0x5FFF, 1)  # no such object: nothing happens
    assert d._v(0x5FFF) == 0
    d._set(0x6064, -1234)
    assert d._v(0x6064) == -1234


def test_the_controls_are_the_ods_own_entries() -> None:
    d, od = view()
    assert d._controls() == tuple(od.entry(i, 0) for i in CONTROLS)
    od.entry(0x6040, 0).value = 0x0F  # an RxPDO or SDO write: the next read sees it
    cw = d._controls()[0]
    assert cw is not None and cw.value == 0x0F


def test_kept_values_reach_their_entries_only_when_the_od_is_read() -> None:
    d, od = view()
    assert d.tx_slots((od.entry(0x6041, 0),)) is None  # nothing kept before the lookup
    hits = d._publish_hits()
    assert [h[0] if h is not None else None for h in hits] == [
        od.objects[i].entries[0] for i in PUBLISHED
    ]
    assert len(d.pub_values) == len(PUBLISHED)
    d.pub_values[0] = 0x0237  # the statusword the drive computed
    d.pub_values[2] = -42  # 6064h, the position
    d.pub_pending = True
    entry = od.objects[0x6041].entries[0]  # the OD's own table: no flush
    assert entry.value != 0x0237
    assert od.value(0x6041) == 0x0237  # a read of the OD flushes first
    assert od.objects[0x6064].entries[0].value == -42
    assert not d.pub_pending
    d.pub_values[0] = 0x1111  # not pending: a read leaves the entry as it is
    assert od.value(0x6041) == 0x0237


def test_tx_slots_name_the_published_index_of_each_mapped_entry() -> None:
    d, od = view()
    d._publish_hits()
    entries = (od.entry(0x6064, 0), od.entry(0x6040, 0), od.entry(0x6041, 0))
    assert d.tx_slots(entries) == (PUBLISHED.index(0x6064), -1, PUBLISHED.index(0x6041))

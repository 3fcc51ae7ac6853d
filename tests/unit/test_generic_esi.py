"""A generic slave from its ESI, in process: the Dictionary as OD, PDOs and their rules,
SII sizes, the minimal master to OP, process data by entry, signals.

Ref: ETG.2000 §5 (Device, Profile/Dictionary, RxPdo/TxPdo); ETG.1000.6 §5.6.7.4 (PDO
mapping and assignment), Table 41 (abort codes).
"""

from __future__ import annotations

import struct
from pathlib import Path

import pytest
import structlog

from ecatsim.clock import ManualClock
from ecatsim.errors import UserError
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.segment import Segment
from ecatsim.ethercat.segment_file import parse_segment
from ecatsim.generic.minimaster import BringUpError, MiniMaster
from ecatsim.generic.model import from_esi
from ecatsim.generic.pinio import PinIo
from ecatsim.sii.image import parse_image
from ecatsim.slave.al import AlState
from ecatsim.slave.od import SdoAbort
from ecatsim.slave.pd import request as pd_request
from tests.support.tinymaster import firmware_of

DATA = Path(__file__).resolve().parents[1] / "data" / "esi"
ACME = DATA / "acme-io.xml"


def segment(*slaves: dict[str, object]) -> tuple[Segment, ManualClock]:
    cfg = parse_segment({"slaves": list(slaves)}, "test.yaml", DATA)
    clock = ManualClock(1_000_000_000)
    return build_segment(cfg, clock), clock


def test_several_devices_are_refused_with_their_list() -> None:
    with pytest.raises(UserError) as e:
        segment({"esi": "acme-io.xml"})
    msg = str(e.value)
    assert "3 devices" in msg and "ACME-IO8 0x1001/0x10000" in msg and "ACME-DI4" in msg
    assert "slaves[0].device_type" in msg


def test_dictionary_objects_types_and_defaults() -> None:
    m = from_esi(ACME, device_type="ACME-IO8")
    od = m.build_od()
    assert od.value(0x1000) == 5001  # DefaultData 89130000, little-endian
    assert od.value(0x1008) == "ACME-IO8"  # DefaultString
    assert [od.value(0x1018, s) for s in range(5)] == [4, 0x00ACE000, 0x1001, 0x10000, 0]
    assert od[0x8010].code.name == "ARRAY"
    assert [od.value(0x8010, s) for s in range(4)] == [3, 100, 200, 300]
    assert od.entry(0x6010, 17).dtype == "INTEGER16" and od.value(0x6010, 17) == -5
    assert od.entry(0x6000, 1).dtype == "BOOLEAN" and od.entry(0x6000, 1).pdo
    assert od.value(0x8000) == 2 and od.entry(0x8000, 0).dtype == "UNSIGNED8"  # an enum
    assert od.read(0x6020, 0) == struct.pack("<f", 21.5)  # REAL default read back exactly
    # access per state: 0x8000 is written in PREOP only; limits from Min/MaxValue
    od.write(0x8000, 0, b"\x01", int(AlState.PREOP))
    with pytest.raises(SdoAbort) as e:
        od.write(0x8000, 0, b"\x01", int(AlState.SAFEOP))
    assert e.value.code == 0x08000022
    with pytest.raises(SdoAbort) as e:
        od.write(0x7010, 0, struct.pack("<H", 1001), int(AlState.PREOP))
    assert e.value.code == 0x06090031
    assert m.warnings == [
        "<Mailbox/VoE>",
        "<Slots>",
        "data type 'FANCY_TYPE' (read as UNSIGNED16)",
    ]


def test_pdos_default_assigned_and_sii() -> None:
    m = from_esi(ACME, device_type="ACME-IO8")
    od = m.build_od()
    assert [od.value(0x1C12, s) for s in range(3)] == [2, 0x1600, 0x1601]
    assert [od.value(0x1C13, s) for s in range(4)] == [3, 0x1A00, 0x1A01, 0x1A02]
    assert [od.value(0x1600, s) for s in range(4)] == [3, 0x70000101, 0x70000201, 0x00000006]
    assert od[0x1A00].name == "Channel 1"
    sms = {p.index: p.sm for p in (*m.desc.rxpdos, *m.desc.txpdos)}
    assert sms == {0x1600: 2, 0x1601: 2, 0x1A00: 3, 0x1A01: 3, 0x1A02: 3, 0x1A03: 0xFF}


def test_eeprom_too_small_gets_the_next_size_with_one_warning() -> None:
    with structlog.testing.capture_logs() as logs:
        seg, _ = segment({"esi": "acme-io.xml", "device_type": "ACME-IO8"})
    img = parse_image(bytes(seg.escs[0].eeprom.image))
    assert img.size_kbit == 8  # 256 bytes declared; the image needs more than 4 kbit
    raised = [e for e in logs if e["event"] == "eeprom_size_raised"]
    assert len(raised) == 1 and raised[0]["declared_bytes"] == 256
    warned = [e for e in logs if e["event"] == "esi_not_modelled"]
    assert len(warned) == 1 and "<Slots>" in warned[0]["constructs"]


def test_minimal_master_brings_it_to_op_with_the_assigned_sizes() -> None:
    seg, _ = segment({"esi": "acme-io.xml", "device_type": "ACME-IO8"})
    m = MiniMaster(seg)
    assert m.to_op(0) == "OP, outputs 3 bytes, inputs 8 bytes"
    fw = firmware_of(seg)
    # inputs by name and by index reach the image; outputs written by the master are read
    pd_request(fw.app, {"entry": "Channel 1", "value": 1})
    pd_request(fw.app, {"entry": "0x6000:03", "value": 1})
    pd_request(fw.app, {"entry": "Analog/Value", "value": -2})
    pd_request(fw.app, {"entry": "Counter", "value": 0x01020304})
    m.lrw(0, bytes([0x02, 0x34, 0x12]))
    data, wkc = m.lrw(0x8000, bytes(8))
    assert wkc == 1
    assert data == bytes([0x01, 0x02]) + struct.pack("<hi", -2, 0x01020304)
    got = pd_request(fw.app, {"entry": "Output 2"})
    assert got["value"] == 1 and got["direction"] == "output"
    assert pd_request(fw.app, {"entry": "0x7010:00"})["value"] == 0x1234
    listing = pd_request(fw.app, {})["entries"]
    assert [e["entry"] for e in listing] == [
        "0x7000:01", "0x7000:02", "0x7010:00", "0x6000:01", "0x6000:02", "0x6000:03",
        "0x6000:04", "0x6010:11", "0x6010:12",
    ]  # fmt: skip
    with pytest.raises(ValueError, match="an output"):
        pd_request(fw.app, {"entry": "Output 1", "value": 1})
    with pytest.raises(ValueError, match="no mapped entry of that name"):
        pd_request(fw.app, {"entry": "Nope"})


def test_remap_and_reassign_where_the_esi_allows() -> None:
    seg, _ = segment({"esi": "acme-io.xml", "device_type": "ACME-IO8"})
    m = MiniMaster(seg)
    station = 0x1001
    m.apwr(0, 0x0010, struct.pack("<H", station))
    for i, (start, ctrl) in enumerate(((0x1000, 0x26), (0x1080, 0x22))):
        m.fpwr(station, 0x0800 + 8 * i, struct.pack("<HHBBBB", start, 128, ctrl, 0, 1, 0))
    m.state(station, 2, "PREOP")
    od = firmware_of(seg).od
    assert od is not None
    st = int(AlState.PREOP)

    def abort(index: int, sub: int, data: bytes) -> int:
        with pytest.raises(SdoAbort) as e:
            od.write(index, sub, data, st)
        return e.value.code

    assert abort(0x1600, 0, b"\x00") == 0x06010002  # Fixed: read-only
    od.write(0x1C13, 0, b"\x00", st)
    od.write(0x1C13, 1, struct.pack("<H", 0x1A02), st)
    od.write(0x1C13, 2, struct.pack("<H", 0x1A03), st)
    assert abort(0x1C13, 0, b"\x02") == 0x06040043  # 0x1A02 excludes 0x1A03
    od.write(0x1C13, 2, struct.pack("<H", 0x1A00), st)
    od.write(0x1C13, 0, b"\x02", st)
    assert abort(0x1C13, 1, struct.pack("<H", 0x1B00)) == 0x06010003  # SI0 first
    od.write(0x1C12, 0, b"\x00", st)
    od.write(0x1C12, 1, struct.pack("<H", 0x1601), st)
    assert abort(0x1C12, 0, b"\x01") == 0x06040043  # 0x1600 is mandatory
    od.write(0x1A02, 0, b"\x00", st)
    assert abort(0x1A02, 1, struct.pack("<I", 0x90000108)) == 0x06020000
    assert abort(0x1A02, 1, struct.pack("<I", 0x60100210)) == 0x06090011  # no 0x6010:02
    assert abort(0x1A02, 1, struct.pack("<I", 0x80000008)) == 0x06040041  # not mappable
    od.write(0x1A02, 1, struct.pack("<I", 0x60101110), st)
    od.write(0x1A02, 0, b"\x01", st)


def test_esi_without_dictionary_gets_pdos_from_the_esi_alone() -> None:
    seg, _ = segment({"esi": "acme-io.xml", "device_type": "ACME-AO1"})
    fw = firmware_of(seg)
    assert fw.od is not None and fw.od.value(0x1C12, 1) == 0x1600
    assert MiniMaster(seg).to_op(0) == "OP, outputs 2 bytes, inputs 2 bytes"


def test_signals_run_on_the_slaves_time() -> None:
    seg, clock = segment(
        {
            "esi": "acme-io.xml",
            "device_type": "ACME-IO8",
            "signals": [
                {"input": "0x6000:01", "loopback": "Output 1"},
                {"input": "Counter", "counter": {"period_ms": 1, "step": 2}},
                {"input": "Analog/Value", "square": {"amplitude": 100, "period_ms": 10}},
                {"input": "0x6000:04", "constant": 1},
            ],
        }
    )
    m = MiniMaster(seg)
    m.to_op(0)
    m.lrw(0, bytes([0x01, 0, 0]))
    first, _ = m.lrw(0x8000, bytes(8))
    clock.advance(6_000_000)
    m.lrw(0x8000, bytes(8))  # the inputs made after this frame (one cycle's latency)
    later, _ = m.lrw(0x8000, bytes(8))
    assert first[0] == 0x01 and first[1] == 0x04  # loopback of Output 1, constant Input 4
    assert struct.unpack_from("<hi", first, 2) == (100, 0)
    assert struct.unpack_from("<hi", later, 2) == (0, 12)


def test_bad_signal_is_one_line() -> None:
    with pytest.raises(UserError, match=r"slaves\[0\]\.signals\[0\]: 'Nope'"):
        segment({"esi": "acme-io.xml", "device_type": "ACME-IO8",
                 "signals": [{"input": "Nope", "constant": 1}]})  # fmt: skip


def test_minimal_master_reports_the_failing_step() -> None:
    seg, _ = segment({"esi": "acme-io.xml", "device_type": "ACME-IO8"})
    firmware_of(seg).refuse_next = 0x0011
    with pytest.raises(BringUpError, match="INIT->PREOP refused: AL status code 0x0011"):
        MiniMaster(seg).to_op(0)


def test_esi_check_over_a_folder_one_line_per_device(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from ecatsim.cli import cli

    (tmp_path / "acme-io.xml").write_bytes(ACME.read_bytes())
    (tmp_path / "broken.xml").write_text("<EtherCATInfo><Vendor><Id>#x1</Id>")
    r = CliRunner().invoke(cli, ["esi", "check", "--esi-dir", str(tmp_path)])
    lines = [ln for ln in r.output.splitlines() if ln.startswith(str(tmp_path))]
    assert r.exit_code == 1 and "Traceback" not in r.output  # the broken file fails
    assert len(lines) == 4
    assert lines[0].endswith(
        "ACME-IO8 (0x00001001/0x00010000): ok: OP, outputs 3 bytes, inputs 8 bytes"
    )
    assert lines[1].endswith(
        "ACME-DI4 (0x00001002/0x00010000): ok: OP, outputs 0 bytes, inputs 1 bytes"
    )
    assert lines[2].endswith(
        "ACME-AO1 (0x00001003/0x00020000): ok: OP, outputs 2 bytes, inputs 2 bytes"
    )
    assert lines[3].startswith(f"{tmp_path / 'broken.xml'}: FAILED: not a readable XML file")


@pytest.mark.parametrize(
    ("slave", "msg"),
    [
        ({"device": "tmc8670", "signals": []}, r"slaves\[0\]\.signals: for a generic slave only"),
        ({"device": "generic"}, r"slaves\[0\]\.device: a generic slave needs esi: FILE"),
        ({"esi": "acme-io.xml", "product": "x"}, r"slaves\[0\]\.product: expected an integer"),
        (
            {"esi": "acme-io.xml", "device_type": "NOPE"},
            r"acme-io.xml: no device matches device_type NOPE; it has: ",
        ),
    ],
)
def test_generic_slave_entry_errors_are_one_line(slave: dict[str, object], msg: str) -> None:
    with pytest.raises(UserError, match=msg):
        segment(slave)


def test_ctl_pd_table_for_people() -> None:
    from ecatsim.slave.pd import format_entries

    seg, _ = segment({"esi": "acme-io.xml", "device_type": "ACME-IO8"})
    rows = format_entries(pd_request(firmware_of(seg).app, {})["entries"]).splitlines()
    assert rows[0].split() == ["entry", "dir", "bits", "value", "name", "pdo"]
    assert rows[3].split() == ["0x7010:00", "out", "16", "256", "(0x100)", "Setpoint", "0x1601",
                               "Setpoint"]  # fmt: skip


def test_mailbox_foe_and_dc_op_modes_from_the_esi() -> None:
    from ecatsim.wire.mailbox import MbxType

    seg, _ = segment({"esi": "acme-io.xml", "device_type": "ACME-IO8"})
    fw = firmware_of(seg)
    assert fw.bootstrap_supported and fw.mbx is not None
    assert int(MbxType.FOE) in fw.mbx.handlers and int(MbxType.COE) in fw.mbx.handlers
    img = parse_image(bytes(seg.escs[0].eeprom.image))
    assert img.mailbox == (0x1000, 0x80, 0x1080, 0x80, 0x1000, 128, 0x1080, 128)
    assert img.protocols == 0x04 | 0x08 | 0x20  # CoE, FoE, VoE as the ESI declares
    assert [(d[4], d[3]) for d in img.dc] == [("FreeRun", 0x0000), ("DC", 0x0300)]
    assert [s[0] for s in img.sms] == [0x1000, 0x1080, 0x1100, 0x1180]


def test_odd_dictionary_constructs_are_warnings_not_crashes() -> None:
    m = from_esi(DATA / "odd-dictionary.xml")
    assert m.warnings == [
        "<Object> #4 without a readable <Index> (left out)",
        "Access 'xx' (read as ro)",
        "ConfigData device emulation (0x0141 bit 0): off, the emulated firmware runs",
        "ReadRestrictions (reads allowed in every state)",
        "WriteRestrictions 'Sometimes'",
        "data type 'WEIRD' (read as UNSIGNED16)",
        "nested record type 'DTINNER' (read as bytes)",
        "object 0x2001: default 'zz' is not a number",
        "object 0x2002: MaxValue 'lots' is not a number (no limit)",
    ]
    od = m.build_od()
    assert od.value(0x2004) == -7 and od.entry(0x2000, 2).bits == 12
    assert m.desc.esc.pdi_control == 0x0C05  # device emulation cleared
    seg, _ = segment({"esi": "odd-dictionary.xml"})
    assert MiniMaster(seg).to_op(0) == "OP, outputs 0 bytes, inputs 0 bytes"


def test_io_without_mailbox_runs_in_device_emulation_on_its_own_sms() -> None:
    seg, _ = segment(
        {"esi": "acme-io.xml", "device_type": "ACME-DI4",
         "signals": [{"input": "Input 2", "constant": 1}]}
    )  # fmt: skip
    assert seg.escs[0].mem[0x0141] & 0x01
    m = MiniMaster(seg)
    assert m.to_op(0) == "OP, outputs 0 bytes, inputs 1 bytes"
    pinio = seg.firmware[0]
    assert isinstance(pinio, PinIo)  # a mailbox-less slave: its process image on its SMs
    pd_request(pinio.app, {"entry": "0x6000:01", "value": 1})
    m.lrw(0x8000, bytes(1))
    data, wkc = m.lrw(0x8000, bytes(1))
    assert (data, wkc) == (b"\x03", 1)  # SM0 (0x1000) carries both inputs


def test_more_than_255_names_leave_the_rest_unnamed_in_the_sii() -> None:
    import dataclasses

    from ecatsim.device.description import PdoDescription, PdoEntry
    from ecatsim.sii.image import build_image

    m = from_esi(ACME, device_type="ACME-IO8")
    pdos = tuple(
        PdoDescription(0x1A00 + k, f"Many {k}", 3, tuple(
            PdoEntry(0x6000, 1, 1, "BOOLEAN", f"Input {100 * k + i}") for i in range(100)))
        for k in range(3)
    )  # fmt: skip
    desc = dataclasses.replace(
        m.desc, txpdos=pdos, esc=dataclasses.replace(m.desc.esc, eeprom_size_kbit=64)
    )
    img = parse_image(build_image(desc))
    assert len(img.strings) == 255
    names = [e[2] for p in img.pdos if p[0] == "TxPDO" for e in p[4]]
    assert names[0] == "Input 0" and names[-1] == ""


def test_ctl_pd_on_the_tmc8670_too() -> None:
    seg, _ = segment({"device": "tmc8670"})
    got = pd_request(firmware_of(seg).app, {})["entries"]
    assert [e["entry"] for e in got][:2] == ["0x6040:00", "0x607A:00"]
    assert got[4] == {
        "entry": "0x6041:00", "name": "Statusword", "pdo": "0x1A00",
        "pdo_name": "Transmit PDO mapping", "direction": "input", "bits": 16, "value": 0x40,
    }  # fmt: skip
    assert pd_request(firmware_of(seg).app, {"entry": "Statusword", "value": 0x37})["value"] == 0x37


def test_bit_string_types_keep_their_codes() -> None:
    from ecatsim.generic.types import base_type, pdo_entry_type

    assert base_type("BIT3") == ("BIT3", 3) and base_type("BOOL") == ("BOOLEAN", 1)
    assert pdo_entry_type("BIT2", 2) == "BIT2"
    from ecatsim.slave.od import Entry

    e = Entry(1, "Mode", "BIT3", access="rw", default=5)
    assert (e.type_code, e.bits, e.encode()) == (0x0032, 3, b"\x05")


def test_an_esi_slave_with_eoe_serves_it_beside_coe() -> None:
    """``eoe:`` on an ESI slave: the SII declares EoE beside CoE, and the mailbox serves it.
    Ref: ETG.1000.6 §5.7; ETG.2010 Table 2 (word 0x1C: CoE 0x04, EoE 0x02)."""
    from ecatsim.wire.mailbox import MbxType

    seg, _ = segment({"esi": "acme-io.xml", "device_type": "ACME-IO8", "eoe": {"tap": "e0"}})
    sii = parse_image(bytes(seg.escs[0].eeprom.image))
    assert sii.protocols & 0x06 == 0x06
    fw = firmware_of(seg)
    assert fw.mbx is not None
    assert int(MbxType.EOE) in fw.mbx.handlers and fw.mbx.sources


def test_eoe_on_an_esi_slave_without_coe_is_one_line() -> None:
    with pytest.raises(UserError, match=r"slaves\[0\]\.eoe: EoE shares the mailbox of a CoE"):
        segment({"esi": "acme-io.xml", "device_type": "ACME-DI4", "eoe": {"tap": "e0"}})

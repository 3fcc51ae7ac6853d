"""CoE against a real master: SDO up/download, aborts, Complete Access, SDO Info, PDO remap,
mailbox repeat. Ref: ETG.1000.6 §5.6 (CoE); ETG.1000.4 §5.6 (mailbox); TMC8670 §4-9.
"""

from __future__ import annotations

import struct
import time
from typing import Any

import pysoem
import pytest

from tests.integration.test_esc_master import RX_TIMEOUT_US, to_op

pytestmark = pytest.mark.integration

MBX_OUT, MBX_IN = 0x1000, 0x1080
FOE_ERROR = -5  # SOEM: -EC_ERR_TYPE_FOE_ERROR


def up(master_factory: Any, daemon_factory: Any, *args: str) -> tuple[Any, Any]:
    daemon_factory(*args)
    m = master_factory()
    assert m.config_init() == 1
    return m, m.slaves[0]


def abort_of(fn: Any, *args: Any, **kw: Any) -> int:
    with pytest.raises(pysoem.SdoError) as e:
        fn(*args, **kw)
    return int(e.value.abort_code)


def test_identity_objects(master_factory: Any, daemon_factory: Any) -> None:
    _m, s = up(master_factory, daemon_factory)
    assert struct.unpack("<I", s.sdo_read(0x1000, 0))[0] == 0xFFFC0192
    assert s.sdo_read(0x1008, 0) == b"TMC8670"  # 7 bytes: a normal (non-expedited) upload
    assert struct.unpack("<I", s.sdo_read(0x1018, 1))[0] == 0x286
    assert struct.unpack("<I", s.sdo_read(0x1018, 2))[0] == 8670
    # SII words 0x08-0x0D equal 0x1018:01-03; the sheet's 1018h has no serial (:00 = 3)
    for sub, word in ((1, 0x08), (2, 0x0A), (3, 0x0C)):
        assert s.sdo_read(0x1018, sub) == s.eeprom_read(word)
    assert s.sdo_read(0x1018, 0) == b"\x03"
    assert abort_of(s.sdo_read, 0x1018, 4) == 0x06090011


def test_abort_codes(master_factory: Any, daemon_factory: Any) -> None:
    m, s = up(master_factory, daemon_factory)
    assert abort_of(s.sdo_read, 0x2FFF, 0) == 0x06020000
    assert abort_of(s.sdo_read, 0x1018, 9) == 0x06090011
    assert abort_of(s.sdo_write, 0x1000, 0, b"\x00\x00\x00\x00") == 0x06010002
    assert abort_of(s.sdo_write, 0x6081, 0, b"\x00\x00") == 0x06070010
    assert abort_of(s.sdo_write, 0x6060, 0, b"\x05") == 0x06090030
    assert abort_of(s.sdo_write, 0x6081, 0, struct.pack("<I", 300_000)) == 0x06090031
    assert abort_of(s.sdo_write, 0x6082, 0, struct.pack("<i", -300_000)) == 0x06090032
    assert s.sdo_read(0x2130, 1) == b"\x7b"  # RW, default 123 (TMC8670 Table 66)
    # mapping: a non-mappable object, then too long a PDO
    s.sdo_write(0x1A00, 0, b"\x00")
    assert abort_of(s.sdo_write, 0x1A00, 1, struct.pack("<I", 0x60810020)) == 0x06040041
    for sub in range(1, 10):
        s.sdo_write(0x1A00, sub, struct.pack("<I", 0x60640020))
    assert abort_of(s.sdo_write, 0x1A00, 0, b"\x09") == 0x06040042
    s.sdo_write(0x1A00, 0, b"\x08")  # 8 x 32 bit = 32 bytes: fits
    # PDO assignment outside PREOP
    s.sdo_write(0x1A00, 0, b"\x00")
    for sub, v in enumerate((0x60410010, 0x60610008, 0x60640020, 0x60770010, 0x606C0020,
                             0x60FD0020), start=1):  # fmt: skip
        s.sdo_write(0x1A00, sub, struct.pack("<I", v))
    s.sdo_write(0x1A00, 0, b"\x06")
    m.config_map()
    assert m.state_check(pysoem.SAFEOP_STATE, 2_000_000) == pysoem.SAFEOP_STATE
    assert abort_of(s.sdo_write, 0x1C12, 0, b"\x00") == 0x08000022
    assert abort_of(s.sdo_write, 0x1600, 0, b"\x00") == 0x08000022


def test_every_object_readable_and_rw_objects_round_trip(
    master_factory: Any, daemon_factory: Any
) -> None:
    _m, s = up(master_factory, daemon_factory)
    od = s.od
    assert len(od) >= 40
    checked = written = 0
    for obj in od:
        subs = list(enumerate(obj.entries)) if obj.entries else [(0, obj)]
        for sub, e in subs:
            if not e.obj_access & 0x07:
                continue  # write-only
            try:
                value = s.sdo_read(obj.index, sub)
            except pysoem.SdoError as exc:
                pytest.fail(f"read 0x{obj.index:04X}:{sub} -> 0x{exc.abort_code:08X}")
            checked += 1
            if e.obj_access & 0x38 == 0x38 and obj.index < 0x1600:
                s.sdo_write(obj.index, sub, value)  # write back what was read
                assert s.sdo_read(obj.index, sub) == value
                written += 1
            elif (
                e.obj_access & 0x38 == 0x38 and obj.index >= 0x2000 and e.bit_length in (8, 16, 32)
            ):
                s.sdo_write(obj.index, sub, value)
                assert s.sdo_read(obj.index, sub) == value
                written += 1
    assert checked >= 60
    assert written >= 20


def test_od_list_names_and_types(master_factory: Any, daemon_factory: Any) -> None:
    _m, s = up(master_factory, daemon_factory)
    by = {o.index: o for o in s.od}
    for index in (0x1000, 0x1008, 0x1018, 0x1600, 0x1A00, 0x1C12, 0x1C13, 0x6040, 0x6041,
                  0x607A, 0x60FF, 0x6064):  # fmt: skip
        assert index in by, hex(index)
    assert by[0x1008].name == b"Manufacturer device name"
    assert by[0x6040].name.lower().startswith(b"controlword")
    assert by[0x6040].data_type == pysoem.ECT_UNSIGNED16
    assert by[0x607A].data_type == pysoem.ECT_INTEGER32
    assert by[0x1018].object_code == 9  # RECORD
    assert [e.name for e in by[0x1018].entries][1] == b"Vendor ID"


def test_complete_access_read_and_write(master_factory: Any, daemon_factory: Any) -> None:
    _m, s = up(master_factory, daemon_factory)
    assert s.sdo_read(0x1C12, 0, ca=True) == b"\x01\x00\x00\x16"
    ca = s.sdo_read(0x1600, 0, ca=True)
    assert ca[:2] == b"\x04\x00"
    assert struct.unpack_from("<4I", ca, 2) == (0x60400010, 0x607A0020, 0x60710010, 0x60FF0020)
    new = struct.pack("<H3I", 3, 0x60400010, 0x607A0020, 0x60FF0020) + bytes(24)
    s.sdo_write(0x1600, 0, new, ca=True)
    assert s.sdo_read(0x1600, 0) == b"\x03"
    assert struct.unpack("<I", s.sdo_read(0x1600, 3))[0] == 0x60FF0020
    s.sdo_write(0x1C12, 0, b"\x00\x00\x00\x16", ca=True)
    assert s.sdo_read(0x1C12, 0) == b"\x00"
    s.sdo_write(0x1C12, 0, b"\x01\x00\x00\x16", ca=True)
    assert s.sdo_read(0x1C12, 0) == b"\x01"


def test_segmented_upload_with_a_small_mailbox(master_factory: Any, daemon_factory: Any) -> None:
    m, s = up(master_factory, daemon_factory)
    m.state = pysoem.INIT_STATE
    m.write_state()
    assert m.state_check(pysoem.INIT_STATE, 1_000_000) == pysoem.INIT_STATE
    s.amend_mbx(mailbox="in", start_address=MBX_IN, size=20)
    m.state = pysoem.PREOP_STATE
    m.write_state()
    assert m.state_check(pysoem.PREOP_STATE, 1_000_000) == pysoem.PREOP_STATE
    # a 7-character string does not fit one 20-byte mailbox after the SDO header
    assert s.sdo_read(0x1008, 0) == b"TMC8670"
    ca = s.sdo_read(0x1A00, 0, ca=True)  # 2 + 6 * 4 bytes over several segments
    assert len(ca) == 26
    assert struct.unpack_from("<H", ca)[0] == 6
    assert struct.unpack_from("<I", ca, 2)[0] == 0x60410010


def test_pdo_remap_changes_the_process_image(
    master_factory: Any, daemon_factory: Any, tmp_path: Any
) -> None:
    cfg = tmp_path / "seg.yaml"
    cfg.write_text("slaves:\n  - device: echo\n")  # outputs echoed into inputs: exact data
    m, s = up(master_factory, daemon_factory, "--config", str(cfg))
    # RxPDO without 60FF; TxPDO with 6062 added
    s.sdo_write(0x1600, 0, b"\x00")
    s.sdo_write(0x1600, 0, b"\x03")
    s.sdo_write(0x1A00, 0, b"\x00")
    s.sdo_write(0x1A00, 7, struct.pack("<I", 0x60620020))
    s.sdo_write(0x1A00, 0, b"\x07")
    size = m.config_map()
    assert size == 8 + 21
    assert (len(s.output), len(s.input)) == (8, 21)
    to_op(m)
    for cycle in range(50):
        s.output = struct.pack("<Hih", cycle, cycle * 3, -cycle)
        m.send_processdata()
        assert m.receive_processdata(RX_TIMEOUT_US) == 3
    sw, _mode, pos, torque, _vel, _di, _demand = struct.unpack("<HbihiIi", bytes(s.input))
    assert (sw, pos, torque) == (48, 48 * 3, -48)


def test_torque_objects_are_signed32_over_sdo_and_pdo(
    master_factory: Any, daemon_factory: Any, tmp_path: Any
) -> None:
    """6071h/6077h/60B2h are SIGNED32 as the TMC8670 object tables type them (Tables 140-149);
    the default PDOs' 16-bit entries and 32-bit remaps both work (decision C1)."""
    cfg = tmp_path / "seg.yaml"
    cfg.write_text("slaves:\n  - device: echo\n")  # 6077 <- 6071 echoed: exact data
    m, s = up(master_factory, daemon_factory, "--config", str(cfg))
    s.sdo_write(0x6071, 0, struct.pack("<i", -40000))
    assert s.sdo_read(0x6071, 0) == struct.pack("<i", -40000)
    s.sdo_write(0x60B2, 0, struct.pack("<i", -70000))
    assert s.sdo_read(0x60B2, 0) == struct.pack("<i", -70000)
    assert abort_of(s.sdo_write, 0x6071, 0, struct.pack("<h", -400)) == 0x06070010
    assert abort_of(s.sdo_write, 0x6071, 0, struct.pack("<i", 90001)) == 0x06090031
    assert abort_of(s.sdo_write, 0x6071, 0, struct.pack("<i", -90001)) == 0x06090032
    s.sdo_write(0x6071, 0, struct.pack("<i", 0))
    # 60B2h is not mappable (Table 149)
    s.sdo_write(0x1600, 0, b"\x00")
    assert abort_of(s.sdo_write, 0x1600, 4, struct.pack("<I", 0x60B20020)) == 0x06040041
    # both torques remapped with 32 bits
    s.sdo_write(0x1600, 3, struct.pack("<I", 0x60710020))
    s.sdo_write(0x1600, 4, struct.pack("<I", 0x60FF0020))
    s.sdo_write(0x1600, 0, b"\x04")
    s.sdo_write(0x1A00, 0, b"\x00")
    s.sdo_write(0x1A00, 4, struct.pack("<I", 0x60770020))
    s.sdo_write(0x1A00, 0, b"\x06")
    assert m.config_map() == 14 + 19
    to_op(m)
    for _ in range(20):
        s.output = struct.pack("<Hiii", 0, 0, -40000, 0)
        m.send_processdata()
        assert m.receive_processdata(RX_TIMEOUT_US) == 3
    assert struct.unpack_from("<i", bytes(s.input), 7)[0] == -40000


def test_torque_in_the_default_16_bit_entries(
    master_factory: Any, daemon_factory: Any, tmp_path: Any
) -> None:
    """The sheet's default RxPDO/TxPDO (60710010h, 60770010h) carry the low 16 bits."""
    cfg = tmp_path / "seg.yaml"
    cfg.write_text("slaves:\n  - device: echo\n")
    m, s = up(master_factory, daemon_factory, "--config", str(cfg))
    assert (m.config_map(), len(s.output), len(s.input)) == (12 + 17, 12, 17)
    to_op(m)
    for _ in range(20):
        s.output = struct.pack("<Hihi", 0, 0, -1234, 0)
        m.send_processdata()
        assert m.receive_processdata(RX_TIMEOUT_US) == 3
    assert struct.unpack_from("<h", bytes(s.input), 7)[0] == -1234
    assert s.sdo_read(0x6077, 0) == struct.pack("<i", -1234)


def _mbx_write(s: Any, data: bytes, counter: int, mtype: int = 3) -> None:
    frame = struct.pack("<HHBB", len(data), 0, 0, mtype | (counter << 4)) + data
    s._fpwr(MBX_OUT, frame.ljust(128, b"\x00"))


def _mbx_read(s: Any, timeout: float = 1.0) -> bytes:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if s._fprd(0x080D, 1)[0] & 0x08:  # SM1 status: mailbox full
            return bytes(s._fprd(MBX_IN, 128))
        time.sleep(0.001)
    raise AssertionError("no mailbox reply")


def test_raw_aborts_toggle_command_and_mailbox_errors(
    master_factory: Any, daemon_factory: Any
) -> None:
    _m, s = up(master_factory, daemon_factory)
    coe = struct.pack("<H", 2 << 12)
    # bad command specifier
    _mbx_write(s, coe + struct.pack("<BHBI", 0xE0, 0x1000, 0, 0), 1)
    r = _mbx_read(s)
    assert r[8] == 0x80 and struct.unpack_from("<I", r, 12)[0] == 0x05040001
    # a toggle error in a segmented download
    new = struct.pack("<H3I", 3, 0x60400010, 0x607A0020, 0x60FF0020)
    _mbx_write(s, coe + struct.pack("<BHBI", 0x31, 0x1600, 0, len(new)) + new[:4], 2)
    assert _mbx_read(s)[8] == 0x60
    _mbx_write(s, coe + bytes([0x10]) + new[4:11], 3)
    r = _mbx_read(s)
    assert r[8] == 0x80 and struct.unpack_from("<I", r, 12)[0] == 0x05030000
    # unsupported mailbox protocol (EoE) and invalid channel
    _mbx_write(s, b"\x00" * 4, 4, mtype=2)
    r = _mbx_read(s)
    assert r[5] & 0x0F == 0 and struct.unpack_from("<HH", r, 6) == (1, 0x0002)
    frame = struct.pack("<HHBB", 10, 0, 5, 3 | (5 << 4)) + coe + bytes(8)
    s._fpwr(MBX_OUT, frame.ljust(128, b"\x00"))
    r = _mbx_read(s)
    assert struct.unpack_from("<HH", r, 6) == (1, 0x0003)


def test_repeat_request_resends_identical_reply(master_factory: Any, daemon_factory: Any) -> None:
    _m, s = up(master_factory, daemon_factory)
    coe = struct.pack("<H", 2 << 12)
    _mbx_write(s, coe + struct.pack("<BHBI", 0x40, 0x1018, 1, 0), 5)
    first = _mbx_read(s)
    assert struct.unpack_from("<I", first, 12)[0] == 0x286
    act = s._fprd(0x080E, 1)[0]
    s._fpwr(0x080E, bytes([act ^ 0x02]))  # toggle the repeat request
    deadline = time.monotonic() + 1
    while (s._fprd(0x080F, 1)[0] & 0x02) != ((act ^ 0x02) & 0x02):
        assert time.monotonic() < deadline, "no repeat ack"
        time.sleep(0.001)
    assert _mbx_read(s) == first


def _to_boot(m: Any, s: Any) -> None:
    m.state = pysoem.INIT_STATE
    m.write_state()
    assert m.state_check(pysoem.INIT_STATE, 1_000_000) == pysoem.INIT_STATE
    s.state = pysoem.BOOT_STATE
    s.write_state()
    assert s.state_check(pysoem.BOOT_STATE, 1_000_000) == pysoem.BOOT_STATE


def test_foe_firmware_write_in_boot_and_read_back(
    master_factory: Any, daemon_factory: Any, tmp_path: Any
) -> None:
    cfg = tmp_path / "seg.yaml"
    cfg.write_text(f"slaves:\n  - device: tmc8670\n    foe_dir: {tmp_path / 'fw'}\n"
                   "    foe_password: 0x12345678\n")  # fmt: skip
    m, s = up(master_factory, daemon_factory, "--config", str(cfg))
    image = bytes((i * 7 + 3) & 0xFF for i in range(5000))
    # outside BOOT: refused; SOEM returns -EC_ERR_TYPE_FOE_ERROR (-5)
    assert s.foe_write("firmware.bin", 0x12345678, image, 500_000) == FOE_ERROR
    # the exact FoE error code, seen in a raw FoE exchange: 0x8009 not in bootstrap
    _mbx_write(s, struct.pack("<BBI", 2, 0, 0x12345678) + b"firmware.bin", 6, mtype=4)
    r = _mbx_read(s)
    assert r[5] & 0x0F == 4 and r[6] == 5 and struct.unpack_from("<I", r, 8)[0] == 0x8009
    # BOOT is reachable only from INIT
    s.state = pysoem.BOOT_STATE
    s.write_state()
    s.state_check(pysoem.BOOT_STATE, 300_000)
    assert s.al_status == 0x0011
    _to_boot(m, s)
    assert s.foe_write("firmware.bin", 1, image, 500_000) == FOE_ERROR  # wrong password
    assert s.foe_write("firmware.bin", 0x12345678, image, 2_000_000) > 0
    assert (tmp_path / "fw" / "firmware.bin").read_bytes() == image
    assert s.foe_read("firmware.bin", 0x12345678, 10_000, 2_000_000) == image
    # unknown file: FoE error 0x8001 (not found)
    _mbx_write(s, struct.pack("<BBI", 1, 0, 0x12345678) + b"nosuch.bin", 7, mtype=4)
    r = _mbx_read(s)
    assert r[6] == 5 and struct.unpack_from("<I", r, 8)[0] == 0x8001
    # CoE is not served in BOOT
    _mbx_write(s, struct.pack("<HBHBI", 2 << 12, 0x40, 0x1000, 0, 0), 1)
    r = _mbx_read(s)
    assert r[5] & 0x0F == 0 and struct.unpack_from("<HH", r, 6) == (1, 0x0002)

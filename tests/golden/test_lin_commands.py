"""Golden bytes: every command of TMC211 §6.11 (Table 16) against the sheet's frame tables.

Each exchange is written byte by byte as the tables print it (byte 0 is the identifier;
here the header is break 0x00, sync 0x55, protected identifier) and the answers are
asserted exactly, checksum included.
"""

from __future__ import annotations

from ecatsim.lin import codec
from ecatsim.lin.config import NodeConfig
from ecatsim.lin.frame import classic_checksum, protect
from ecatsim.lin.tables import RomPointer, State
from tests.support.linmaster import LinMaster, activate, make_bus

# node 0x45: HW0 = 1 (AD6), PA = 5 (Table 13, ADM = 0)
OTP = bytes((0x11, 0x22, 0x05, 0xF3, 0x51, 0x03, 0x00, 0x0C))
NODE = NodeConfig(name="n", hw=0b001, otp=OTP)
AD = 0x45
GP2, GP4, PREP, STATUS, ACTPOS, SETPOS = 0x18, 0x28, 0x1A, 0x00, 0x20, 0x10


def wire(*data: int) -> bytes:
    """A node's answer: data and classic checksum."""
    return bytes(data) + bytes((classic_checksum(bytes(data)),))


def hdr(ident: int) -> bytes:
    return bytes((0x00, 0x55, protect(ident)))


def mframe(ident: int, *data: int) -> bytes:
    return hdr(ident) + wire(*data)


def ids(m: LinMaster) -> None:
    """The example identifiers of Table 15 with xxx = 000, broadcast (Broad = 0)."""
    first = [(RomPointer.GENERAL_PURPOSE_2, GP2), (RomPointer.GENERAL_PURPOSE_4, GP4)]
    m.assign(0, [*first, (RomPointer.PREPARING, PREP), (RomPointer.GET_STATUS, STATUS)], True)
    m.assign(
        0, [(RomPointer.GET_ACTUAL_POS, ACTPOS), (RomPointer.SET_POSITION, SETPOS)], broad=True
    )


def setup() -> tuple[LinMaster, object]:
    bus, _clock, m = make_bus((NODE,))
    ids(m)
    return m, bus.nodes[0]


def test_dynamic_id_assignment_frame_bytes() -> None:
    # §6.8: 0x3C, AppCMD 0x80, CMD 0x91, Broad|AD, then ROMp/DynID pairs LSB first
    bus, _clock, m = make_bus((NODE,))
    data = codec.pack_dynamic_ids([(0b0011, 0b000101), (0b0010, 0b100101)])
    assert data == bytes((0x53, 0x48, 0xF9, 0xFF, 0xFF))
    assert m.raw(mframe(0x3C, 0x80, 0x91, 0x80 | AD, *data)) == b""
    assert bus.nodes[0].rom_ids == {RomPointer.GET_STATUS: 0x05, RomPointer.GET_ACTUAL_POS: 0x25}


def test_get_full_status_two_reading_frames_and_flag_reset() -> None:
    m, node = setup()
    # type #8 preparing frame (§6.11.2), then two type #6 reading frames on 0x3D
    assert m.raw(mframe(0x3C, 0x80, 0x81, 0x80 | AD, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF)) == b""
    # RAM from OTP: Irun F Ihold 3, Vmax 5 Vmin 1, SecPos[10:8]=0, Shaft 0, Acc 3,
    # StepMode 3; VddReset = 1; Motion 000, ESW 0, bit 1 = 1; LIN errors 0
    assert m.raw(hdr(0x3D)) == wire(0xC5, 0xF3, 0x51, 0x63, 0x80, 0x02, 0x00, 0xFF)
    # ActPos 0, TagPos 0, SecPos 0x000 (11 bits, 0x400 would disable it)
    assert m.raw(hdr(0x3D)) == wire(0xC5, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF8, 0xFF)
    assert m.raw(hdr(0x3D)) == b""  # a third reading frame is not consecutive to a preparing one
    m.wait(0.02)
    # <VddReset> was reset once read (§5.2.2), the node left ShutDown (§5.1.10)
    m.prepare(0x01, AD)
    assert m.raw(hdr(0x3D)) == wire(0xC5, 0xF3, 0x51, 0x63, 0x00, 0x02, 0x00, 0xFF)
    assert node.state == State.STOPPED  # type: ignore[attr-defined]


def test_get_full_status_type7_preparing_frame() -> None:
    m, _node = setup()
    assert m.raw(mframe(PREP, 0x81, 0x80 | AD)) == b""  # §6.11.2 type #7
    assert m.raw(hdr(0x3D)) == wire(0xC5, 0xF3, 0x51, 0x63, 0x80, 0x02, 0x00, 0xFF)


def test_get_actual_pos_direct_and_indirect() -> None:
    m, _node = setup()
    activate(m, AD)
    m.raw(mframe(GP4, 0x8B, 0x80 | AD, 0x03, 0x20))  # SetPosition 800
    m.wait(2.0)
    m.full_status(AD)
    # type #5 (§6.11.1): ESW|AD, ActPos, status
    assert m.raw(hdr(ACTPOS)) == wire(0x45, 0x03, 0x20, 0x00)
    # type #8 + type #6: 1|AD, ActPos, status, 4 x 0xFF
    m.raw(mframe(0x3C, 0x80, 0x80, 0x80 | AD, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF))
    assert m.raw(hdr(0x3D)) == wire(0xC5, 0x03, 0x20, 0x00, 0xFF, 0xFF, 0xFF, 0xFF)
    # type #7 preparing frame, same answer
    m.raw(mframe(PREP, 0x80, 0x80 | AD))
    assert m.raw(hdr(0x3D)) == wire(0xC5, 0x03, 0x20, 0x00, 0xFF, 0xFF, 0xFF, 0xFF)


def test_get_actual_pos_does_not_reset_flags() -> None:
    m, _node = setup()
    assert m.raw(hdr(ACTPOS)) == wire(0x45, 0x00, 0x00, 0x80)
    assert m.raw(hdr(ACTPOS)) == wire(0x45, 0x00, 0x00, 0x80)


def test_get_status_direct_and_its_flag_reset() -> None:
    m, _node = setup()
    assert m.raw(hdr(STATUS)) == wire(0x45, 0x80)  # §6.11.4: ESW|AD, VddReset
    assert m.raw(hdr(STATUS)) == wire(0x45, 0x00)


def test_get_otp_param_with_the_hardwired_address() -> None:
    m, _node = setup()
    m.raw(mframe(0x3C, 0x80, 0x82, 0x80 | AD, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF))
    # §6.11.3: byte 3 = ADM HW2 HW1 HW0 PA[3:0] = 0 0 0 1 0101
    assert m.raw(hdr(0x3D)) == wire(0x11, 0x22, 0x15, 0xF3, 0x51, 0x03, 0x00, 0x0C)


def test_set_motor_param_read_back() -> None:
    m, _node = setup()
    m.full_status(AD)
    # §6.11.10: Irun 9 Ihold 2, Vmax 7 Vmin 4, SecPos 0x3FF Shaft 1 Acc 6, AccShape 1 StepMode 0
    m.raw(mframe(0x3C, 0x80, 0x89, 0x80 | AD, 0x92, 0x74, 0x76, 0xFF, 0xF3))
    m.prepare(0x01, AD)
    assert m.raw(hdr(0x3D)) == wire(0xC5, 0x92, 0x74, 0x96, 0x00, 0x02, 0x00, 0xFF)
    assert m.raw(hdr(0x3D)) == wire(0xC5, 0x00, 0x00, 0x00, 0x00, 0xFF, 0xFB, 0xFF)


def test_set_otp_param_zaps_one_byte() -> None:
    m, _node = setup()
    # §6.11.11: OTP address 0x06 (1111 1 110), data 0x81
    m.raw(mframe(0x3C, 0x80, 0x90, 0x80 | AD, 0xFE, 0x81, 0xFF, 0xFF, 0xFF))
    m.prepare(0x02, AD)
    assert m.raw(hdr(0x3D)) == wire(0x11, 0x22, 0x15, 0xF3, 0x51, 0x03, 0x81, 0x0C)


def test_set_position_three_ways() -> None:
    m, _node = setup()
    activate(m, AD)
    m.raw(mframe(SETPOS, 0x01, 0x00))  # type #3: TagPos 0x0100
    m.wait(1.0)
    assert m.actual_pos(AD) == 0x100
    m.raw(mframe(GP4, 0x8B, 0x80 | AD, 0xFF, 0x00))  # type #1: TagPos -256
    m.wait(1.0)
    assert m.actual_pos(AD) == -256
    # type #4 for two motors: AD1 = 0x45 to 0x0200, AD2 = 0x46 (absent) to 0x0300
    m.raw(mframe(0x3C, 0x80, 0x8B, 0x80 | AD, 0x02, 0x00, 0x80 | 0x46, 0x03, 0x00))
    m.wait(1.0)
    assert m.actual_pos(AD) == 0x200


def test_set_position_short_one_two_four_motors() -> None:
    a = NodeConfig(name="a", hw=0b111, otp=bytes((0, 0, 0x03, 0, 0, 0, 0, 0)))  # AD 0x73
    b = NodeConfig(name="b", hw=0b111, otp=bytes((0, 0, 0x04, 0, 0, 0, 0, 0)))  # AD 0x74
    _bus, _clock, m = make_bus((a, b))
    half = codec.MotorParams(irun=8, ihold=1, vmax=5, vmin=1, secpos=0x400, acc=3, stepmode=0)
    for ad in (0x73, 0x74):
        activate(m, ad, half)
    m.assign(0, [(RomPointer.SET_POSITION_SHORT_1, 0x09), (RomPointer.SET_POSITION_SHORT_2, 0x29),
                 (RomPointer.SET_POSITION_SHORT_4, 0x39)], broad=True)  # fmt: skip
    # 1 motor (§6.11.13): Pos[10:8] Broad AD[3:0], Pos[7:0]: node 3 to 100 half-steps
    m.raw(mframe(0x09, 0x13, 100))
    m.wait(1.0)
    assert [m.actual_pos(ad) for ad in (0x73, 0x74)] == [800, 0]
    # 2 motors: node 3 to -1 half-step (0x7FF), node 4 to 0x1FF = 511 half-steps
    m.raw(mframe(0x29, 0xF3, 0xFF, 0x34, 0xFF))
    m.wait(1.5)
    assert [m.actual_pos(ad) for ad in (0x73, 0x74)] == [-8, 511 * 8]
    # 4 motors: nodes 4 and 3 (two absent), to 2 and -1024 (0x400)
    m.raw(mframe(0x39, 0x14, 2, 0x15, 0, 0x83, 0x00, 0x16, 0))
    m.wait(3.0)
    assert [m.actual_pos(ad) for ad in (0x73, 0x74)] == [-1024 * 8, 16]
    # broadcast (Broad = 0) with one motor: both to 10 half-steps
    m.raw(mframe(0x09, 0x00, 10))
    m.wait(3.0)
    assert [m.actual_pos(ad) for ad in (0x73, 0x74)] == [80, 80]


def test_set_position_short_is_ignored_outside_half_stepping() -> None:
    a = NodeConfig(name="a", hw=0b111, otp=bytes((0, 0, 0x03, 0, 0, 0, 0, 0)))
    _bus, _clock, m = make_bus((a,))
    activate(m, 0x73)  # 1/16 stepping
    m.assign(0x73, [(RomPointer.SET_POSITION_SHORT_1, 0x09)])
    m.raw(mframe(0x09, 0x13, 100))
    m.wait(0.5)
    assert m.actual_pos(0x73) == 0


def test_goto_secure_position() -> None:
    m, _node = setup()
    params = codec.MotorParams(irun=8, ihold=1, vmax=5, vmin=1, secpos=0x005, acc=3, stepmode=3)
    activate(m, AD, params)
    assert m.raw(mframe(GP2, 0x84, 0x80 | AD)) == b""  # §6.11.5
    m.wait(1.0)
    assert m.actual_pos(AD) == 5 << 5  # SecPos 11 MSBs of the 16-bit position


def test_hard_stop_sets_steploss() -> None:
    m, _node = setup()
    activate(m, AD)
    m.raw(mframe(GP4, 0x8B, 0x80 | AD, 0x40, 0x00))
    m.wait(0.3)
    m.raw(mframe(GP2, 0x85, 0x80 | AD))  # §6.11.6
    m.wait(0.01)
    pos = m.actual_pos(AD)
    assert 0 < pos < 0x4000
    assert m.raw(hdr(STATUS)) == wire(0x45, 0x40)  # <StepLoss>
    m.prepare(0x01, AD)
    m.raw(hdr(0x3D))
    assert m.raw(hdr(0x3D))[1:5] == bytes((*codec.u16(pos), *codec.u16(pos)))  # TagPos = ActPos


def test_soft_stop_decelerates_then_keeps_the_position() -> None:
    m, node = setup()
    activate(m, AD)
    m.raw(mframe(GP4, 0x8B, 0x80 | AD, 0x40, 0x00))
    m.wait(0.3)
    m.raw(mframe(GP2, 0x8F, 0x80 | AD))  # §6.11.14
    assert node.state == State.SOFTSTOP  # type: ignore[attr-defined]
    m.wait(0.5)
    pos = m.actual_pos(AD)
    assert node.state == State.STOPPED  # type: ignore[attr-defined]
    assert node.tagpos == pos  # type: ignore[attr-defined]
    assert m.raw(hdr(STATUS)) == wire(0x45, 0x00)  # no step loss


def test_reset_position() -> None:
    m, _node = setup()
    activate(m, AD)
    m.raw(mframe(GP4, 0x8B, 0x80 | AD, 0x01, 0x00))
    m.wait(1.0)
    m.raw(mframe(GP2, 0x86, 0x80 | AD))  # §6.11.7
    assert m.actual_pos(AD) == 0


def test_reset_to_default_reloads_ram_and_keeps_actpos() -> None:
    m, _node = setup()
    activate(
        m, AD, codec.MotorParams(irun=1, ihold=1, vmax=5, vmin=1, secpos=0x400, acc=3, stepmode=3)
    )
    m.raw(mframe(GP4, 0x8B, 0x80 | AD, 0x01, 0x00))
    m.wait(1.0)
    m.raw(mframe(GP2, 0x87, 0x80 | AD))  # §6.11.8
    first, second = m.full_status(AD)
    assert first == bytes((0xC5, 0xF3, 0x51, 0x63, 0x00, 0x02, 0x00, 0xFF))
    assert second == bytes((0xC5, 0x01, 0x00, 0x01, 0x00, 0x00, 0xF8, 0xFF))


def test_run_init_frame() -> None:
    m, node = setup()
    activate(m, AD)
    # §6.11.9: Vmax 5 Vmin 1, Pos1 = 0x0400, Pos2 = 0x0380
    m.raw(mframe(0x3C, 0x80, 0x88, 0x80 | AD, 0x51, 0x04, 0x00, 0x03, 0x80))
    assert node.state == State.RUNINIT  # type: ignore[attr-defined]
    m.wait(3.0)
    assert node.state == State.STOPPED  # type: ignore[attr-defined]
    assert m.actual_pos(AD) == 0


def test_sleep_frame() -> None:
    m, node = setup()
    activate(m, AD)
    assert m.raw(mframe(0x3C, 0x00, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF)) == b""  # §6.11.15
    m.wait(0.01)
    assert node.state == State.SLEEP  # type: ignore[attr-defined]

"""The shipped LDF (config/tmc211.ldf) parses with ldfparser and says what the nodes do.

Ref: TMC211 §6.8 Table 15 (example identifiers), §6.9 (frame types), §6.11 (layouts).
"""

from __future__ import annotations

from pathlib import Path

import ldfparser

from ecatsim.lin import codec
from ecatsim.lin.frame import data_length
from ecatsim.lin.tables import EXAMPLE_IDS, ROM_FRAME_LENGTH, RomPointer

ROOT = Path(__file__).resolve().parents[3]
LDF = ldfparser.parse_ldf(str(ROOT / "config" / "tmc211.ldf"))
ROMS = {
    "GetStatus": RomPointer.GET_STATUS,
    "GetActualPos": RomPointer.GET_ACTUAL_POS,
    "SetPosition": RomPointer.SET_POSITION,
    "GeneralPurpose2": RomPointer.GENERAL_PURPOSE_2,
    "GeneralPurpose4": RomPointer.GENERAL_PURPOSE_4,
    "Preparing": RomPointer.PREPARING,
    "SetPositionShort1": RomPointer.SET_POSITION_SHORT_1,
    "SetPositionShort2": RomPointer.SET_POSITION_SHORT_2,
    "SetPositionShort4": RomPointer.SET_POSITION_SHORT_4,
}
ADDRESS = {"left": 0x01, "right": 0x02}


def test_header_values() -> None:
    assert str(LDF.get_protocol_version()) == "1.3"
    assert LDF.get_baudrate() == 19200
    assert LDF.get_frame(0x3C).name == "MasterReq" and LDF.get_frame(0x3D).name == "SlaveResp"


def test_every_frame_is_a_table_15_identifier_of_the_right_length() -> None:
    frames = list(LDF.get_unconditional_frames())
    assert len(frames) == 12
    for f in frames:
        kind, _, node = f.name.partition("_")
        rom = ROMS[kind]
        xxx = ADDRESS[node] & 7 if node else 0
        assert f.frame_id == EXAMPLE_IDS[rom] | xxx, f.name
        assert f.length == data_length(f.frame_id) == ROM_FRAME_LENGTH[rom], f.name
        bits = sorted(
            b for sig_offset, sig in f.signal_map for b in range(sig_offset, sig_offset + sig.width)
        )
        assert bits == list(range(8 * f.length)), f.name  # every bit, once


def test_ldf_decodes_what_the_node_sends() -> None:
    flags = codec.Flags(vddreset=1, steploss=1, tw=1, tinfo=2, esw=1)
    data = codec.get_actual_pos_direct(0x02, -2, flags)
    d = LDF.get_frame("GetActualPos_right").decode_raw(data)
    assert (d["GAP_right_AD"], d["GAP_right_ESW"]) == (0x02, 1)
    assert codec.s16(d["GAP_right_ActPosHi"], d["GAP_right_ActPosLo"]) == -2
    assert (d["GAP_right_VddReset"], d["GAP_right_StepLoss"], d["GAP_right_TW"]) == (1, 1, 1)
    assert (d["GAP_right_Tinfo"], d["GAP_right_TSD"], d["GAP_right_UV2"]) == (2, 0, 0)
    s = LDF.get_frame("GetStatus_left").decode(codec.get_status(0x01, flags))
    assert s["GS_left_Tinfo"] == "high temperature warning"


def test_ldf_encodes_what_the_sheet_prints() -> None:
    gp4 = LDF.get_frame("GeneralPurpose4")
    raw = gp4.encode({"GP4_Command": "SetPosition", "GP4_AD": 0x45, "GP4_Broad": 1,
                      "GP4_ParamHi": 0x12, "GP4_ParamLo": 0x34})  # fmt: skip
    assert bytes(raw) == bytes((0x8B, 0xC5, 0x12, 0x34))  # §6.11.12 type #1
    sps = LDF.get_frame("SetPositionShort1")
    raw = sps.encode_raw({"SPS1_AD": 3, "SPS1_Broad": 1, "SPS1_PosHi": 7, "SPS1_PosLo": 0xFF})
    assert bytes(raw) == bytes((0xF3, 0xFF))  # §6.11.13: Pos[10:8] Broad AD[3:0], Pos[7:0]
    prep = LDF.get_frame("Preparing")
    raw = prep.encode({"PREP_Command": "GetFullStatus", "PREP_AD": 0x02, "PREP_One": 1})
    assert bytes(raw) == bytes((0x81, 0x82))  # §6.11.2 type #7

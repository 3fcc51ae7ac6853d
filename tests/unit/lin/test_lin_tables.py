"""The datasheet tables as data: consistency checks that catch a mistyped entry.

Ref: TMC211 §5.1.4 Table 3, §5.1.5 Table 4, §5.1.6 Table 5, §5.3.2 Table 12, §6.5 Table 13.
"""

from __future__ import annotations

from ecatsim.lin import tables as t
from ecatsim.lin.otp import physical_address


def test_vmax_columns_scale_by_step_mode() -> None:
    for i in range(16):
        fs = t.VMAX_SIXTEENTH[i] / 16
        assert abs(t.VMAX_FS[i] - fs) <= 1  # the FS/s column is rounded
        for col, per_fs in ((t.VMAX_HALF, 2), (t.VMAX_QUARTER, 4), (t.VMAX_EIGHTH, 8)):
            assert abs(col[i] - fs * per_fs) <= 1, (i, col[i])


def test_vmax_groups_as_the_faq_lists_them() -> None:
    assert [i for i, g in enumerate(t.VMAX_GROUP) if g == "A"] == [0]
    assert [i for i, g in enumerate(t.VMAX_GROUP) if g == "B"] == [1, 2, 3, 4, 5, 6]
    assert [i for i, g in enumerate(t.VMAX_GROUP) if g == "D"] == [13, 14, 15]


def test_vmin_table_is_about_k_over_32_of_vmax() -> None:
    """Table 4's "possible rounded values" stray up to 17 % from k/32 at the smallest
    ratios (the circuit's dividers); a mistyped entry would stray further."""
    for k in range(1, 16):
        for v in range(16):
            exact = k / 32 * t.VMAX_FS[v]
            assert abs(t.VMIN_FS[k - 1][v] - exact) <= max(0.17 * exact, 1.5), (k, v)
        row = t.VMIN_FS[k - 1]
        assert list(row) == sorted(row)
    for v in range(16):
        assert [t.VMIN_FS[k][v] for k in range(15)] == sorted(t.VMIN_FS[k][v] for k in range(15))
    assert t.vmin_units(0, 7) == t.vmax_units(7) == 4364.0  # index 0: Vmin = Vmax


def test_acc_table_rows_rise_and_units() -> None:
    for v in range(16):
        col = [row[v] for row in t.ACC_FS2]
        assert col == sorted(col)
    assert t.acc_units(3, 5) == 3609 * 16
    assert t.ACC_FS2[0][15] == 473 and t.ACC_FS2[15][15] == 40047 and t.ACC_FS2[14][3] == 29570


def test_current_table_and_step_resolution() -> None:
    assert t.CURRENT_MA[0] == 59 and t.CURRENT_MA[0xF] == 800 and len(t.CURRENT_MA) == 16
    assert [t.STEP_RESOLUTION[m] for m in t.StepMode] == [8, 4, 2, 1]


def test_rom_pointer_examples_code_their_frame_lengths() -> None:
    lengths = {0: 2, 1: 2, 2: 4, 3: 8}
    for rom, ident in t.EXAMPLE_IDS.items():
        assert lengths[ident >> 4] == t.ROM_FRAME_LENGTH[rom], rom


def test_priority_encoder_is_complete() -> None:
    for event in t.Event:
        assert set(t.PRIORITY_ENCODER[event]) == set(t.State)
    # the Sleep column is blank: no power (Table 8 note 1)
    assert all(row[t.State.SLEEP] in (t.Action.IGNORED, t.Action.NA)
               for row in t.PRIORITY_ENCODER.values())  # fmt: skip


def test_physical_address_table_13() -> None:
    # ADM = 0: HW0 HW1 HW2 PA3..PA0
    assert physical_address(0, 0b0101, 0b001) == 0b1000101
    assert physical_address(0, 0b0000, 0b100) == 0b0010000
    # ADM = 1: PA0 HW0 HW1 HW2 PA3 PA2 PA1
    assert physical_address(1, 0b0001, 0b000) == 0b1000000
    assert physical_address(1, 0b1110, 0b011) == 0b0110111
    assert physical_address(1, 0b0000, 0b100) == 0b0001000

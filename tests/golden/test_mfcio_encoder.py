"""Golden tests of the MFCIO encoder unit against TMC8460 §6.6: quadrature counting scaled
by ENC_CONST (Table 139's constants give 51200 per revolution), the N event detector of
ENC_MODE, ENC_LATCH and ENC_STATUS."""

from __future__ import annotations

import random

import pytest

from ecatsim.mfcio.encoder import AB_OF, PHASE, Encoder
from ecatsim.mfcio.parts import EncoderSpec, Shaft, StepperSpec

SEL_DECIMAL = 0x0400


def forward(e: Encoder, k: int, n: int = 0) -> None:
    """k quadrature transitions one by one (the decoder's view)."""
    step = 1 if k > 0 else -1
    for _ in range(abs(k)):
        e.inputs(*AB_OF[(PHASE[(e.a, e.b)] + step) % 4], n)


def test_const_one_counts_each_transition() -> None:
    """ENC_CONST = 0x00010000 (§6.5.1 step 5, §6.6.8): +1/-1 per A/B transition."""
    e = Encoder()
    e.write("ENC_CONST", 0x00010000)
    forward(e, 10)
    assert e.x == 10
    forward(e, -13)
    assert e.x == (-3) & 0xFFFFFFFF


@pytest.mark.parametrize(
    ("counts", "const", "decimal"),
    [
        (200, 0x01000000, False),
        (360, 0x008E38E4, False),
        (500, 0x00660FA0, True),
        (1000, 0x003307D0, True),
        (1024, 0x00320000, False),
        (4000, 0x000C1F40, True),
        (4096, 0x000C8000, False),
        (16384, 0x00032000, False),
    ],
)
def test_table_139_constants_match_51200_microsteps(counts: int, const: int, decimal: bool) -> None:
    """One revolution of each encoder of Table 139 counts 51200 (200 full steps x 256)."""
    e = Encoder()
    e.write("ENC_MODE", SEL_DECIMAL if decimal else 0)
    e.write("ENC_CONST", const)
    e.run(counts, 0)
    assert e.x == 51200
    e.run(-counts, 0)
    assert e.x == 0


def test_decimal_fraction_of_10000_is_one_more_integer() -> None:
    """§6.6.3: with enc_sel_decimal a fractional part of 10000 equals +1."""
    e = Encoder()
    e.write("ENC_MODE", SEL_DECIMAL)
    e.write("ENC_CONST", 10000)  # 0 + 10000/10000
    e.run(7, 0)
    assert e.x == 7


def test_example_mode_0x1c_latches_while_n_is_high() -> None:
    """§6.6.8: ENC_MODE 0x001C: an N event while N is high, A/B ignored, latch only."""
    e = Encoder()
    e.write("ENC_MODE", 0x001C)
    e.write("ENC_CONST", 0x00010000)
    forward(e, 5)
    assert (e.latch, e.status) == (0, 0)
    forward(e, 1, n=1)
    assert (e.x, e.latch, e.status) == (6, 6, 1)
    forward(e, 1, n=1)  # still active: latched again
    assert e.latch == 7
    forward(e, 3)
    assert (e.x, e.latch) == (10, 7)


def test_status_is_not_cleared_by_reading_but_by_mode_bit_15() -> None:
    e = Encoder()
    e.write("ENC_MODE", 0x005C)  # pos_edge, clr_cont, ignore_AB, pol_N
    e.write("ENC_CONST", 0x00010000)
    forward(e, 1, n=1)
    assert e.status == 1
    assert e.status == 1
    e.write("ENC_MODE", 0x805C)
    assert e.status == 0


def test_clr_enc_x_on_positive_edge_once() -> None:
    """clr_once passes the next event only; clr_enc_x clears ENC_X, the latch keeps it."""
    e = Encoder()
    e.write("ENC_MODE", 0x0100 | 0x0040 | 0x0020 | 0x0008 | 0x0004)
    e.write("ENC_CONST", 0x00010000)
    forward(e, 9)
    forward(e, 1, n=1)
    assert (e.x, e.latch) == (0, 10)
    forward(e, 4)
    forward(e, 1, n=1)  # the second N pulse passes no more
    assert (e.x, e.latch) == (5, 10)


def test_ab_gating_and_negative_edge() -> None:
    """Without ignore_AB the event needs A = pol_A and B = pol_B; neg_edge fires when N
    becomes inactive."""
    e = Encoder()
    e.write("ENC_MODE", 0x0080 | 0x0010 | 0x0004)  # neg_edge, clr_cont, pol_N, pol A=B=0
    e.write("ENC_CONST", 0x00010000)
    forward(e, 3)  # phase 3: A=0, B=1
    forward(e, 1, n=1)  # phase 0: A=B=0, N high
    assert e.status == 0
    forward(e, 1, n=0)  # N falls, A=1 B=0: A/B do not match
    assert e.status == 0
    forward(e, 3, n=1)  # back to phase 0 with N high
    forward(e, -1, n=0)  # N falls at phase 3 (A=0, B=1): no match
    forward(e, 1, n=1)
    e.write("ENC_MODE", 0x0080 | 0x0010 | 0x0004 | 0x0001)  # pol_A = 1
    forward(e, 1, n=0)  # N falls at phase 1: A=1, B=0: match
    assert (e.status, e.latch) == (1, e.x)


def test_double_transition_is_not_counted() -> None:
    e = Encoder()
    e.write("ENC_CONST", 0x00010000)
    e.inputs(1, 1, 0)
    assert (e.x, e.errors) == (0, 1)


def test_write_x_loads_the_accumulator() -> None:
    e = Encoder()
    e.write("ENC_CONST", 0x00018000)  # 1.5
    e.run(3, 0)
    assert e.x == 4  # 4.5
    e.write("ENC_X_W", 100)
    e.run(1, 0)
    assert e.x == 101  # fraction cleared by the load


@pytest.mark.parametrize("seed", range(6))
def test_run_equals_transition_by_transition(seed: int) -> None:
    """The O(1) run is the same as feeding every transition (any mode, N held)."""
    rnd = random.Random(seed)
    for _ in range(40):
        mode = rnd.choice([0x18, 0x1C, 0x10, 0x30, 0x118, 0x11C, 0x13, 0x1B, 0x5C, 0x9C, 0x0])
        const = rnd.choice([0x10000, 0x18000, 0x8E38E4, 0xFFFF0000, 0x1F40])
        a, b = Encoder(), Encoder()
        for e in (a, b):
            e.write("ENC_MODE", mode | (SEL_DECIMAL if const == 0x1F40 else 0))
            e.write("ENC_CONST", const)
        for _ in range(8):
            k = rnd.randint(-9, 9)
            n = rnd.randint(0, 1)
            a.run(k, n)
            if k:
                forward(b, k, n)
            assert (a.x, a.latch, a.status, a.a, a.b, a.n, a.armed_once) == (
                b.x,
                b.latch,
                b.status,
                b.a,
                b.b,
                b.n,
                b.armed_once,
            ), (mode, const, k, n)
            assert (a.events > 0) == (b.events > 0)


def test_shaft_3200_pulses_4000_counts() -> None:
    """A stepper at 3200 pulses per revolution with a 4000-count encoder: 2000 pulses read
    back as 2500 counts; the index pulse latches once per turn."""
    sh = Shaft(StepperSpec(200, 16, 1), EncoderSpec(4000, True))
    e = Encoder()
    e.write("ENC_MODE", 0x005C)  # latch at the positive edge of N (active high)
    e.write("ENC_CONST", 0x00010000)
    sh.move(2000, e)
    assert (sh.count, e.x) == (2500, 2500)
    sh.move(2000, e)  # passes the index at count 4000
    assert (e.x, e.latch, e.status) == (5000, 4000, 1)
    sh.move(-4000, e)  # back through the index at 4000 and 0
    assert (e.x, e.latch) == (0, 0)

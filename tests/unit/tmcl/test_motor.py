"""The axis on simulated time: switches, reference search modes, open-loop step loss and
the encoder deviation, stallGuard2, I²t, faults, encoder and closed-loop initialisation.

Ref: TMCM-1311 TMCL firmware manual §6, §7, §8.1, §8.3, §9, §9.1.1.
"""

from __future__ import annotations

from typing import Any, cast

from ecatsim.tmcl import protocol as P
from ecatsim.tmcl.module import ModuleConfig
from ecatsim.tmcl.motor import DE_OT, DE_STALL, SW_I2T, SW_LEFT, SW_OVERT, Switches
from tests.unit.tmcl.conftest import Bench


def bench_with(**switches: float) -> Bench:
    return Bench([ModuleConfig(switches=Switches(**cast("dict[str, Any]", switches)))])


def test_stop_switch_stops_motion_toward_it_unless_disabled() -> None:
    b = bench_with(left=-10_000)
    b.value(P.ROL, 0, 0, 20_000)
    b.advance(2.0)
    assert b.gap(11) == 1
    assert b.gap(3) == 0
    assert b.gap(18) & SW_LEFT
    stopped = b.gap(1)
    assert -14_000 < stopped <= -10_000  # soft stop (149): 3906 steps to stop
    b.value(P.ROL, 0, 0, 20_000)  # still toward the switch: no motion
    b.advance(0.5)
    assert b.gap(1) == stopped
    b.value(P.ROR, 0, 0, 20_000)  # away from it: free
    b.advance(0.5)
    assert b.gap(1) > stopped
    b.sap(13, 1)  # left switch disabled
    b.value(P.ROL, 0, 0, 20_000)
    b.advance(2.0)
    assert b.gap(1) < -20_000
    b.value(P.SGP, 79, 0, 1)  # end switch polarity reversed: now reads inactive
    assert b.gap(11) == 0
    b.door.close()


def test_reference_search_mode_1_left_switch_and_mode_2_end_switch_distance() -> None:
    b = bench_with(left=-20_000, right=40_000)
    b.sap(194, 25_600)
    b.sap(195, 5000)
    b.value(P.RFS, 0)
    b.advance(10.0)
    assert b.cmd(P.RFS, 2) == (P.OK, 1)
    assert b.gap(1) == 0
    assert abs(b.m.axis.rotor - (-20_000)) < 10
    b.sap(193, 2)
    b.value(P.RFS, 0)
    b.advance(12.0)
    assert b.cmd(P.RFS, 2) == (P.OK, 1)
    assert abs(b.gap(196) - 60_000) < 100
    b.door.close()


def test_reference_search_mode_5_reverses_at_the_left_switch() -> None:
    b = bench_with(left=-5_000, home=20_000, home_width=1000)
    b.sap(193, 5)  # home in negative direction: not there, the left switch turns it
    b.sap(194, 25_600)
    b.sap(195, 5000)
    b.value(P.RFS, 0)
    b.advance(8.0)
    assert b.cmd(P.RFS, 2) == (P.OK, 1)
    assert abs(b.m.axis.rotor - 20_000) < 10
    assert b.gap(1) == 0
    assert b.gap(9) == 1
    b.door.close()


def test_open_loop_loses_steps_under_load_and_the_deviation_stops_it() -> None:
    b = Bench()
    b.sap(212, 1000)  # max encoder deviation, microsteps
    b.value(P.ROR, 0, 0, 25_600)
    b.advance(1.0)
    assert b.gap(207) == 0
    assert abs(b.gap(237)) < 100
    b.value(P.SGP, 0, 3, 0)
    b.door.ctl("load", ["1", "0.8"])  # more than the 0.6 Nm run current 128 gives
    b.advance(0.5)
    assert b.gap(207) == 1
    assert b.gap(3) == 0  # stopped
    b.door.ctl("load", ["1", "0"])
    b.value(P.ROR, 0, 0, 25_600)  # the next command drives again
    assert b.gap(207) == 0
    b.door.close()


def test_stallguard_load_value_falls_with_load_and_stop_on_stall() -> None:
    b = Bench()
    b.value(P.ROR, 0, 0, 51_200)
    b.advance(1.5)
    light = b.gap(206)
    b.door.ctl("load", ["1", "0.4"])
    b.advance(0.2)
    heavy = b.gap(206)
    assert 0 < heavy < light <= 1023
    b.sap(181, 10_000)  # stop on stall above 10000 pps
    b.door.ctl("fault", ["1", "stall", "on"])
    b.advance(0.05)
    assert b.gap(3) == 0
    assert b.gap(208) & DE_STALL
    b.door.close()


def test_i2t_exceed_counter_flag_and_clear() -> None:
    b = Bench()
    b.sap(6, 255)  # 3 A RMS: 900000 > the limit of 500000 (mA²/10)
    b.sap(25, 100)
    b.value(P.ROR, 0, 0, 10_000)
    b.advance(1.0)
    assert b.gap(27) > 500_000
    assert b.gap(28) == 1
    assert b.gap(18) & SW_I2T
    b.sap(29, 0)
    assert not b.gap(18) & SW_I2T
    b.door.close()


def test_overtemperature_switches_the_driver_off() -> None:
    b = Bench()
    b.door.ctl("fault", ["1", "overtemperature", "on"])
    assert b.gap(208) & DE_OT
    assert b.gap(18) & SW_OVERT
    assert b.gap(155) == 125
    b.value(P.ROR, 0, 0, 20_000)
    b.advance(0.5)
    assert b.gap(150) == 0  # no current
    assert b.m.axis.rotor == 0.0  # the motor does not turn
    b.door.close()


def test_encoder_initialisation_and_closed_loop_need_a_working_encoder() -> None:
    b = Bench()
    b.sap(132, 1)
    b.advance(0.5)
    assert b.gap(132) == 1
    b.advance(0.6)
    assert b.gap(132) == 2
    b.door.ctl("fault", ["1", "encoder_loss", "on"])
    b.sap(132, 1)
    b.advance(1.1)
    assert b.gap(132) == 3
    b.sap(129, 1)
    b.advance(0.5)
    assert b.gap(133) == 0
    b.door.close()


def test_an_encoder_back_from_a_loss_counts_on_from_where_it_stopped() -> None:
    """ctl fault encoder_loss on/off: the counter (AP 209) freezes, then counts on from the
    frozen value; a position set with SAP 209 before is kept."""
    b = Bench()
    b.sap(209, 5000)
    assert b.gap(209) == 5000
    b.door.ctl("fault", ["1", "encoder_loss", "on"])
    ax = b.m.axis
    ax.rotor += 256 * 10  # ten full steps turned while the signal is gone
    assert b.gap(209) == 5000
    b.door.ctl("fault", ["1", "encoder_loss", "off"])
    assert b.gap(209) == 5000
    ax.rotor += 256 * ax.fullsteps  # a full turn with the signal back: AP 210 counts
    assert b.gap(209) == 5000 + ax.enc_res
    b.door.close()


def test_torque_mode_only_in_closed_loop() -> None:
    b = Bench()
    assert b.cmd(P.SAP, 14, 0, 500)[0] == P.INVALID_VALUE
    b.sap(129, 1)
    b.advance(0.2)
    b.sap(14, 500)
    assert b.gap(128) == 2
    b.advance(0.5)
    assert b.gap(19) == 500
    assert b.gap(131) > 0
    b.door.close()


def _turns(b: Bench) -> float:
    return b.m.axis.rotor / (256 * 200)


def test_speeds_are_pulses_per_second_in_both_loops() -> None:
    """§5.7.1 (ROR: microsteps per second), §6.1, the §6/§8.4 tables: speeds and
    accelerations are pps in closed loop too; only positions count encoder steps (the
    1.11 revision note). With a 4000-step encoder, ROR 20000 turns 0.39 rev/s in both
    loops (decision T7)."""
    speeds = []
    for closed in (0, 1):
        b = Bench()
        b.sap(210, 4000)
        b.sap(129, closed)
        b.advance(0.2)
        b.value(P.ROR, 0, 0, 20_000)
        b.advance(1.0)  # 0.39 s of ramp at 51200 pps/s
        start = _turns(b)
        b.advance(1.0)
        speeds.append(_turns(b) - start)
        assert b.gap(3) == 20_000
        # measured: pps as well, to one encoder step (12.8 pulses) per 10 ms window
        assert abs(b.gap(131) - 20_000) <= 12_800
        assert b.gap(16) == 1
        b.door.close()
    assert abs(speeds[0] - 20_000 / 51_200) < 1e-3
    assert abs(speeds[1] - 20_000 / 51_200) < 2e-3


def test_closed_loop_positions_are_encoder_steps_moved_at_pps() -> None:
    """MVP in closed loop: the target in encoder steps (§8.4), the ramp of 4 and 5 in pps:
    one revolution (4000 steps) at 51200 pps and 51200 pps/s takes the 2 s it takes in
    open loop (51200 microsteps)."""
    b = Bench()
    b.sap(210, 4000)
    b.sap(129, 1)
    b.advance(0.2)
    b.value(P.MVP, 0, 0, 4000)
    b.advance(1.0)
    assert abs(_turns(b) - 0.5) < 0.01  # half way after 1 s
    assert b.gap(3) == 51_200
    b.advance(1.2)
    assert b.gap(8) == 1
    assert b.gap(1) == 4000
    assert b.gap(233) == 51_200  # the ramp's virtual position in microsteps (§6, T34)
    assert abs(_turns(b) - 1.0) < 1e-3
    b.door.close()


def test_pull_out_torque_falls_with_speed_open_loop_loses_steps() -> None:
    """Decision T31: the chopper cannot drive the set current against the inductance and
    the back EMF at speed. Run current 128 (1.5 A RMS, 0.6 Nm) follows 10 rev/s; at
    2,048,000 pps (40 rev/s) the field runs away from the rotor: it stalls, the position
    error grows and the deviation limit (212) stops the motor."""
    b = Bench()
    b.sap(5, 1_000_000)
    b.sap(212, 10_000)
    b.value(P.ROR, 0, 0, 512_000)  # 10 rev/s
    b.advance(1.5)
    assert b.gap(207) == 0
    assert abs(b.gap(237)) < 200
    assert abs(b.m.axis.rotor_v / (256 * 200) - 10.0) < 0.01
    b.value(P.MST)
    b.advance(1.0)
    fastest = 0.0
    b.value(P.ROR, 0, 0, 2_048_000)
    for _ in range(30):
        b.advance(0.05)
        fastest = max(fastest, abs(b.m.axis.rotor_v) / (256 * 200))
    assert b.gap(207) == 1  # the deviation stopped it
    assert b.gap(3) == 0
    assert fastest < 13.5  # where the back EMF reaches the 24 V supply
    b.door.close()


def test_torque_speed_curve_of_the_default_motor() -> None:
    """The share of the set current the driver reaches: all of it at rest and up to the
    corner speed, then less, none where the back EMF reaches the supply (T31)."""
    import math

    ax = Bench().m.axis
    per_rps = 2 * math.pi  # rad/s per rev/s

    def share(rps: float, amps: float) -> float:
        return ax._current_reach(amps, rps * per_rps, rps * per_rps)

    assert share(0, 3.0) == 1.0
    assert share(5, 3.0) == 1.0
    assert 0.75 < share(7, 3.0) < 0.85  # 0.96 Nm of 1.2
    assert share(9, 1.5) == 1.0  # half the current holds on longer
    assert share(11, 1.5) < share(10, 1.5) < 1.0
    assert share(13.6, 1.5) == 0.0


def test_an_overload_holds_the_rotor_it_does_not_race_it() -> None:
    """Decision T32: the load resists motion like friction and never turns the rotor: 3 Nm
    (2.5 x the holding torque) at rest leaves it still; driven, the field slips past it."""
    b = Bench()
    b.sap(212, 2_000)
    b.door.ctl("load", ["1", "3"])
    b.advance(2.0)
    assert b.m.axis.rotor == 0.0
    b.value(P.ROR, 0, 0, 51_200)
    b.advance(1.0)
    assert b.m.axis.rotor == 0.0
    assert b.gap(207) == 1  # steps lost: the deviation stopped it
    b.door.ctl("load", ["1", "-3"])  # the size counts, not the sign
    b.sap(129, 1)
    b.advance(0.2)
    b.value(P.MVP, 0, 0, -40_000)
    b.advance(2.0)
    assert abs(b.m.axis.rotor) < 1.0
    assert b.m.axis.rotor_v == 0.0
    b.door.close()


def test_gamma_is_0_to_255_between_the_field_weakening_speeds() -> None:
    """Axis parameter 230 (§6 and §8.9: 0-255; §8.10's pps range is not taken, T33)."""
    b = Bench()
    b.sap(108, 100_000)
    b.sap(109, 300_000)
    b.sap(5, 1_000_000)
    assert b.gap(230) == 0
    b.value(P.ROR, 0, 0, 200_000)
    b.advance(1.0)
    assert abs(b.gap(230) - 128) <= 2
    b.value(P.ROR, 0, 0, 400_000)
    b.advance(1.0)
    assert b.gap(230) == 255
    b.door.close()

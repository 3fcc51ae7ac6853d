"""One daemon per link: the lock file per interface, TAP device or UDP port (decision O1)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from ecatsim.errors import UserError
from ecatsim.ethercat.linklock import lock_link, lock_name
from ecatsim.ethercat.run import RunOptions, take_link


def test_a_second_lock_on_the_link_names_the_pid_serving_it(tmp_path: Path) -> None:
    first = lock_link(tmp_path, "ecat1", None, None)
    assert first is not None
    path = tmp_path / lock_name("iface", "ecat1")
    assert path.read_text() == f"{os.getpid()}\n"
    with pytest.raises(UserError) as exc:
        lock_link(tmp_path, "ecat1", None, None)
    assert str(exc.value) == (
        f"--iface ecat1: ecatsim PID {os.getpid()} serves this link already; two daemons on "
        f"one link would both answer every frame: stop that one first (kill {os.getpid()})"
    )
    other = lock_link(tmp_path, "ecat2", None, None)  # another interface: no conflict
    assert other is not None
    first.close()
    assert not path.exists()
    again = lock_link(tmp_path, "ecat1", None, None)  # free again once the first is gone
    assert again is not None
    again.close()
    other.close()
    assert list(tmp_path.iterdir()) == []


def test_a_lock_left_by_a_dead_daemon_does_not_refuse(tmp_path: Path) -> None:
    path = tmp_path / lock_name("tap", "ecattap0")
    path.write_text("999999\n")  # the file of a daemon that was killed: nobody holds it
    lock = lock_link(tmp_path, None, "ecattap0", None)
    assert lock is not None and path.read_text() == f"{os.getpid()}\n"
    lock.close()


def test_udp_locks_the_port_whatever_the_host(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ECATSIM_RUN_DIR", str(tmp_path))
    a = take_link(RunOptions(udp="127.0.0.1:34980"))
    with pytest.raises(UserError, match=r"^--udp port 34980: ecatsim PID \d+ serves this link"):
        take_link(RunOptions(udp="0.0.0.0:34980"))
    assert take_link(RunOptions(udp="127.0.0.1:0")) is None  # kernel's choice
    assert a is not None
    a.close()


def test_the_link_options_are_checked_before_any_lock(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ECATSIM_RUN_DIR", str(tmp_path))
    with pytest.raises(UserError, match="give exactly one of"):
        take_link(RunOptions(iface="ecat1", tap="t0"))
    with pytest.raises(UserError, match="expected HOST:PORT"):
        take_link(RunOptions(udp="34980"))
    assert list(tmp_path.iterdir()) == []


def test_the_out_interface_is_a_link_of_its_own(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--out-iface B`` sends and receives on B: a daemon serving B already refuses it,
    before anything is built, and the daemon's own link lock is let go again."""
    from ecatsim.ethercat.run import run_daemon

    monkeypatch.setenv("ECATSIM_RUN_DIR", str(tmp_path))
    other = lock_link(tmp_path, "ecat9", None, None)  # another daemon serves ecat9
    assert other is not None
    with pytest.raises(UserError) as exc:
        run_daemon(RunOptions(udp="127.0.0.1:34999", out_iface="ecat9"))
    assert str(exc.value).startswith(f"--out-iface ecat9: ecatsim PID {os.getpid()} serves")
    assert sorted(p.name for p in tmp_path.iterdir()) == [lock_name("iface", "ecat9")]
    other.close()

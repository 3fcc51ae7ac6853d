"""Startup problems are one clear line naming the fix; --version; clean exit on signals."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from ecatsim import __version__
from tests.integration.netns import NetnsPair, proc_status

pytestmark = pytest.mark.integration


def ecatsim(
    *args: str, ns: str | None = None, user: int | None = None, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    cmd = [sys.executable, "-m", "ecatsim", *args]
    if user is not None:
        cmd = ["setpriv", f"--reuid={user}", f"--regid={user}", "--clear-groups", *cmd]
    if ns is not None:
        cmd = ["ip", "netns", "exec", ns, *cmd]
    full_env = {**os.environ, **env} if env is not None else None
    return subprocess.run(cmd, capture_output=True, text=True, timeout=20, env=full_env)


def one_error_line(r: subprocess.CompletedProcess[str]) -> str:
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("ecatsim: error: ")
    assert "Traceback" not in r.stderr
    return lines[0]


def test_version() -> None:
    r = ecatsim("--version")
    assert r.returncode == 0
    assert __version__ in r.stdout


def test_missing_interface() -> None:
    line = one_error_line(ecatsim("run", "--iface", "nosuch0"))
    assert "'nosuch0' does not exist" in line and "--iface" in line


def test_interface_with_ipv4_is_refused(netns_pair: NetnsPair) -> None:
    subprocess.run(
        [
            "ip",
            "-n",
            netns_pair.slave_ns,
            "addr",
            "add",
            "192.0.2.7/24",
            "dev",
            netns_pair.slave_if,
        ],
        check=True,
    )
    line = one_error_line(ecatsim("run", "--iface", netns_pair.slave_if, ns=netns_pair.slave_ns))
    assert "192.0.2.7" in line and "--allow-ip-iface" in line


def test_no_cap_net_raw(netns_pair: NetnsPair) -> None:
    line = one_error_line(
        ecatsim("run", "--iface", netns_pair.slave_if, ns=netns_pair.slave_ns, user=65534)
    )
    assert "CAP_NET_RAW" in line


def test_bad_yaml_field_names_file_and_key(tmp_path: Path) -> None:
    cfg = tmp_path / "seg.yaml"
    cfg.write_text("slaves:\n  - device: tmc8670\n    alias: twelve\n")
    line = one_error_line(ecatsim("run", "--iface", "lo", "--config", str(cfg)))
    assert f"{cfg}: slaves[0].alias: expected an integer 0..65535" in line
    cfg.write_text("slaves:\n  - device: tmc8670\n    colour: red\n")
    line = one_error_line(ecatsim("run", "--iface", "lo", "--config", str(cfg)))
    assert "slaves[0].colour: unknown key" in line
    cfg.write_text("slaves: [\n")
    line = one_error_line(ecatsim("run", "--iface", "lo", "--config", str(cfg)))
    assert str(cfg) in line and "not valid YAML" in line


def test_bad_device_description(tmp_path: Path) -> None:
    desc = tmp_path / "dev.yaml"
    desc.write_text(
        "identity: {vendor_id: 1, product_code: 2, revision: 3}\nsync_managers: [{control: x}]\n"
    )
    cfg = tmp_path / "seg.yaml"
    cfg.write_text(f"slaves:\n  - device: tmc8670\n    description: {desc}\n")
    line = one_error_line(ecatsim("run", "--iface", "lo", "--config", str(cfg)))
    assert "dev.yaml" in line and "sync_managers[0]" in line


def test_sigint_exits_cleanly(netns_pair: NetnsPair, tmp_path: Path) -> None:
    log = tmp_path / "d.log"
    cmd = ["ip", "netns", "exec", netns_pair.slave_ns, sys.executable, "-m", "ecatsim", "run",
           "--iface", netns_pair.slave_if, "--log-format", "json"]  # fmt: skip
    with open(log, "wb") as f:
        p = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT)

    deadline = time.monotonic() + 10
    while '"ready"' not in log.read_text() and time.monotonic() < deadline:
        time.sleep(0.05)
    p.send_signal(2)
    assert p.wait(5) == 0
    text = log.read_text()
    assert '"event": "stopped"' in text
    assert "Traceback" not in text


def test_daemon_keeps_only_cap_net_raw_and_switches_user(
    daemon_factory: object, master_factory: object
) -> None:

    d = daemon_factory("--user", "nobody")  # type: ignore[operator]
    time.sleep(0.2)  # the daemon drops privileges right after "ready"
    st = proc_status(d.pid)  # `ip netns exec` execs the daemon: same pid
    assert st["Uid"].split()[0] == "65534"
    assert int(st["CapEff"], 16) == 1 << 13  # CAP_NET_RAW only
    assert int(st["CapPrm"], 16) == 1 << 13
    assert int(st["CapBnd"], 16) == 1 << 13
    m = master_factory()  # type: ignore[operator]
    assert m.config_init() == 1  # still serving frames
    assert d.alive()


def test_default_control_socket_under_the_run_directory(
    daemon_factory: Any, tmp_path: Path
) -> None:
    """Without --ctl the daemon serves /run/ecatsim/LINK.sock (directory 0700, socket 0600);
    `ecatsim ctl --link LINK status` finds it; a second daemon on the same link is refused
    with one line; the socket is removed on exit."""
    import json
    import stat

    d = daemon_factory()
    sock = Path("/run/ecatsim") / f"{d.pair.slave_if}.sock"
    assert stat.S_IMODE(sock.stat().st_mode) == 0o600
    assert stat.S_IMODE(sock.parent.stat().st_mode) == 0o700
    r = ecatsim("ctl", "--link", d.pair.slave_if, "--json", "status")
    assert r.returncode == 0, r.stderr
    status = json.loads(r.stdout)
    assert status["ok"] and status["slaves"][0]["al_status"] == 0x01 and status["faults"] == []
    # the only daemon in the run directory (ECATSIM_RUN_DIR: one that holds only this
    # daemon's socket, whatever else runs on the host): found without --link, as a table
    alone = tmp_path / "run"
    alone.mkdir()
    (alone / sock.name).symlink_to(sock)
    r = ecatsim("ctl", "status", env={"ECATSIM_RUN_DIR": str(alone)})
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[1].split()[:5] == ["0", "0x0000", "INIT", "0x0000", "no"]
    # a missing object: the SDO abort within 1 s, and exit status 1 from the command line
    from ecatsim.ctl.server import request

    req = {"cmd": "od", "slave": 0, "index": 0x9999, "sub": 0}
    assert request(sock, req, timeout=1.0)["abort"] == 0x06020000
    r = ecatsim("ctl", "od", "0", "0x9999", "0", env={"ECATSIM_RUN_DIR": str(alone)})
    assert (r.returncode, r.stderr) == (
        1,
        "ecatsim: error: ctl od: 0x06020000 object does not exist\n",
    )
    # a second daemon on the link is refused, with its own control socket too (decision O1)
    assert d.proc is not None
    for extra in ([], ["--ctl", str(tmp_path / "second.sock")]):
        r = ecatsim("run", "--iface", d.pair.slave_if, *extra, ns=d.pair.slave_ns)
        line = one_error_line(r)
        assert line == (
            f"ecatsim: error: --iface {d.pair.slave_if}: ecatsim PID {d.proc.pid} serves this "
            "link already; two daemons on one link would both answer every frame: stop that "
            f"one first (kill {d.proc.pid})"
        )
        assert r.stdout == ""
    assert not (tmp_path / "second.sock").exists()
    assert d.alive()
    d.stop()
    assert not sock.exists()


def _open_files(pid: int) -> list[str]:
    fds = Path(f"/proc/{pid}/fd")
    return [os.readlink(fds / n) for n in os.listdir(fds)]


def test_a_realtime_daemon_holds_the_cpus_out_of_their_idle_states(daemon_factory: Any) -> None:
    """K12: while the real-time daemon serves it holds /dev/cpu_dma_latency open with a
    request of 0 us (the kernel's aggregate reads back 0); with --no-hold-cpu-latency it
    does not, and a stopped daemon gives the request back."""
    assert Path("/dev/cpu_dma_latency").exists(), "the kernel's PM QoS device is missing"
    d = daemon_factory()
    assert "/dev/cpu_dma_latency" in _open_files(d.pid)
    with open("/dev/cpu_dma_latency", "rb") as f:
        assert struct.unpack("=i", f.read(4))[0] == 0
    assert '"cpu_latency_held"' in d.log.read_text()
    assert d.stop() == 0
    d2 = daemon_factory("--no-hold-cpu-latency")
    assert "/dev/cpu_dma_latency" not in _open_files(d2.pid)
    assert "cpu_latency" not in d2.log.read_text()

"""First use without surprises: each bad input through the real entry point gives exit
status != 0, one line naming the option or file and the fix, no traceback and no file.

Ref: issue "first use and operations without surprises"; docs/decisions.md O1-O4.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from ecatsim.device.trace import TraceWriter

ROOT = Path(__file__).resolve().parents[2]


def ecatsim(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "ecatsim", *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
        env={**os.environ, **(env or {})},
    )


def one_line(r: subprocess.CompletedProcess[str], status: int = 2) -> str:
    """The only line of stderr, after checking the exit status and that nothing else came."""
    assert r.returncode == status, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1, r.stderr
    assert r.stdout == ""
    return lines[0]


def files(d: Path) -> list[str]:
    return sorted(str(p.relative_to(d)) for p in d.rglob("*"))


@pytest.fixture
def trace(tmp_path: Path) -> Path:
    path = tmp_path / "t.csv"
    w = TraceWriter(path)
    for i in range(3):
        w.row(i * 1_000_000, 0, (0x0F, 0x237, 8, "OPERATION_ENABLED", i, i, 0, 0, 0, 0))
    w.close()
    return path


def test_output_in_a_missing_directory_is_one_line_and_no_file(tmp_path: Path, trace: Path) -> None:
    """eeprom build, esi export and plot with -o in a directory that does not exist."""
    esi = tmp_path / "d.xml"
    assert ecatsim("esi", "export", "-o", str(esi)).returncode == 0
    before = files(tmp_path)
    missing = tmp_path / "nonexistent" / "dir"
    fix = "does not exist: create it first or write elsewhere"
    for args, out in (
        (["eeprom", "build", str(esi)], missing / "x.bin"),
        (["esi", "export"], missing / "x.xml"),
        (["plot", str(trace)], missing / "x.png"),
    ):
        line = one_line(ecatsim(*args, "-o", str(out)))
        assert line == f"ecatsim: error: -o {out}: the directory {out.parent} {fix}", args
    assert files(tmp_path) == before


def test_plot_to_an_unknown_format_leaves_no_file(tmp_path: Path, trace: Path) -> None:
    out = tmp_path / "p.xyz"
    line = one_line(ecatsim("plot", str(trace), "-o", str(out)))
    assert line.startswith(f"ecatsim: error: -o {out}: Format 'xyz' is not supported")
    assert not out.exists()


def test_eeprom_build_option_errors_name_the_option(tmp_path: Path) -> None:
    esi = tmp_path / "d.xml"
    assert ecatsim("esi", "export", "-o", str(esi)).returncode == 0
    out = tmp_path / "x.bin"
    line = one_line(ecatsim("eeprom", "build", str(esi), "-o", str(out), "--revision", "zz"))
    assert line == (
        "ecatsim: error: --revision zz: not a number; give it as in the ESI, e.g. 65536 or 0x10000"
    )
    line = one_line(ecatsim("eeprom", "build", str(esi), "-o", str(out), "--product", "1234"))
    assert line == (
        f"ecatsim: error: {esi}: no device matches --product 1234 (0x4d2); it has: "
        "--product 0x21de --revision 0x10000"
    )
    assert not out.exists()


def test_esi_export_of_an_xml_description_names_the_option(tmp_path: Path) -> None:
    bad = tmp_path / "bad.xml"
    bad.write_text('<?xml version="1.0"?><EtherCATInfo/>\n')
    out = tmp_path / "x.xml"
    line = one_line(ecatsim("esi", "export", "--description", str(bad), "-o", str(out)))
    assert line == (
        "ecatsim: error: --description bad.xml: not a device description: an XML file (an "
        "ESI? 'ecatsim eeprom build' reads those); expected a YAML mapping with device:, "
        "identity:, ... as in config/tmc8670.yaml"
    )
    assert not out.exists()


def test_a_truncated_eeprom_image_is_refused_at_start(tmp_path: Path) -> None:
    """A 50-byte image is refused before the link opens, naming the file and what is
    wrong; the file is left as it was."""
    image = tmp_path / "trunc.bin"
    image.write_bytes(bytes(range(50)))
    cfg = tmp_path / "seg.yaml"
    cfg.write_text(f"slaves:\n  - device: tmc8670\n    eeprom: {image}\n")
    env = {"ECATSIM_RUN_DIR": str(tmp_path / "run"), "ECATSIM_PURE_PYTHON": "1"}
    r = ecatsim("run", "--udp", "127.0.0.1:0", "--config", str(cfg), "--no-rt", env=env)
    line = one_line(r)
    assert line == (
        f"ecatsim: error: {image}: not an SII EEPROM image: image too short: 50 bytes, the "
        "header alone is 128; rebuild it with 'ecatsim eeprom build', or remove it and a new "
        "one is made"
    )
    assert image.read_bytes() == bytes(range(50))


def test_a_missing_eeprom_image_is_still_created(tmp_path: Path) -> None:
    from ecatsim.clock import ManualClock
    from ecatsim.ethercat.assembly import build_segment
    from ecatsim.ethercat.segment_file import load_segment
    from ecatsim.sii.image import parse_image

    image = tmp_path / "new.bin"
    cfg = tmp_path / "seg.yaml"
    cfg.write_text(f"slaves:\n  - device: tmc8670\n    eeprom: {image}\n")
    build_segment(load_segment(cfg), ManualClock())
    assert parse_image(image.read_bytes()).product_code == 8670


def free_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = int(s.getsockname()[1])
    s.close()
    return port


def test_tmcl_demo_without_a_server_says_how_to_start_one(tmp_path: Path) -> None:
    port = free_port()
    out = tmp_path / "demo.png"
    r = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "tmcl_demo.py"), "--connect",
         f"127.0.0.1:{port}", "-o", str(out)],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert one_line(r, 1) == (
        f"tmcl_demo: no TMCL module at 127.0.0.1:{port} (Connection refused): start one "
        f"first with '.venv/bin/ecatsim tmcl --listen tcp://127.0.0.1:{port}'"
    )
    assert not out.exists()


def wait_for(path: Path, proc: subprocess.Popen[str], timeout: float = 30.0) -> None:
    import time

    end = time.monotonic() + timeout
    while not path.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < end, f"{path} did not appear"
        time.sleep(0.05)


def test_ctl_of_a_tmcl_daemon_beside_an_ethercat_one(tmp_path: Path) -> None:
    """`ctl door tmcl help` reaches the one daemon serving a TMCL door without --link, with
    an EtherCAT daemon running beside it; `ctl status` of the TMCL daemon is a table of its
    modules, no EtherCAT table and no raw dict (decision O5)."""
    run = tmp_path / "run"
    env = {**os.environ, "ECATSIM_RUN_DIR": str(run), "ECATSIM_PURE_PYTHON": "1"}
    daemons = [
        subprocess.Popen(
            [sys.executable, "-m", "ecatsim", *args],
            cwd=ROOT,
            env=env,
            text=True,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
        )
        for args in (
            ["tmcl", "--listen", "tcp://127.0.0.1:0", "--module-address", "3"],
            ["run", "--udp", "127.0.0.1:0", "--no-rt"],
        )
    ]
    try:
        wait_for(run / "tmcl.sock", daemons[0])
        wait_for(run / "127.0.0.1_0.sock", daemons[1])
        r = ecatsim("ctl", "door", "tmcl", "help", env=env)
        assert r.returncode == 0, r.stderr
        assert "fault" in r.stdout
        r = ecatsim("ctl", "status", env=env)  # two daemons: say which
        assert one_line(r) == (
            "ecatsim: error: ctl: several daemons are running (127.0.0.1_0, tmcl); say which "
            "with --link NAME"
        )
        r = ecatsim("ctl", "door", "lin", "nodes", env=env)
        assert one_line(r) == (
            "ecatsim: error: ctl: none of the running daemons (127.0.0.1_0, tmcl) serves the "
            "door lin"
        )
        r = ecatsim("ctl", "--link", "tmcl", "status", env=env)
        assert r.returncode == 0, r.stderr
        lines = r.stdout.splitlines()
        assert lines[0].startswith("tmcl: listen tcp://127.0.0.1:")
        assert lines[0].endswith(", clients 0, frames 0, bad checksums 0")
        assert lines[1].split("  ")[:3] == ["", "address", "mode"]
        assert lines[2].split()[:3] == ["3", "position", "no"]
        assert len(lines) == 3
        assert "{" not in r.stdout and "station" not in r.stdout
    finally:
        for d in daemons:
            d.terminate()
            d.wait(10)


def test_ctl_status_of_a_lin_only_daemon_is_a_table_of_its_nodes(tmp_path: Path) -> None:
    from ecatsim.ctl.server import ControlSocket
    from ecatsim.ctl.table import format_status
    from ecatsim.doors.host import DoorHost
    from ecatsim.lin.server import door_from_config

    door = door_from_config(
        {"pty": "lin0", "nodes": [{"name": "left"}, {"name": "right", "hw": [1, 0, 0]}]},
        "seg.yaml",
        tmp_path,
    )
    host = DoorHost({"lin": door})
    ctl = ControlSocket(tmp_path / "ctl.sock", None, None, host)
    try:
        lines = format_status(ctl.status()).splitlines()
    finally:
        ctl.close()
        host.close()
    assert lines[0] == (
        f"lin: pty {tmp_path / 'lin0'}, frames 0, errors bit 0 header 0 data 0 timeout 0, "
        "timeouts 0"
    )
    assert lines[1].split() == [
        "name", "address", "state", "actpos", "tagpos", "current", "ma", "flags"
    ]  # fmt: skip
    nodes = [ln.split()[:3] for ln in lines[2:]]
    assert nodes == [["left", "0", "ShutDown"], ["right", "64", "ShutDown"]]
    assert "{" not in "\n".join(lines)


def test_a_control_socket_in_use_does_not_invite_a_second_daemon(tmp_path: Path) -> None:
    """The refusal names the socket and how to see who serves it; it offers --ctl only for
    a daemon that serves something else (the link itself is locked: decision O1)."""
    from ecatsim.ctl.server import ControlSocket
    from ecatsim.errors import UserError

    path = tmp_path / "ecat1.sock"
    live = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    live.bind(str(path))
    try:
        with pytest.raises(UserError) as exc:
            ControlSocket(path, None, None)
    finally:
        live.close()
    assert str(exc.value) == (
        f"{path}: a running daemon answers on this control socket (see it with 'ecatsim ctl "
        f"--socket {path} status'); stop it first, or give this daemon another socket with "
        "--ctl PATH if it serves something else"
    )

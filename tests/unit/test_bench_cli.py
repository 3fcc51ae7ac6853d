"""``ecatsim bench`` is a click command with help for every option, shipped whole in the
package (no import of tools/ or tests/, its C floor as package data, pysoem optional);
the daemon's reply times pair up."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import tomllib
from importlib import resources
from pathlib import Path

from click.testing import CliRunner

import ecatsim
from ecatsim.bench.capture import Capture, Frame, percentile, reply_stats
from ecatsim.bench.cli import NO_PYSOEM, bench
from ecatsim.bench.floor import SOURCE, c_source, echo_source
from ecatsim.bench.master import wkc_seen_text
from ecatsim.bench.roundtrip import repeated
from ecatsim.cli import cli
from ecatsim.wire import datagram as dg

PACKAGE = Path(ecatsim.__file__).parent
ROOT = PACKAGE.parent
BENCH_MODULES = sorted(f"ecatsim.bench.{p.stem}" for p in (PACKAGE / "bench").glob("*.py"))


def test_every_option_has_help() -> None:
    missing = [p.name for p in bench.params if not getattr(p, "help", None)]
    assert missing == []
    r = CliRunner().invoke(cli, ["bench", "--help"])
    assert r.exit_code == 0
    assert r.output.startswith("Usage: cli bench [OPTIONS]")
    assert "p99.99" in r.output
    for option in ("--bringup", "--cycles", "--overlap", "--repeat", "--results", "--master-rt",
                   "--master", "--sync0"):  # fmt: skip
        assert option in r.output


def frame(t_ns: int, idx: int, reply: bool) -> Frame:
    return Frame(t_ns, reply, idx, 12, 0, 0, 2, b"")


def test_reply_times_pair_requests_and_replies_by_index() -> None:
    # two requests in flight, one reply lost, one stray reply
    frames = [
        frame(1_000, 7, False),
        frame(1_500, 8, False),
        frame(21_000, 7, True),
        frame(41_500, 8, True),
        frame(50_000, 9, False),
        frame(60_000, 3, True),
    ]
    st = reply_stats(frames)
    assert (st["frames"], st["unpaired"], st["median"], st["max"]) == (2, 2, 20.0, 40.0)


def test_a_capture_parses_what_its_taps_read() -> None:
    """The taps keep (kernel time, direction, bytes); the frames are parsed afterwards,
    EtherCAT only, a reply told by the end it was seen on, not by the source MAC (KickCAT
    sets bit 1 in its own requests)."""
    request = bytearray(
        dg.ethernet_frame([dg.build(dg.Cmd.FPRD, 0x1001, 0x0130, bytes(2), idx=0x21)])
    )
    request[6] |= 0x02
    cap = Capture.both_ends((None, "lo"), (None, "lo"))
    cap.raw = [(10_000, False, bytes(request)),
               (12_000, True, b"\x00" * 12 + b"\x08\x00" + bytes(40)),
               (35_000, True, bytes(request))]  # fmt: skip
    assert [(f.t_ns, f.reply, f.idx) for f in cap.frames()] == [(10_000, False, 0x21),
                                                                (35_000, True, 0x21)]  # fmt: skip
    st = cap.stats()
    assert (st["frames"], st["unpaired"], st["median"], st["max"]) == (1, 0, 25.0, 25.0)


def test_percentile_is_nearest_rank() -> None:
    us = [float(i) for i in range(1, 10001)]
    assert (percentile(us, 0.5), percentile(us, 0.9999), percentile(us, 1.0)) == (
        5000.0,
        9999.0,
        10000.0,
    )


def test_repeated_runs_report_the_median_ratio_per_size() -> None:
    def run(n: int, ratio: float, rtt: float) -> dict[str, object]:
        return {"mode": "blocking", "placement": "same-cpu", "slaves": n,
                "ratio_median": ratio, "rtt_us": {"median": rtt},
                "floor_rtt_us": {"median": 10.0}, "cpu_percent": 5.0}  # fmt: skip

    runs = [run(1, 1.9, 19.0), run(1, 1.1, 11.0), run(1, 1.4, 14.0), run(16, 3.0, 30.0)]
    rows = repeated(runs)
    assert [(r["slaves"], r["runs"]) for r in rows] == [(1, 3), (16, 1)]
    one = rows[0]
    assert (one["ratio_median"], one["ratio_min"], one["ratio_max"]) == (1.4, 1.1, 1.9)
    assert (one["rtt_median_us"], one["floor_median_us"]) == (14.0, 10.0)


def test_wkc_mismatches_are_named_with_their_wkc_and_time() -> None:
    run = {"expected_wkc": 192, "wkc_error_seen": [(96, 6387), (0, 2100)]}
    assert wkc_seen_text(run) == " wkc seen 96/192 after 6387 us wkc seen 0/192 after 2100 us"
    assert wkc_seen_text({"expected_wkc": 3, "wkc_error_seen": []}) == ""


def _imports(path: Path) -> set[str]:
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
    return out


def test_no_module_of_the_package_imports_tools_or_tests() -> None:
    """A wheel holds ecatsim/ only: nothing in it may reach into tools/ or tests/ (by
    import or by a path added to sys.path)."""
    offenders = []
    for f in sorted(PACKAGE.rglob("*.py")):
        text = f.read_text()
        for mod in _imports(f):
            if mod.split(".")[0] in ("tests", "tools"):
                offenders.append(f"{f.relative_to(ROOT)} imports {mod}")
        if "sys.path" in text or '"tools"' in text:
            offenders.append(f"{f.relative_to(ROOT)} changes sys.path or names tools/")
    assert offenders == []


def test_the_bench_imports_with_tools_and_tests_out_of_reach(tmp_path: Path) -> None:
    """In a fresh interpreter run from elsewhere, with ``tests`` unimportable and neither
    the source tree's root nor tools/ on sys.path, every bench module imports and
    ``ecatsim bench --help`` runs."""
    code = (
        "import sys\n"
        "sys.modules['tests'] = None\n"
        f"root = {str(ROOT)!r}\n"
        "sys.path[:] = [p for p in sys.path if p not in ('', '.', root, root + '/tools')]\n"
        "import importlib\n"
        f"for m in {BENCH_MODULES!r}:\n"
        "    importlib.import_module(m)\n"
        "assert not any(m == 'tests' or m.startswith(('tests.', 'tools')) for m in sys.modules"
        " if sys.modules[m] is not None)\n"
        "from ecatsim.cli import main\n"
        "sys.argv = ['ecatsim', 'bench', '--help']\n"
        "main()\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                       text=True, timeout=60)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "--bringup" in r.stdout


def test_the_c_floor_is_package_data() -> None:
    """The floor's C source (and the host probe's and the stall watch's) is read from the
    installed package, and pyproject.toml lists it as package data, so a wheel carries it."""
    src = resources.files("ecatsim.bench").joinpath(SOURCE)
    assert src.is_file()
    assert echo_source() == src.read_text()
    assert "socket(AF_PACKET, SOCK_RAW, htons(0x88A4))" in echo_source()
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "ecatsim.bench" in conf["tool"]["setuptools"]["packages"]
    data = conf["tool"]["setuptools"]["package-data"]["ecatsim.bench"]
    assert data == [SOURCE, "steadiness.c", "stallwatch.c"]
    assert "sched_setscheduler(0, SCHED_FIFO" in c_source("steadiness.c")
    assert "clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME" in c_source("stallwatch.c")
    assert conf["project"]["optional-dependencies"]["bench"] == ["pysoem>=1.1.13"]


def test_without_pysoem_the_bench_says_so_in_one_line() -> None:
    code = (
        "import sys\n"
        "sys.modules['pysoem'] = None\n"
        "from ecatsim.cli import main\n"
        "sys.argv = ['ecatsim', 'bench', '--slaves', '1', '--seconds', '1']\n"
        "main()\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=60)  # fmt: skip
    assert (r.returncode, r.stdout) == (2, "")
    assert r.stderr == f"ecatsim: error: {NO_PYSOEM}\n"
    assert NO_PYSOEM == "ecatsim bench needs pysoem: pip install 'ecatsim[bench]'"


def test_the_bringup_master_runs_real_time_on_its_cpu_and_is_restored() -> None:
    """``--master-rt``/``--master-cpu``: SCHED_FIFO and one CPU for the master's thread
    during the bring-up and the cycles, the thread's own scheduling again afterwards."""
    from ecatsim.bench.bringup import master_scheduling

    cpu = min(os.sched_getaffinity(0))
    before = (os.sched_getscheduler(0), os.sched_getaffinity(0))
    with master_scheduling(30, cpu) as said:
        assert said == f"SCHED_FIFO 30, CPU {cpu}"
        assert os.sched_getscheduler(0) == os.SCHED_FIFO
        assert os.sched_getparam(0).sched_priority == 30
        assert os.sched_getaffinity(0) == {cpu}
    assert (os.sched_getscheduler(0), os.sched_getaffinity(0)) == before
    with master_scheduling(None, None) as said:
        assert said == "ordinary, unpinned"


def test_the_soem_master_options_go_with_bringup_and_soem() -> None:
    from ecatsim.errors import UserError

    cases = [(["--master", "soem"], "add --bringup N"),
             (["--bringup", "2", "--sync0"], "--sync0 is for --master soem"),
             (["--restart"], "--restart is for --bringup N"),
             (["--bringup", "2", "--master", "soem", "--restart"],
              "with the pysoem master")]  # fmt: skip
    for args, text in cases:
        r = CliRunner().invoke(cli, ["bench", *args])
        assert isinstance(r.exception, UserError) and text in str(r.exception), r.output

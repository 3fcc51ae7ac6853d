"""SOEM's own tools, built from pysoem's source distribution, against the daemon over a
veth pair: eepromtool reads a slave's whole SII EEPROM, writes it back changed and sets its
alias; slaveinfo finds the slaves, brings them to SAFEOP and lists their PDO mapping from
CoE and their object dictionary through SDO information; simple_test brings a drive and an
MFCIO slave to OP and runs cycles of process data; firm_update writes a file over FoE in
BOOT. Each test runs its own daemon of two slaves. Tests of function, not of time: the
tools wait 50 ms for a frame (decision K11).
Ref: ETG.1000.6 §5.4 (SII), §5.8 (FoE); ETG.2010 (SII header and categories); TMC8460
§5.45-5.46."""

from __future__ import annotations

import re
import subprocess
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest

from ecatsim.sii.crc import crc8
from ecatsim.sii.image import parse_image
from tests.integration.netns import NetnsPair
from tests.integration.test_esc_master import PRODUCT, REVISION, VENDOR

pytestmark = pytest.mark.integration

TIMEOUT_S = 120
ROOT = Path(__file__).resolve().parents[2]


def run_tool(pair: NetnsPair, exe: Path, *args: str, cwd: Path | None = None) -> str:
    """A SOEM tool in the master's namespace on its end of the veth; its stdout."""
    cmd = ["ip", "netns", "exec", pair.master_ns, str(exe), pair.master_if, *args]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT_S, check=False, cwd=cwd)
    assert r.returncode == 0, r.stdout + r.stderr
    return r.stdout


def test_eepromtool_reads_writes_and_sets_the_alias(
    netns_pair: NetnsPair, daemon_factory: Any, tmp_path: Path
) -> None:
    from tests.support.soem_build import functional_sample

    exe = functional_sample("eepromtool")
    daemon_factory("--slaves", "2")
    image = tmp_path / "slave2.bin"
    out = run_tool(netns_pair, exe, "2", "-r", str(image))
    assert "2 slaves found." in out, out
    assert f" Vendor ID        : {VENDOR:08X}\n" in out, out
    assert f" Product Code     : {PRODUCT:08X}\n" in out, out
    assert f" Revision Number  : {REVISION:08X}\n" in out, out
    data = image.read_bytes()
    sii = parse_image(data)  # the whole image, as eepromtool read it: a valid SII
    assert sii.crc_ok and (sii.vendor_id, sii.product_code) == (VENDOR, PRODUCT)
    assert len(data) == sii.size_kbit * 128
    assert sii.name.startswith("TMC8670"), sii.name

    # the image written back with another alias and its checksum, then read again
    changed = bytearray(data)
    changed[8:10] = (0x0BEE).to_bytes(2, "little")
    changed[14] = crc8(bytes(changed[0:14]))
    (tmp_path / "changed.bin").write_bytes(changed)
    run_tool(netns_pair, exe, "2", "-w", str(tmp_path / "changed.bin"))
    run_tool(netns_pair, exe, "2", "-r", str(tmp_path / "again.bin"))
    assert (tmp_path / "again.bin").read_bytes() == bytes(changed)

    # eepromtool's own alias command: word 4 and the checksum, nothing else
    out = run_tool(netns_pair, exe, "2", "-walias", "4660")
    assert "Alias 1234 written successfully to slave 2" in out, out
    out = run_tool(netns_pair, exe, "2", "-i")
    assert " Config Alias     : 1234\n" in out, out
    crc = crc8(bytes(changed[0:8]) + b"\x34\x12" + bytes(changed[10:14]))
    assert f" Checksum         : {crc:04X}\n   calculated     : {crc:04X}\n" in out, out
    out = run_tool(netns_pair, exe, "1", "-i")  # the other slave's EEPROM is its own
    assert " Config Alias     : 0000\n" in out, out


def test_slaveinfo_finds_the_slaves_and_lists_their_pdo_mapping(
    netns_pair: NetnsPair, daemon_factory: Any
) -> None:
    from tests.support.soem_build import functional_sample

    exe = functional_sample("slaveinfo")
    daemon_factory("--slaves", "2")
    out = run_tool(netns_pair, exe, "-map")
    assert "2 slaves found and configured." in out, out
    assert out.count(f"Man: {VENDOR:08x} ID: {PRODUCT:08x} Rev: {REVISION:08x}") == 2, out
    assert out.count(" Name:TMC8670\n Output size: 96bits\n Input size: 136bits\n State: 4\n") == 2
    # the SMs and FMMUs as SOEM configured them from the SII, slave 1's and slave 2's
    for line in (
        " SM0 A:1000 L: 128 F:00010026 Type:1",
        " SM1 A:1080 L: 128 F:00010022 Type:2",
        " SM2 A:1100 L:  12 F:00010064 Type:3",
        " SM3 A:1200 L:  17 F:00010020 Type:4",
        " MBX length wr: 128 rd: 128 MBX protocols : 0c",
        " CoE details: 2f FoE details: 01 EoE details: 00 SoE details: 00",
    ):
        assert out.count(line + "\n") == 2, (line, out)
    assert " FMMU0 Ls:00000000 Ll:  12 Lsb:0 Leb:7 Ps:1100 Psb:0 Ty:02 Act:01\n" in out, out
    assert " FMMU1 Ls:00000029 Ll:  17 Lsb:0 Leb:7 Ps:1200 Psb:0 Ty:01 Act:01\n" in out, out
    # slave 1's PDO mapping as SOEM reads it over CoE (1C12h/1C13h, 16xxh/1Axxh) with each
    # entry's name and type from the SDO information service (default PDOs, decision C1)
    assert (
        "PDO mapping according to CoE :\n"
        "  SM2 outputs\n"
        "     addr b   index: sub bitl data_type    name\n"
        "  [0x0000.0] 0x6040:0x00 0x10 UNSIGNED16   Controlword\n"
        "  [0x0002.0] 0x607A:0x00 0x20 INTEGER32    Target position\n"
        "  [0x0006.0] 0x6071:0x00 0x10 INTEGER32    Target torque\n"
        "  [0x0008.0] 0x60FF:0x00 0x20 INTEGER32    Target velocity\n"
        "  SM3 inputs\n"
        "     addr b   index: sub bitl data_type    name\n"
        "  [0x0018.0] 0x6041:0x00 0x10 UNSIGNED16   Statusword\n"
        "  [0x001A.0] 0x6061:0x00 0x08 INTEGER8     Modes of operation display\n"
        "  [0x001B.0] 0x6064:0x00 0x20 INTEGER32    Position actual value\n"
        "  [0x001F.0] 0x6077:0x00 0x10 INTEGER32    Torque actual value\n"
        "  [0x0021.0] 0x606C:0x00 0x20 INTEGER32    Velocity actual value\n"
        "  [0x0025.0] 0x60FD:0x00 0x20 UNSIGNED32   Digital inputs\n"
    ) in out, out
    assert out.endswith("End slaveinfo, close socket\nEnd program\n"), out

    # -sdo: the object dictionary through SDO information (the list, each object's and
    # entry's description) and every value by SDO upload
    out = run_tool(netns_pair, exe, "-sdo")
    assert out.count(" CoE Object Description found, 67 entries.\n") == 2, out
    assert sum(line.startswith("0x") for line in out.splitlines()) == 2 * 67, out
    identity = (
        '0x1018      "Identity object"                             [RECORD  maxsub(0x03 / 3)]\n'
        '    0x00      "Number of entries"                           [UNSIGNED8        R_R_R_]'
        "      0x03 / 3\n"
        '    0x01      "Vendor ID"                                   [UNSIGNED32       R_R_R_]'
        f"      0x{VENDOR:08x} / {VENDOR}\n"
        '    0x02      "Product code"                                [UNSIGNED32       R_R_R_]'
        f"      0x{PRODUCT:08x} / {PRODUCT}\n"
        '    0x03      "Revision number"                             [UNSIGNED32       R_R_R_]'
        f"      0x{REVISION:08x} / {REVISION}\n"
    )
    assert out.count(identity) == 2, out
    name = (
        '    0x00      "Manufacturer device name"                    [VISIBLE_STR(56)  R_R_R_]'
        '      "TMC8670"\n'
    )
    assert out.count(name) == 2, out


#: simple_test's cycles, 5 ms apart (the sample's own 10 000 take 50 s)
SIMPLE_CYCLES = 200
#: one of simple_test's cycle lines (each ends in a carriage return, a newline in text mode)
CYCLE = re.compile(
    r"Processdata cycle +(?P<i>\d+), WKC (?P<wkc>\d+) , O:(?P<o>( [0-9a-f]{2})*)"
    r" I:(?P<i_>( [0-9a-f]{2})*) T:(?P<t>\d+)"
)


def test_simple_test_brings_a_drive_and_an_mfcio_slave_to_op(
    netns_pair: NetnsPair, daemon_factory: Any
) -> None:
    """SOEM's first sample, as a user runs it first: config_init, config_map, configdc,
    SAFEOP, OP, then cycles of process data at the calculated WKC, its check thread
    watching every cycle's WKC and every slave's state. The segment: a TMC8670 and,
    behind it, a TMC8460 MFCIO slave (config/tmc8460-beside-tmc8670.yaml)."""
    from tests.support.soem_build import FUNCTIONAL, build_sample

    cycles = ("simple_test.c", "i <= 10000;", f"i <= {SIMPLE_CYCLES};")
    exe = build_sample("simple_test", patches=(*FUNCTIONAL, cycles))
    daemon_factory("--config", str(ROOT / "config/tmc8460-beside-tmc8670.yaml"))
    out = run_tool(netns_pair, exe)
    assert "2 slaves found and configured.\n" in out, out
    # one LRW segment: the drive's 12 + 17 bytes and the MFCIO slave's 132
    assert "segments : 1 : 161 0 0 0\n" in out, out
    assert "Calculated workcounter 6\n" in out, out  # 2 x 2 output WKC + 2 input WKC
    assert "Operational state reached for all slaves.\n" in out, out
    seen = [CYCLE.fullmatch(c) for c in out.splitlines() if c.startswith("Processdata")]
    assert [m and int(m["i"]) for m in seen] == list(range(1, SIMPLE_CYCLES + 1)), out
    for m in seen:
        assert m is not None
        # the outputs as simple_test leaves them (zero); the inputs' first 8 bytes, the
        # drive's: statusword 0240h (switch on disabled, remote), mode display 0, position 0
        assert (m["wkc"], m["o"], m["i_"]) == ("6", " 00" * 8, " 40 02" + " 00" * 6), m[0]
    # the reference clock's system time (the FRMW in each cycle's frame), 5 ms of sleep
    # or more between two cycles (at most 1 s: a wide guard)
    times = [int(m["t"]) for m in seen if m is not None]
    assert all(5_000_000 <= b - a < 1_000_000_000 for a, b in pairwise(times)), times
    for alarm in ("ERROR", "WARNING", "MESSAGE", "OK : all slaves resumed", "Not all slaves"):
        assert alarm not in out, out
    assert out.endswith("Request init state for all slaves\nEnd simple test, close socket\n"
                        "End program\n"), out  # fmt: skip


def test_firm_update_writes_a_file_over_foe_in_boot(
    netns_pair: NetnsPair, daemon_factory: Any, tmp_path: Path
) -> None:
    """SOEM's firmware update sample: slave 2 to INIT, its SM0/SM1 set to the bootstrap
    mailbox read from its SII, BOOT, the file written over FoE, INIT again. The file lands
    whole in the slave's FoE directory; slave 1 is left alone.
    Ref: ETG.1000.6 §5.8 (FoE); TMC8670 §2.3 (firmware update in bootstrap)."""
    from tests.support.soem_build import functional_sample

    exe = functional_sample("firm_update")
    fw = tmp_path / "fw"
    cfg = tmp_path / "segment.yaml"
    cfg.write_text(f"slaves:\n  - device: tmc8670\n    count: 2\n    foe_dir: {fw}\n")
    daemon_factory("--config", str(cfg))
    image = bytes(range(256)) * 40 + b"end"  # 10243 bytes: many mailbox fragments
    (tmp_path / "app.bin").write_bytes(image)
    out = run_tool(netns_pair, exe, "2", "app.bin", cwd=tmp_path)
    assert "2 slaves found and configured.\n" in out, out
    assert "Slave 2 state to INIT.\n" in out, out
    # the bootstrap mailbox from the SII (words 0x14-0x17), the flags SOEM set for SM0/SM1
    assert " SM0 A:1000 L: 128 F:00010026\n SM1 A:1080 L: 128 F:00010022\n" in out, out
    assert "Slave 2 state to BOOT.\n" in out, out
    assert f"File read OK, {len(image)} bytes.\nFoE write....result 1.\n" in out, out
    assert out.endswith("End firmware update example, close socket\nEnd program\n"), out
    assert (fw / "slave1" / "app.bin").read_bytes() == image
    assert not (fw / "slave0").exists() or not any((fw / "slave0").iterdir())

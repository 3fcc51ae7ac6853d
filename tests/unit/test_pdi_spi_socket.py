"""The PDI socket: framing, one client at a time, the IRQ line, bad clients."""

from __future__ import annotations

import os
import socket
import stat
import struct
from pathlib import Path

import pytest

from ecatsim.doors.from_config import build_doors
from ecatsim.doors.host import DoorHost
from ecatsim.errors import UserError
from ecatsim.ethercat.segment_file import SegmentConfig, SlaveConfig, parse_segment
from ecatsim.pdi_spi.external import ExternalFirmware
from tests.support.tinymaster import TinyMaster, segment_of


def frame(mosi: bytes) -> bytes:
    return struct.pack("<H", len(mosi)) + mosi


def recv_exactly(c: socket.socket, n: int, host: DoorHost) -> bytes:
    out = b""
    c.settimeout(0.01)
    for _ in range(200):
        host.serve()
        try:
            out += c.recv(n - len(out))
        except TimeoutError:
            pass
        if len(out) == n:
            return out
    raise AssertionError(f"got {out!r}, wanted {n} bytes")


def setup(tmp_path: Path):  # type: ignore[no-untyped-def]
    path = tmp_path / "pdi.sock"
    seg, clock = segment_of(1, firmware="external", pdi_socket=path)
    cfg = SegmentConfig((SlaveConfig(device="echo"),))
    host = build_doors(cfg, seg)
    assert host is not None and list(host.doors) == ["pdi0"]
    return seg, clock, host, path


def test_frames_over_the_socket(tmp_path: Path) -> None:
    seg, _, host, path = setup(tmp_path)
    try:
        assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
        m = TinyMaster(seg)
        m.apwr(0, 0x0120, struct.pack("<H", 0x0008))
        c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        c.connect(str(path))
        # two frames in one write, the second split across two writes, and an empty one
        c.sendall(frame(b"\x00\x00") + frame(b"") + frame(b"\x09\x02\x00\xff")[:3])
        assert recv_exactly(c, 2, host) == b"\x01\x00"
        c.sendall(frame(b"\x09\x02\x00\xff")[3:])
        assert recv_exactly(c, 4, host) == b"\x01\x00\x08\x00"
        # a second client is refused while the first is connected
        d = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        d.connect(str(path))
        host.serve()
        d.settimeout(1)
        assert d.recv(1) == b""
        d.close()
        # the first goes away mid-frame: the half frame never happened; a new client works
        c.sendall(b"\x05\x00\x10\x06")
        host.serve()
        c.close()
        host.serve()
        e = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        e.connect(str(path))
        host.serve()
        e.sendall(frame(b"\x10\x06\x50\x4c\x48"))
        assert recv_exactly(e, 5, host) == bytes(5)
        assert m.aprd(0, 0x4200, 2).data == b"\x4c\x48"
        e.close()
        status = host.status()["pdi0"]
        assert status["frames"] == 4 and status["refused"] == 1
    finally:
        host.close()
    assert not path.exists()


def test_a_failing_transfer_is_answered_with_zeros_and_the_next_frames_are_served(
    tmp_path: Path,
) -> None:
    """A fault inside ecatsim while it serves one frame (here: the slave's transfer raises)
    answers that frame with zeros and counts it; the frames after it are served."""
    _seg, _, host, path = setup(tmp_path)
    door = host.doors["pdi0"]
    sock = door.socket
    real = sock._transfer
    calls: list[bytes] = []
    answers: list[bytes] = []

    def flaky(mosi: bytes) -> bytes:
        calls.append(mosi)
        if len(calls) == 1:
            raise RuntimeError("boom")
        answers.append(real(mosi))
        return answers[-1]

    sock._transfer = flaky
    try:
        c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        c.connect(str(path))
        host.serve()
        c.sendall(frame(b"\x09\x02\x00\xff") + frame(b"\x09\x02\x00\xff"))
        got = recv_exactly(c, 8, host)
        assert got[:4] == bytes(4)  # the failed frame
        assert len(calls) == 2 and got[4:] == answers[0]  # the next one served
        status = host.status()["pdi0"]
        assert status["frames"] == 2 and status["failures"] == 1
        c.close()
    finally:
        host.close()


def test_the_irq_line_rises_once_per_edge(tmp_path: Path) -> None:
    seg, _, host, path = setup(tmp_path)
    try:
        fw = seg.firmware[0]
        assert isinstance(fw, ExternalFirmware)
        irq = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        irq.connect(f"{path}.irq")
        host.serve()
        spi = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        spi.connect(str(path))
        host.serve()
        m = TinyMaster(seg)
        m.apwr(0, 0x0120, struct.pack("<H", 0x0002))  # AL control event, masked in
        m.apwr(0, 0x0120, struct.pack("<H", 0x0002))  # still high: no second rise
        irq.settimeout(0.5)
        assert irq.recv(16) == b"\x01"
        spi.sendall(frame(b"\x09\x02\x00\xff"))  # reading AL control lowers the line
        assert recv_exactly(spi, 4, host) == b"\x01\x00\x02\x00"
        m.apwr(0, 0x0120, struct.pack("<H", 0x0004))
        assert irq.recv(16) == b"\x01"
        irq.settimeout(0.05)
        try:
            extra = irq.recv(16)
        except TimeoutError:
            extra = b""
        assert extra == b""
    finally:
        host.close()


def test_a_stale_socket_file_is_replaced_and_other_files_are_not(tmp_path: Path) -> None:
    path = tmp_path / "pdi.sock"
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.bind(str(path))
    s.close()
    seg, _ = segment_of(1, firmware="external", pdi_socket=path)
    seg.firmware[0].close()  # type: ignore[attr-defined]
    path.write_text("not a socket")
    with pytest.raises(UserError, match=r"slaves\[0\]\.pdi_socket: cannot create the socket"):
        segment_of(1, firmware="external", pdi_socket=path)


@pytest.mark.parametrize(
    ("slave", "message"),
    [
        ({"firmware": "mcu"}, r"slaves\[0\]\.firmware: use one of: ecatsim, external, got 'mcu'"),
        ({"firmware": "external"}, r"slaves\[0\]\.pdi_socket: firmware: external and pdi_socket"),
        ({"pdi_socket": "x.sock"}, r"slaves\[0\]\.pdi_socket: firmware: external and pdi_socket"),
        (
            {"firmware": "external", "pdi_socket": "x.sock", "count": 2},
            r"slaves\[0\]\.pdi_socket: one PDI socket cannot serve count > 1 slaves",
        ),
        ({"pdi_emulation": "yes"}, r"slaves\[0\]\.pdi_emulation: expected true or false"),
    ],
)
def test_config_errors_name_the_key(slave: dict[str, object], message: str) -> None:
    with pytest.raises(UserError, match=r"^seg\.yaml: " + message):
        parse_segment({"slaves": [{"device": "echo", **slave}]}, "seg.yaml")


def test_config_paths_are_relative_to_the_file(tmp_path: Path) -> None:
    cfg = parse_segment(
        {"slaves": [{"firmware": "external", "pdi_socket": "fw.sock", "pdi_emulation": True}]},
        "seg.yaml",
        tmp_path,
    )
    s = cfg.slaves[0]
    assert (s.firmware, s.pdi_socket, s.pdi_emulation) == ("external", tmp_path / "fw.sock", True)

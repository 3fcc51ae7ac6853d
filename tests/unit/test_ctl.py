"""The control socket answers every request; ``ctl status`` reads as a table."""

from __future__ import annotations

import json
import socket
from collections.abc import Iterator
from pathlib import Path

import pytest

from ecatsim.clock import MonotonicClock
from ecatsim.ctl.server import ControlSocket, find_socket
from ecatsim.ctl.table import format_status, port_text
from ecatsim.errors import UserError
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.segment_file import default_segment
from ecatsim.faults.engine import FaultEngine


@pytest.fixture
def ctl(tmp_path: Path) -> Iterator[ControlSocket]:
    segment = build_segment(default_segment(), MonotonicClock())
    c = ControlSocket(tmp_path / "ctl.sock", segment, FaultEngine(segment))
    yield c
    c.close()


def ask(ctl: ControlSocket, **req: object) -> dict[str, object]:
    return ctl.answer(json.dumps(req).encode())


def test_od_of_a_missing_object_answers_the_sdo_abort(ctl: ControlSocket) -> None:
    assert ask(ctl, cmd="od", slave=0, index=0x9999, sub=0) == {
        "ok": False,
        "error": "0x06020000 object does not exist",
        "abort": 0x06020000,
    }
    assert ask(ctl, cmd="od", slave=0, index=0x6040, sub=7) == {
        "ok": False,
        "error": "0x06090011 subindex does not exist",
        "abort": 0x06090011,
    }
    assert ask(ctl, cmd="od", slave=0, index=0x6040, sub=0) == {"ok": True, "value": 0}


def test_peek_past_the_end_is_an_error(ctl: ControlSocket) -> None:
    assert ask(ctl, cmd="peek", slave=0, addr=0xFFFF, len=4) == {
        "ok": False,
        "error": "0xFFFF+4 runs past the end of the ESC address space (0x0000..0xFFFF)",
    }
    assert ask(ctl, cmd="peek", slave=0, addr=0xFFFC, len=4) == {"ok": True, "data": "00000000"}
    assert ask(ctl, cmd="peek", slave=0, addr=0, len=0)["ok"] is False
    assert ask(ctl, cmd="poke", slave=0, addr=0xFFFF, data="0000")["ok"] is False


def test_every_request_gets_an_answer(ctl: ControlSocket, monkeypatch: pytest.MonkeyPatch) -> None:
    assert ctl.answer(b"not json")["ok"] is False
    assert ctl.answer(b"[1, 2]")["ok"] is False
    assert ask(ctl, cmd="peek", slave=0) == {"ok": False, "error": "missing field 'addr'"}
    assert ask(ctl, cmd="peek", slave=5, addr=0, len=1) == {"ok": False, "error": "no slave 5"}

    def bug() -> dict[str, object]:
        raise RuntimeError("a bug")

    monkeypatch.setattr(ctl, "status", bug)
    assert ask(ctl, cmd="status") == {"ok": False, "error": "internal error: RuntimeError('a bug')"}


def test_the_socket_answers_a_missing_object_at_once(ctl: ControlSocket, tmp_path: Path) -> None:
    client = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    client.bind(str(tmp_path / "c.sock"))
    client.settimeout(1.0)
    try:
        req = {"cmd": "od", "slave": 0, "index": 0x9999, "sub": 0}
        client.sendto(json.dumps(req).encode(), str(ctl.path))
        ctl.serve()
        assert json.loads(client.recv(4096))["abort"] == 0x06020000
    finally:
        client.close()


def test_status_table(ctl: ControlSocket) -> None:
    st = ctl.status()
    assert format_status(st).splitlines() == [
        "slave  station  state  AL status code   port 0     port 1         errors"
        + "                                  wd expiries",
        "0      0x0000   INIT   0x0000 no error  link/open  nolink/closed  "
        + "rx 0/0+0/0 fwd 0+0 pu 0 pdi 0 lost 0+0  0",
        "frames 0, bad frames 0",
        "active faults: none",
    ]
    st["slaves"][0].update(al_status=0x14, al_status_code=0x001B, wd_expired=2)
    st["faults"] = [{"id": 3, "kind": "drop", "probability": 0.5}]
    assert format_status(st).splitlines()[1:4] == [
        "0      0x0000   SAFEOP+ERR  0x001B sync manager watchdog  link/open  nolink/closed  "
        + "rx 0/0+0/0 fwd 0+0 pu 0 pdi 0 lost 0+0  2 expired",
        "frames 0, bad frames 0",
        "active faults (1, fired 0):",
    ]


def test_port_text_reads_the_dl_status_bits() -> None:
    # Table 31: bit 4+p physical link, bit 8+2p loop closed
    assert port_text(0x0010 | 0x0100, 0) == "link/closed"
    assert port_text(0x0020, 1) == "link/open"
    assert port_text(0x0400, 1) == "nolink/closed"


def _serve(path: Path) -> socket.socket:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(str(path))
    return s


def test_find_socket_takes_the_one_live_daemon(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="no running daemon has a control socket"):
        find_socket(tmp_path)
    dead = _serve(tmp_path / "dead.sock")
    dead.close()  # its file stays behind: a stale socket
    a = _serve(tmp_path / "ecat1.sock")
    try:
        assert find_socket(tmp_path) == tmp_path / "ecat1.sock"
        b = _serve(tmp_path / "ecat3.sock")
        try:
            with pytest.raises(UserError, match=r"several daemons are running \(ecat1, ecat3\)"):
                find_socket(tmp_path)
        finally:
            b.close()
    finally:
        a.close()


@pytest.mark.parametrize("kind", ["al_refuse", "al_fall"])
def test_al_faults_on_a_slave_without_ecatsim_firmware_answer_one_line(
    tmp_path: Path, kind: str
) -> None:
    """A TMC8460 in device emulation has no firmware to refuse or leave a state."""
    from ecatsim.ethercat.segment_file import load_segment

    root = Path(__file__).resolve().parents[2]
    segment = build_segment(load_segment(root / "config" / "tmc8460-mfcio.yaml"), MonotonicClock())
    c = ControlSocket(tmp_path / "ctl.sock", segment, FaultEngine(segment))
    try:
        r = ask(c, cmd="inject", fault={"kind": kind, "slave": 0, "code": 0x1B})
        assert r["ok"] is False
        assert str(r["error"]).startswith(f"slave: slave 0 has no ecatsim firmware to {kind[3:]}")
    finally:
        c.close()


def test_a_refused_fault_is_not_left_armed(tmp_path: Path) -> None:
    """The refusal comes when the fault is armed, even one due later, and nothing stays."""
    from ecatsim.ethercat.segment_file import load_segment

    root = Path(__file__).resolve().parents[2]
    segment = build_segment(load_segment(root / "config" / "tmc8460-mfcio.yaml"), MonotonicClock())
    engine = FaultEngine(segment)
    c = ControlSocket(tmp_path / "ctl.sock", segment, engine)
    try:
        r = ask(c, cmd="inject", fault={"kind": "al_fall", "slave": 0, "code": 0x1B, "after_s": 5})
        assert r["ok"] is False
        r = ask(c, cmd="inject", fault={"kind": "mbx_drop", "slave": 0})
        assert r == {"ok": False, "error": "slave: slave 0 has no mailbox for mbx_drop"}
        assert engine.faults == []
    finally:
        c.close()

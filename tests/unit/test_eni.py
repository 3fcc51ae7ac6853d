"""A segment from an ENI (ETG.2100): model resolution (built-in, ESI folder, made from the
ENI), every CoE InitCmd of the ENI accepted, the made-up slaves brought to OP in process.

Ref: ETG.2100 (Config/Slave/Info, Mailbox/CoE/InitCmds); ETG.1000.6 §5.6.7.4.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import structlog
from click.testing import CliRunner

from ecatsim.cli import cli
from ecatsim.clock import ManualClock
from ecatsim.errors import UserError
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.eni import load_eni
from ecatsim.ethercat.segment_file import parse_segment
from ecatsim.generic.dictionary import num
from ecatsim.generic.minimaster import MiniMaster
from ecatsim.slave.al import AlState
from ecatsim.wire import datagram as dg
from tests.support.eni import coe_init_cmds
from tests.support.tinymaster import firmware_of

DATA = Path(__file__).resolve().parents[1] / "data"
PAIR = DATA / "eni" / "unknown-pair.xml"
MIXED = DATA / "eni" / "mixed.xml"


def test_models_in_order_built_in_esi_then_eni() -> None:
    slaves = load_eni(MIXED, DATA / "esi")
    assert [s.model for s in slaves] == [
        "built-in tmc8670",
        "ESI acme-io.xml (ACME-IO8)",
        "from the ENI",
    ]
    assert [s.name for s in slaves] == ["Drive 1 (TMC8670)", "Term 2 (ACME-IO8)", "Box 3 (BX-200)"]
    assert slaves[2].warnings == [
        "mixed.xml: <Slave> #3 (Box 3 (BX-200)): PDO 0x1605 is described nowhere: no entries"
    ]
    assert load_eni(MIXED)[1].model == "from the ENI"  # no ESI folder: made from the ENI


def test_eni_show_lists_every_slave() -> None:
    r = CliRunner().invoke(cli, ["eni", "show", str(MIXED), "--esi-dir", str(DATA / "esi")])
    assert r.exit_code == 0, r.output
    lines = [ln for ln in r.output.splitlines() if not ln.startswith("     warning")]
    assert len(lines) == 3 and lines[1].endswith("-> ESI acme-io.xml (ACME-IO8)")


def test_every_init_cmd_accepted_and_op() -> None:
    with structlog.testing.capture_logs() as logs:
        cfg = parse_segment({"eni": str(PAIR)}, "seg.yaml")
    assert [e["detail"] for e in logs if e["event"] == "eni_pdo_undescribed"] == [
        "unknown-pair.xml: <Slave> #2 (Box 2 (BX-200)): PDO 0x1605 is described nowhere: no entries"
    ]
    seg = build_segment(cfg, ManualClock(1_000_000_000))
    m = MiniMaster(seg)
    for s in ET.parse(PAIR).getroot().findall("Config/Slave"):  # the ESC register InitCmds
        for c in s.findall("InitCmds/InitCmd"):
            cmd, adp, ado = (num(c.findtext(t)) for t in ("Cmd", "Adp", "Ado"))
            data = bytes.fromhex(c.findtext("Data") or "")
            _reply, wkc = m.exchange(dg.build(dg.Cmd(cmd), adp, ado, data))
            assert wkc == 1, c.findtext("Comment")
    preop = int(AlState.PREOP)
    for i, cmds in enumerate(coe_init_cmds(PAIR)):
        fw = firmware_of(seg, i)
        assert fw.od is not None
        for index, sub, data, ca in cmds:
            if ca:
                fw.od.write_complete(index, sub, data, preop)
            else:
                fw.od.write(index, sub, data, preop)
        assert fw.od.value(0x1018, 1) == 0x00BEEF00
    assert m.to_op(0) == "OP, outputs 2 bytes, inputs 6 bytes"
    assert m.to_op(1) == "OP, outputs 0 bytes, inputs 3 bytes"
    fw1 = firmware_of(seg, 1)
    assert fw1.od is not None
    assert [fw1.od.value(0x8010, s) for s in range(3)] == [2, 1, 2]


def test_eni_and_slaves_exclude_each_other() -> None:
    with pytest.raises(UserError, match="give eni: or slaves:, not both"):
        parse_segment({"eni": str(PAIR), "slaves": [{"device": "echo"}]}, "seg.yaml")


def test_broken_eni_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.xml"
    bad.write_text("<EtherCATConfig><Config><Slave><Info><Name>x</Name></Info></Slave>")
    with pytest.raises(UserError, match="not a readable ENI file"):
        load_eni(bad)
    bad.write_text("<EtherCATConfig><Config><Slave><Info/></Slave></Config></EtherCATConfig>")
    with pytest.raises(UserError, match=r"bad.xml: <Slave> #1: missing <VendorId>"):
        load_eni(bad)


PROCESS_DATA_ENI = """<EtherCATConfig><Config><Slave>
  <Info><Name>Box PD</Name><VendorId>#x00BEEF00</VendorId><ProductCode>300</ProductCode>
    <RevisionNo>1</RevisionNo></Info>
  <ProcessData>
    <Sm2><Type>Outputs</Type><StartAddress>#x1200</StartAddress><ControlByte>#x64</ControlByte>
      <Enable>true</Enable><Pdo>#x1600</Pdo></Sm2>
    <Sm3><Type>Inputs</Type><StartAddress>#x1300</StartAddress><ControlByte>#x20</ControlByte>
      <Enable>true</Enable><Pdo>#x1A00</Pdo></Sm3>
    <RxPdo Sm="2" Fixed="true"><Index>#x1600</Index><Name>Out</Name>
      <Entry><Index>#x7000</Index><SubIndex>1</SubIndex><BitLen>16</BitLen><Name>Level</Name>
        <DataType>INT</DataType></Entry></RxPdo>
    <TxPdo Sm="3" Fixed="true"><Index>#x1A00</Index><Name>In</Name>
      <Entry><Index>#x6000</Index><SubIndex>1</SubIndex><BitLen>1</BitLen><Name>Ready</Name>
        <DataType>BOOL</DataType></Entry>
      <Entry><Index>0</Index><BitLen>7</BitLen></Entry>
      <Entry><Index>#x6000</Index><SubIndex>2</SubIndex><BitLen>32</BitLen><Name>Count</Name>
        <DataType>UDINT</DataType></Entry></TxPdo>
  </ProcessData>
</Slave></Config></EtherCATConfig>
"""


def test_process_data_of_the_eni_without_a_mailbox(tmp_path: Path) -> None:
    """<ProcessData> PDOs with data types and SM areas; no mailbox: device emulation."""
    eni = tmp_path / "pd.xml"
    eni.write_text(PROCESS_DATA_ENI)
    seg = build_segment(parse_segment({"eni": str(eni)}, "seg.yaml"), ManualClock(1_000_000_000))
    m = MiniMaster(seg)
    assert m.to_op(0) == "OP, outputs 2 bytes, inputs 5 bytes"
    app = seg.firmware[0].app  # type: ignore[attr-defined]
    from ecatsim.slave.pd import request as pd_request

    pd_request(app, {"entry": "Ready", "value": 1})
    pd_request(app, {"entry": "In/Count", "value": 7})
    m.lrw(0, b"\xfe\xff")
    m.lrw(0x8000, bytes(5))
    assert m.lrw(0x8000, bytes(5)) == (b"\x01\x07\x00\x00\x00", 1)
    assert pd_request(app, {"entry": "Level"})["value"] == -2
    assert app.od.entry(0x6000, 2).dtype == "UNSIGNED32"

"""What an ENI-driven master sends from an ENI (ETG.2100): its CoE InitCmds, per slave."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from ecatsim.generic.dictionary import num


def coe_init_cmds(
    eni: Path, transition: str | None = None
) -> list[list[tuple[int, int, bytes, bool]]]:
    """Per slave, the SDO downloads of its CoE InitCmds as (index, subindex, data, complete
    access), in order; ``transition`` (e.g. ``"PS"``): only that transition's."""
    out = []
    for s in ET.parse(eni).getroot().findall("Config/Slave"):
        out.append(
            [
                (
                    num(c.findtext("Index")),
                    num(c.findtext("SubIndex")),
                    bytes.fromhex(c.findtext("Data") or ""),
                    c.get("CompleteAccess") == "true",
                )
                for c in s.findall("Mailbox/CoE/InitCmds/InitCmd")
                if transition is None or c.findtext("Transition") == transition
            ]
        )
    return out

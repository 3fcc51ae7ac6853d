"""``ecatsim ctl door tmcl COMMAND ARGS``: look at the modules and inject faults.

Modules are named by their serial address (global parameter 66).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ecatsim.tmcl.commands import read_axis, read_global
from ecatsim.tmcl.params import AXIS, global_param

if TYPE_CHECKING:
    from ecatsim.tmcl.module import Module
    from ecatsim.tmcl.server import TmclDoor

HELP = {
    "status": "status: every module's position, mode, flags, faults",
    "gap": "gap ADDR N: read axis parameter N",
    "ggp": "ggp ADDR N BANK: read global parameter N of BANK",
    "fault": "fault ADDR KIND on|off: overtemperature, encoder_loss, undervoltage, short, stall",
    "switch": "switch ADDR left|right|home on|off|auto: force a switch or let the position say",
    "load": "load ADDR NM: the machine's load torque (Nm): resists motion, never drives it",
    "input": "input ADDR PORT 0|1: a digital input IN_0-IN_7",
    "analog": "analog ADDR 0|4 VALUE: an analog input AIN_0/AIN_4 (0-4095)",
}

FAULTS = ("overtemperature", "encoder_loss", "undervoltage", "short", "stall")


def _module(door: TmclDoor, text: str) -> Module:
    m = door.module(int(text, 0))
    if m is None:
        have = ", ".join(str(x.address) for x in door.modules)
        raise ValueError(f"no TMCL module at address {text} (modules at: {have})")
    return m


def _onoff(text: str) -> bool:
    if text not in ("on", "off", "1", "0"):
        raise ValueError(f"{text!r}: expected on or off")
    return text in ("on", "1")


def handle(door: TmclDoor, command: str, args: list[str]) -> dict[str, Any]:
    """One request; ValueError/IndexError become the control socket's error answer."""
    if command == "help":
        return {"commands": list(HELP.values())}
    if command == "status":
        return door.status()
    if command not in HELP:
        raise ValueError(f"unknown tmcl command {command!r} (door tmcl help)")
    try:
        m = _module(door, args[0])
        if command == "gap":
            n = int(args[1], 0)
            if n not in AXIS:
                raise ValueError(f"no axis parameter {n}")
            return {"value": read_axis(m, n)}
        if command == "ggp":
            n, bank = int(args[1], 0), int(args[2], 0)
            if global_param(bank, n) is None:
                raise ValueError(f"no global parameter {n} in bank {bank}")
            return {"value": read_global(m, bank, n)}
        ax = m.axis
        if command == "fault":
            kind = args[1]
            if kind not in FAULTS:
                raise ValueError(f"fault {kind!r}: expected one of {', '.join(FAULTS)}")
            on = _onoff(args[2])
            setattr(ax.faults, kind, on)
            if kind == "encoder_loss":
                if on:
                    ax.enc_frozen = ax.encoder()
                elif ax.enc_frozen is not None:
                    # the counter goes on from where it stopped: the counts it missed while
                    # the signal was gone are lost, as with an incremental encoder
                    frozen, ax.enc_frozen = ax.enc_frozen, None
                    ax.enc_offset += frozen - ax.encoder()
            ax.settled = False
            return {"faults": [k for k in FAULTS if getattr(ax.faults, k)]}
        if command == "switch":
            name, state = args[1], args[2]
            if name not in ("left", "right", "home"):
                raise ValueError(f"switch {name!r}: expected left, right or home")
            if state == "auto":
                ax.sw.forced.pop(name, None)
            else:
                ax.sw.forced[name] = _onoff(state)
            ax.settled = False
            return {name: ax.switch(name)}
        if command == "load":
            ax.mech.load = float(args[1])
            ax.settled = False
            return {"load_nm": ax.mech.load}
        if command == "input":
            port = int(args[1], 0)
            if not 0 <= port <= 7:
                raise ValueError(f"input {port}: expected 0-7")
            m.set_input(port, int(args[2], 0))
            return {"inputs": m.inputs}
        port, value = int(args[1], 0), int(args[2], 0)
        if port not in (0, 4) or not 0 <= value <= 4095:
            raise ValueError("analog PORT VALUE: PORT 0 or 4, VALUE 0-4095")
        m.analog[port // 4] = value
        return {"analog": m.analog}
    except IndexError:
        raise ValueError(f"usage: {HELP[command]}") from None

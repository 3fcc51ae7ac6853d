"""``ecatsim ctl status`` as a table for people (``--json`` keeps the raw answer).

Ref: TMC8460 §5.19 Table 31 (DL status), §5.21/5.22 (AL status and code), §5.33-5.38
(error counters), §5.42/5.43 (process-data watchdog status and counter).
"""

from __future__ import annotations

from typing import Any

from ecatsim.slave.al import AL_ERROR, AL_STATE_MASK, AlState, status_code_text

#: ports the TMC8460 has (§1: two MII ports); a junction slave (ports 2 and 3 cabled in
#: the segment file) adds its ports 2 and 3 to the table
PORTS = (0, 1)
ALL_PORTS = (0, 1, 2, 3)


def al_state_text(al_status: int) -> str:
    """``SAFEOP+ERR``: the AL state name of AL status bits 3:0, with the error flag."""
    try:
        name = AlState(al_status & AL_STATE_MASK).name
    except ValueError:
        name = f"0x{al_status & AL_STATE_MASK:X}?"
    return name + ("+ERR" if al_status & AL_ERROR else "")


def port_text(dl_status: int, port: int) -> str:
    """``link/closed``: physical link (bit 4+p) and loop (bit 8+2p) of one port."""
    link = "link" if dl_status >> (4 + port) & 1 else "nolink"
    loop = "closed" if dl_status >> (8 + 2 * port) & 1 else "open"
    return f"{link}/{loop}"


def _errors(s: dict[str, Any]) -> str:
    rx = "+".join(f"{inv}/{phy}" for inv, phy in s["rx_errors"])
    fwd = "+".join(str(n) for n in s["fwd_rx_errors"])
    lost = "+".join(str(n) for n in s["lost_link"])
    return f"rx {rx} fwd {fwd} pu {s['pu_errors']} pdi {s['pdi_errors']} lost {lost}"


def _table(rows: list[list[str]]) -> list[str]:
    """Rows of cells as aligned lines (the first row is the header)."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]


def _cell(v: Any) -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, list | tuple):
        return ",".join(_cell(x) for x in v) or "-"
    if isinstance(v, dict):
        return ",".join(f"{k}={_cell(x)}" for k, x in v.items()) or "-"
    return "-" if v is None or v == "" else str(v)


#: the columns ``ctl status`` shows of each front door's devices (the rest: ``--json``)
DOOR_COLUMNS: dict[str, tuple[str, ...]] = {
    "modules": (
        "address", "mode", "closed_loop", "actual_position", "target_position",
        "actual_speed", "encoder", "target_reached", "program", "faults", "errors",
    ),
    "nodes": ("name", "address", "state", "actpos", "tagpos", "current_ma", "flags"),
}  # fmt: skip


def format_door(name: str, door: dict[str, Any]) -> list[str]:
    """One front door (TMCL, LIN, a PDI or MFC CTRL socket): a line of its counters, then
    a table of its devices (TMCL modules, LIN nodes), one per line."""
    scalars = {k: v for k, v in door.items() if not _is_rows(v)}
    counters = ", ".join(f"{k.replace('_', ' ')} {_cell(v)}" for k, v in scalars.items())
    lines = [f"{name}: {counters}"]
    for key, devices in door.items():
        if not _is_rows(devices):
            continue
        cols = [c for c in DOOR_COLUMNS.get(key, ()) if c in devices[0]] or list(devices[0])
        rows = [[c.replace("_", " ") for c in cols]]
        rows += [[_cell(d.get(c)) for c in cols] for d in devices]
        lines += ["  " + ln for ln in _table(rows)]
    return lines


def _is_rows(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def eoe_text(position: int, e: dict[str, Any]) -> str:
    """One slave's EoE counters: frames/fragments/drops each way. Ref: ETG.1000.6 §5.7."""
    return (
        f"slave {position} EoE ip {e['ip'] or '-'}: to slave {e['to_slave_frames']} frames "
        f"({e['to_slave_fragments']} fragments, {e['to_slave_dropped']} dropped), to master "
        f"{e['to_master_frames']} frames ({e['to_master_fragments']} fragments, "
        f"{e['to_master_dropped']} dropped), {e['requests']} requests "
        f"({e['refused']} refused)"
    )


def format_status(status: dict[str, Any]) -> str:
    """The daemon's ``status`` answer as aligned text: the EtherCAT slaves, one per line
    (left out for a daemon that serves front doors only), then each front door."""
    doors = status.get("doors", {})
    slaves = status.get("slaves", [])
    if not slaves and doors:
        return "\n".join(ln for name, door in doors.items() for ln in format_door(name, door))
    ports = ALL_PORTS if any(s.get("ports", 0x3) & 0xC for s in slaves) else PORTS
    header = ["slave", "station", "state", "AL status code", *(f"port {p}" for p in ports)]
    header += ["errors", "wd expiries"]
    rows = [header]
    for s in slaves:
        # 0x0440 bit 0 reads 0 until the watchdog first runs: it means "expired" only
        # where process data should flow
        running = s["al_status"] & AL_STATE_MASK in (AlState.SAFEOP, AlState.OP)
        wd = " expired" if running and s.get("wd_pd_status", 1) == 0 else ""
        rows.append(
            [
                str(s["position"]),
                f"0x{s['station']:04X}",
                al_state_text(s["al_status"]),
                status_code_text(s["al_status_code"]),
                *(
                    port_text(s["dl_status"], p) if s.get("ports", 0x3) >> p & 1 else "-"
                    for p in ports
                ),
                _errors(s),
                f"{s['wd_expired']}{wd}",
            ]
        )
    lines = _table(rows)
    for s in status.get("slaves", []):
        e = s.get("eoe")
        if e is not None:
            lines.append(eoe_text(s["position"], e))
    tree = status.get("topology", [])
    if len(tree) > 1 or any(" - out" in t for t in tree):
        lines.append("topology (port 0 -> 3 -> 1 -> 2):")
        lines += [f"  {t}" for t in tree]
    lines.append(f"frames {status.get('frames', 0)}, bad frames {status.get('bad_frames', 0)}")
    faults = status.get("faults", [])
    if faults:
        lines.append(f"active faults ({len(faults)}, fired {status.get('faults_fired', 0)}):")
        for f in faults:
            rest = " ".join(f"{k}={v}" for k, v in f.items() if k not in ("id", "kind"))
            lines.append(f"  #{f['id']} {f['kind']} {rest}".rstrip())
    else:
        lines.append("active faults: none")
    for name, door in doors.items():
        lines += format_door(name, door)
    return "\n".join(lines)

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


def format_status(status: dict[str, Any]) -> str:
    """The daemon's ``status`` answer as aligned text, one slave per line."""
    slaves = status.get("slaves", [])
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
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]
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
    for name, door in status.get("doors", {}).items():
        lines.append(f"{name}: " + ", ".join(f"{k} {v}" for k, v in door.items()))
    return "\n".join(lines)

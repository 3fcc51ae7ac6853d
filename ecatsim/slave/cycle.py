"""The compiled DC cycle of a CoE slave's firmware (optional C extension ``_cycle``).

In DC synchronous mode every SYNC0 pulse wakes the firmware of every slave: acknowledge
SYNC0, read SM2, apply the outputs, refresh and write the inputs to SM3. ``_cycle.run``
does this PDI-side work in one call when nothing else is pending, and leaves everything
else (AL control, mailbox, watchdog, a state that is not SAFEOP/OP) to
:meth:`Firmware.service`, the reference model. The device (CiA 402 drive, servo) is
called through its Python methods, so it has one implementation.

:func:`build` collects the stable references the C code needs, once per process-data
plan; every value that can change is read live on every call.
Ref: ETG.1000.6 §5.3 (DC synchronous mode); docs/decisions.md P3.
"""

from __future__ import annotations

import re
import struct
from typing import TYPE_CHECKING

from ecatsim.compiled import load
from ecatsim.slave.al import AlState
from ecatsim.slave.pdo import Codec, PdoImage

if TYPE_CHECKING:
    from ecatsim.slave.firmware import Firmware

compiled = load("ecatsim.slave._cycle")  # decision P3; None: Python serves

#: one DC cycle's tuple for _cycle.run (layout: the enum in _cycle.c)
Cycle = tuple[object, ...]

SM_PD_OUT = 2
SM_PD_IN = 3
_TOKEN = re.compile(r"(\d*)([a-zA-Z?])")


def layout(c: Codec) -> bytes:
    """Offset (LE 16) and struct code of each entry of a one-struct codec, 3 bytes each,
    taken from the struct format itself."""
    out = bytearray()
    pos = 0
    fmt = c.st.format
    for count, code in _TOKEN.findall(fmt.lstrip("<")):
        n = int(count) if count else 1
        if code == "x":
            pos += n
            continue
        for _ in range(n):
            out += struct.pack("<Hc", pos, code.encode())
            pos += struct.calcsize("<" + code)
    if len(out) // 3 != len(c.entries):  # pragma: no cover - codec() builds no such format
        raise ValueError(f"struct format {fmt!r} does not match its {len(c.entries)} entries")
    return bytes(out)


def _device_step(device: object) -> object:
    """The device's compiled steady cycle, (step, fast), or None: then the C code calls
    its methods outputs_applied() and update_inputs(). The drive has none since its cycle
    is part of the compiled core (decision P2); the hook goes with this module."""
    fn = getattr(device, "compiled_step", None)
    return fn() if fn is not None else None


def build(fw: Firmware, mask_dc: int) -> Cycle | None:
    """The tuple ``_cycle.run`` works on, or None where the compiled cycle does not apply
    (no extension, an application other than a CoE process image, an image without a
    one-struct codec, or register side effects it does not know)."""
    if compiled is None:
        return None
    app = fw.app
    if not isinstance(app, PdoImage):
        return None
    plan = app.plan
    rx, tx = plan.rx_codec, plan.tx_codec
    if rx is None or tx is None:
        return None
    view = fw.pdi.compiled_view(SM_PD_OUT, SM_PD_IN)
    if view is None:
        return None
    return (
        fw,
        *view,
        rx.entries,
        layout(rx),
        tx.entries,
        layout(tx),
        rx.st.size,
        tx.st.size,
        app.device,
        _device_step(app.device),
        fw.mbx,
        app,
        AlState.OP,
        AlState.SAFEOP,
        mask_dc,
    )

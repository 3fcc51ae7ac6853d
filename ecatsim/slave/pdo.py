"""PDO mapping (0x16xx/0x1Axx), assignment (0x1C12/0x1C13) and the compiled copy plan.

Mapping writes are validated when they happen (object exists, is mappable, direction,
length) and the plan is compiled at PREOP->SAFEOP, when the SM lengths are checked. What a
device allows (which PDOs each SM may carry, fixed and mandatory ones, exclusions, bit-wise
mapping) is a ``PdoRules``: the TMC8670's by default, an ESI's for a generic slave.
Ref: ETG.1000.6 §5.6.7.4 (PDO mapping/assignment objects); CiA 301 §7.5.2.35/36;
ETG.2000 §5 (RxPdo/TxPdo Fixed, Mandatory, Exclude); TMC8670 §2.1 (max. 9 mapping
entries), §4.1.7-4.1.11.
"""

from __future__ import annotations

import struct
from array import array
from dataclasses import dataclass, field
from typing import Protocol

from ecatsim.esc.pdi import SmImage
from ecatsim.slave.al import AlState
from ecatsim.slave.od import (
    ABORT_NO_OBJECT,
    ABORT_NOT_MAPPABLE,
    ABORT_PARAM_INCOMPATIBLE,
    ABORT_PDO_LENGTH,
    ABORT_SI0_NOT_ZERO,
    Entry,
    ObjectDictionary,
    SdoAbort,
)

RX_MAP = 0x1600
TX_MAP = 0x1A00
RX_ASSIGN = 0x1C12
TX_ASSIGN = 0x1C13
#: Largest PDO: 32 bytes (see docs/decisions.md C6).
MAX_PDO_BITS = 256


@dataclass(frozen=True, slots=True)
class PdoRules:
    """What the master may assign and map. The default is the TMC8670's: one PDO per SM
    (0x1600, 0x1A00), byte-aligned entries, 32 bytes at most (decision C6).

    Ref: ETG.2000 §5 (RxPdo/TxPdo: Fixed, Mandatory, Exclude); ETG.1000.6 §5.6.7.4.
    """

    rx_pdos: tuple[int, ...] = (RX_MAP,)
    tx_pdos: tuple[int, ...] = (TX_MAP,)
    max_bits: int = MAX_PDO_BITS
    #: entries may have any bit length at any bit offset (an ESI's BOOL/BIT entries)
    bit_mapping: bool = False
    #: PDOs that must stay assigned
    mandatory: frozenset[int] = frozenset()
    #: PDO -> the PDOs it cannot be assigned with
    exclude: dict[int, frozenset[int]] = field(default_factory=dict)

    def allowed(self, assign: int) -> tuple[int, ...]:
        return self.rx_pdos if assign == RX_ASSIGN else self.tx_pdos


#: the TMC8670's rules
DEFAULT_RULES = PdoRules()


@dataclass(frozen=True, slots=True)
class Field:
    """One mapped entry: byte offset, byte size, the OD entry (None = padding); an entry
    that is not whole bytes also has its bit offset in that byte and its bit length."""

    offset: int
    size: int
    entry: Entry | None
    bit: int = 0
    bits: int = 0

    @property
    def whole_bytes(self) -> bool:
        return self.bits == 0 or (self.bit == 0 and self.bits % 8 == 0)

    def read(self, data: bytes | bytearray | memoryview) -> int:
        """The field's bits from an image, as an unsigned integer."""
        raw = int.from_bytes(data[self.offset : self.offset + self.size], "little")
        return (raw >> self.bit) & ((1 << self.bits) - 1)

    def write(self, out: bytearray, value: int) -> None:
        """Put ``value``'s low bits into the field's bits of ``out``."""
        raw = int.from_bytes(out[self.offset : self.offset + self.size], "little")
        mask = ((1 << self.bits) - 1) << self.bit
        raw = (raw & ~mask) | ((value << self.bit) & mask)
        out[self.offset : self.offset + self.size] = raw.to_bytes(self.size, "little")


@dataclass(frozen=True, slots=True)
class Codec:
    """A whole process image as one struct: the mapped entries in order, padding skipped."""

    st: struct.Struct
    entries: tuple[Entry, ...]
    #: per entry ``offset << 4 | bytes << 1 | signed`` where every entry is an integer of
    #: 1-4 bytes (the compiled core decodes and encodes those in C; decision P33), else None
    layout: tuple[int, ...] | None = None


@dataclass(frozen=True, slots=True)
class Plan:
    """The compiled process images (with a one-struct codec where every field allows it)."""

    rx: tuple[Field, ...]
    tx: tuple[Field, ...]
    rx_size: int
    tx_size: int
    rx_codec: Codec | None = None
    tx_codec: Codec | None = None


#: struct codes of the integer types, by (signed, bits). Ref: ETG.1000.6 Table 64.
_CODES = {
    (True, 8): "b", (False, 8): "B", (True, 16): "h", (False, 16): "H",
    (True, 32): "i", (False, 32): "I", (True, 64): "q", (False, 64): "Q",
}  # fmt: skip


def codec(fields: tuple[Field, ...], size: int) -> Codec | None:
    """One struct for an image of byte-aligned integer fields; None if any field is of
    another type (strings, REAL32, 24-bit types: the per-entry path handles those)."""
    fmt, pos, entries, layout = ["<"], 0, [], []
    for f in fields:
        if not f.whole_bytes:
            return None
        if f.offset > pos:
            fmt.append(f"{f.offset - pos}x")
        if f.entry is None:
            fmt.append(f"{f.size}x")
        else:
            dtype = f.entry.dtype
            if not dtype.startswith(("INTEGER", "UNSIGNED", "BOOLEAN")):
                return None
            code = _CODES.get((dtype.startswith("INTEGER"), f.size * 8))
            if code is None:
                return None
            fmt.append(code)
            entries.append(f.entry)
            layout.append(f.offset << 4 | f.size << 1 | (code in "bhiq"))
        pos = f.offset + f.size
    if size > pos:
        fmt.append(f"{size - pos}x")
    # the compiled core's tables hold an offset in two bytes (an SM is at most 64 KiB long)
    small = all((spec >> 1) & 7 <= 4 and spec >> 4 < 1 << 16 for spec in layout)
    return Codec(struct.Struct("".join(fmt)), tuple(entries), tuple(layout) if small else None)


def _table(layout: tuple[int, ...] | None) -> bytearray:
    """A layout as the compiled core reads it through a kept pointer (decision P89): per
    entry four bytes, the offset's low and high byte, ``bytes | signed << 3`` and the
    device's slot + 1 for the value (0: the entry's own value; set by ``_bind_slots``)."""
    out = bytearray()
    for spec in layout or ():
        off = spec >> 4
        out += bytes((off & 0xFF, off >> 8, (spec >> 1) & 7 | (spec & 1) << 3, 0))
    return out


def _spec_bounds(high: bool) -> list[int]:
    """Per row spec of a layout table (``bytes | signed << 3``, 0-15), the lowest (False)
    or highest (True) value its field codes: the field's range as two loads, not a shift
    and a test of the sign per entry and cycle (decision P95). No layout row holds 0 bytes
    (``codec``): those specs get an empty range, lowest 0 above highest -1."""
    out = []
    for spec in range(16):
        bits = 8 * (spec & 7)
        if not bits:
            out.append(-1 if high else 0)
        elif spec & 8:
            out.append((1 << (bits - 1)) - 1 if high else -(1 << (bits - 1)))
        else:
            out.append((1 << bits) - 1 if high else 0)
    return out


#: a layout row's field range by its spec (decision P95), C arrays in the compiled core
_SPEC_LO = _spec_bounds(False)
_SPEC_HI = _spec_bounds(True)


def _c_int(v: int) -> int:
    """``v`` itself; compiled, a C ``long long`` (OverflowError beyond its range)."""
    return v


def _mapped(od: ObjectDictionary, value: int, rx: bool) -> tuple[Entry | None, int]:
    """Resolve one mapping entry value (index << 16 | sub << 8 | bits)."""
    index, sub, bits = value >> 16, (value >> 8) & 0xFF, value & 0xFF
    if index == 0 or index < 0x0008:  # padding / dummy data types
        return None, bits
    if index not in od:
        raise SdoAbort(ABORT_NO_OBJECT, f"mapped object 0x{index:04X}")
    e = od.entry(index, sub)
    if not e.pdo or bits not in (e.bits, *e.pdo_bits) or (rx and e.access == "ro"):
        raise SdoAbort(ABORT_NOT_MAPPABLE, f"0x{index:04X}:{sub} ({bits} bits)")
    return e, bits


def _is_rx(index: int) -> bool:
    return 0x1600 <= index < 0x1800


def mapping_fields(
    od: ObjectDictionary, index: int, rules: PdoRules = DEFAULT_RULES, start: int = 0
) -> tuple[list[Field], int]:
    """Fields and total bits of a mapping object whose first entry sits at bit ``start``
    of the image. Ref: CiA 301 §7.5.2.36."""
    obj = od[index]
    n = int(obj.entries[0].value)
    fields = []
    bit = start
    for s in range(1, n + 1):
        e, bits = _mapped(od, int(obj.entries[s].value), _is_rx(index))
        if bit % 8 or bits % 8:
            if not rules.bit_mapping:
                raise SdoAbort(ABORT_NOT_MAPPABLE, "only byte-aligned mappings are supported")
            first, last = bit // 8, (bit + bits - 1) // 8
            fields.append(Field(first, last - first + 1, e, bit % 8, bits))
        else:
            fields.append(Field(bit // 8, bits // 8, e))
        bit += bits
    if bit - start > rules.max_bits:
        raise SdoAbort(ABORT_PDO_LENGTH, f"{bit - start} bits > {rules.max_bits}")
    return fields, bit - start


def assigned(od: ObjectDictionary, assign: int) -> list[int]:
    """The PDOs an assignment object lists now (subindex 1..n)."""
    if assign not in od:
        return []
    obj = od[assign]
    return [int(obj.entries[s].value) for s in range(1, int(obj.entries[0].value) + 1)]


def check_assignment(od: ObjectDictionary, assign: int, rules: PdoRules) -> None:
    """Each assigned PDO is one the SM may carry, listed once, with none it excludes.

    Ref: ETG.1000.6 §5.6.7.4.7; ETG.2000 §5 (Exclude); abort codes of Table 41.
    """
    pdos = assigned(od, assign)
    allowed = rules.allowed(assign)
    for p in pdos:
        if p not in allowed or p not in od:
            raise SdoAbort(ABORT_NO_OBJECT, f"PDO 0x{p:04X}")
    if len(set(pdos)) != len(pdos):
        raise SdoAbort(ABORT_PARAM_INCOMPATIBLE, "a PDO assigned twice")
    for p in pdos:
        clash = rules.exclude.get(p, frozenset()) & set(pdos)
        if clash:
            raise SdoAbort(ABORT_PARAM_INCOMPATIBLE, f"PDO 0x{p:04X} excludes 0x{min(clash):04X}")


def _check_mandatory(od: ObjectDictionary, assign: int, rules: PdoRules) -> None:
    pdos = assigned(od, assign)
    missing = [p for p in rules.allowed(assign) if p in rules.mandatory and p not in pdos]
    if missing:
        raise SdoAbort(ABORT_PARAM_INCOMPATIBLE, f"mandatory PDO 0x{missing[0]:04X} unassigned")


def install(od: ObjectDictionary, rules: PdoRules = DEFAULT_RULES) -> None:
    """Validators on the mapping and assignment objects."""

    def mapping_validator(index: int) -> None:
        def check(sub: int) -> None:
            obj = od[index]
            if sub > 0:
                if int(obj.entries[0].value) != 0:
                    raise SdoAbort(ABORT_SI0_NOT_ZERO, "write subindex 0 = 0 first")
                value = int(obj.entries[sub].value)
                if value:
                    _mapped(od, value, _is_rx(index))
                return
            mapping_fields(od, index, rules)

        od[index].validate = check

    def assign_validator(index: int) -> None:
        def check(sub: int) -> None:
            obj = od[index]
            if sub > 0 and int(obj.entries[0].value) != 0:
                raise SdoAbort(ABORT_SI0_NOT_ZERO, "write subindex 0 = 0 first")
            check_assignment(od, index, rules)
            if sub == 0 and int(obj.entries[0].value) > 0:
                _check_mandatory(od, index, rules)

        od[index].validate = check

    for idx in (*rules.rx_pdos, *rules.tx_pdos):
        if idx in od:
            mapping_validator(idx)
    for idx in (RX_ASSIGN, TX_ASSIGN):
        if idx in od:
            assign_validator(idx)


def _image_fields(od: ObjectDictionary, assign: int, rules: PdoRules) -> tuple[list[Field], int]:
    fields: list[Field] = []
    bits = 0
    if assign in od:
        check_assignment(od, assign, rules)
        for p in assigned(od, assign):
            f, n = mapping_fields(od, p, rules, bits)
            fields += f
            bits += n
    return fields, bits


def compile_plan(od: ObjectDictionary, rules: PdoRules = DEFAULT_RULES) -> Plan:
    """The copy plan from the assigned PDOs, in assignment order.

    Ref: ETG.1000.6 §5.6.7.4.7."""
    rx, rx_bits = _image_fields(od, RX_ASSIGN, rules)
    tx, tx_bits = _image_fields(od, TX_ASSIGN, rules)
    rx_size, tx_size = (rx_bits + 7) // 8, (tx_bits + 7) // 8
    return Plan(
        tuple(rx), tuple(tx), rx_size, tx_size, codec(tuple(rx), rx_size), codec(tuple(tx), tx_size)
    )


class CoeDevice(Protocol):
    """A device that works on object dictionary values."""

    def outputs_applied(self, now_ns: int) -> None:
        """RxPDO values were just written into the OD (OP only)."""
        ...

    def update_inputs(self, now_ns: int) -> None:
        """Refresh the OD values the TxPDO carries."""
        ...

    def al_state_changed(self, state: AlState, now_ns: int) -> None: ...


class CycleDevice:
    """The base of a CoeDevice whose cycle the compiled process image calls as C calls
    (pdo.pxd declares both methods cpdef: a subclass's overrides are found through the
    extension type's method table, not by Python attribute lookup; decision P32). A
    CoeDevice that does not derive from it is called through Python as before.

    A device may keep values the TxPDO carries as C integers (``pub_values``) and write
    them into their OD entries only when something reads the OD (``pub_flush``):
    ``tx_slots`` says which; while ``pub_pending``, the image takes those values from the
    device, not from the entries (decision P38)."""

    #: values the device keeps for OD entries (see tx_slots); set by a device that does
    pub_values: array[int]
    #: whether those values are newer than their entries
    pub_pending: bool

    def outputs_applied(self, now_ns: int) -> None:
        raise NotImplementedError

    def update_inputs(self, now_ns: int) -> None:
        raise NotImplementedError

    def pub_flush(self) -> None:
        """Write the kept values into their entries (none kept: nothing)."""

    def tx_slots(self, entries: tuple[Entry, ...]) -> tuple[int, ...] | None:
        """Per entry, its index in ``pub_values`` or -1; None: the device keeps none."""
        return None


class PdoImage(SmImage):
    """The firmware's Application for a CoE device: process images through the OD; it
    fills SM3's buffer in place where it can (``fill``, decision P71)."""

    def __init__(
        self, od: ObjectDictionary, device: CoeDevice, rules: PdoRules = DEFAULT_RULES
    ) -> None:
        self.od = od
        self._device: CoeDevice
        self._dev: CycleDevice | None = None
        self._tx_entries: tuple[Entry, ...] = ()
        self._tx_tab = self._tx_tp = bytearray()
        #: whether the device keeps values for TxPDO entries (P38), and how many it must
        #: keep for the slots of _tx_tab (checked against ``pub_values`` per fill, P89)
        self._tx_slots_on = False
        self._tx_top = 0
        self.device = device
        self.rules = rules
        self.plan = compile_plan(od, rules)
        install(od, rules)

    @property
    def device(self) -> CoeDevice:
        """The device behind the process image."""
        return self._device

    @device.setter
    def device(self, device: CoeDevice) -> None:
        self._device = device
        #: the same device as a CycleDevice, called in C (None: through Python)
        self._dev = device if isinstance(device, CycleDevice) else None
        self._bind_slots()

    def _bind_slots(self) -> None:
        """Where the device keeps the TxPDO entries' values (decision P38), written into
        _tx_tab (P89): one slot per entry, each -1 (the entry) or an index below 255."""
        dev = self._dev
        entries = self._tx_entries
        slots = dev.tx_slots(entries) if dev is not None else None
        if slots is not None and (
            len(slots) != len(entries) or not all(-1 <= k < 255 for k in slots)
        ):
            raise ValueError(f"tx_slots: {slots!r} for {len(entries)} entries")
        tab = self._tx_tab
        top = 0
        for i in range(len(tab) // 4):
            k = slots[i] if slots is not None else -1
            tab[4 * i + 3] = k + 1
            top = max(top, k + 1)
        self._tx_slots_on = slots is not None
        self._tx_top = top

    @property
    def plan(self) -> Plan:
        """The copy plan in use (compiled at PREOP->SAFEOP)."""
        return self._plan

    @plan.setter
    def plan(self, plan: Plan) -> None:
        self._plan = plan
        rx, tx = plan.rx_codec, plan.tx_codec
        #: the one-struct codecs' parts, bound once per plan (the DC cycle's hot path)
        self._rx_st = rx.st if rx is not None else None
        #: the output struct's size (-1: no struct), a C integer for the per-cycle test
        self._rx_need = rx.st.size if rx is not None else -1
        self._rx_entries = rx.entries if rx is not None else ()
        self._rx_layout = rx.layout if rx is not None else None
        self._tx_st = tx.st if tx is not None else None
        self._tx_entries = tx.entries if tx is not None else ()
        self._tx_layout = tx.layout if tx is not None else None
        #: the layouts as bytes read through pointers kept beside them (decisions P51,
        #: P89: no int object converted, no view's checks per entry and cycle); empty where
        #: there is no layout. A table is never resized: a new plan makes new ones.
        self._rx_tab = _table(self._rx_layout)
        self._rx_tp = self._rx_tab  # compiled: a pointer to the table's bytes
        self._tx_tab = _table(self._tx_layout)
        self._tx_tp = self._tx_tab  # compiled: a pointer to the table's bytes
        #: the input image the C encoder fills: its padding stays zero, its entries'
        #: bytes are all written by every fill (decision P33)
        self._tx_buf = bytearray(plan.tx_size)
        self._tx_bp = self._tx_buf  # compiled: a pointer to its bytes, kept (P89)
        self._bind_slots()

    def prepare(self) -> int:
        """Compile the plan at PREOP->SAFEOP; an invalid mapping is an AL status code.

        Ref: ETG.1000.6 Table 11 (0x0024 invalid input mapping, 0x0025 invalid output).
        """
        try:
            self.plan = compile_plan(self.od, self.rules)
        except SdoAbort:
            return 0x0025
        return 0

    def rx_size(self) -> int:
        return self.plan.rx_size

    def tx_size(self) -> int:
        return self.plan.tx_size

    def set_outputs(self, data: bytes | bytearray, now_ns: int) -> None:
        st = self._rx_st
        if st is not None and len(data) >= self._rx_need:
            entries: tuple[Entry, ...] = self._rx_entries
            layout = self._rx_layout
            if layout is not None and type(data) is bytearray:
                # the outputs the firmware latched into its buffer (decision P70)
                ba: bytearray = data
                self._rx_decode(ba)  # compiled: a pointer to the buffer's bytes
            elif layout is not None and type(data) is bytes:
                buf: bytes = data
                self._rx_decode(buf)  # compiled: a pointer to the bytes
            else:
                values: tuple[int, ...] = st.unpack_from(data)
                for i in range(len(entries)):
                    e = entries[i]
                    e.value = values[i]
        else:
            for f in self._plan.rx:
                if f.entry is not None:
                    if f.whole_bytes:
                        f.entry.value = f.entry.decode(data[f.offset : f.offset + f.size])
                    else:
                        f.entry.value = f.read(data)
        dev = self._dev
        if dev is not None:
            dev.outputs_applied(now_ns)
        else:
            self._device.outputs_applied(now_ns)

    def _rx_decode(self, q: bytes | bytearray) -> int:
        """The struct's values, decoded in C from the bytes (decision P33); the caller
        checked that the struct fits. 0 (compiled: a C int whose value shows an error, so
        no test of the thread's error state follows the call, P96)."""
        entries: tuple[Entry, ...] = self._rx_entries
        t = self._rx_tp  # the layout's table (P89), one row per entry
        for i in range(len(entries)):
            j = 4 * i
            off = t[j] | t[j + 1] << 8
            spec = t[j + 2]
            n = spec & 7
            # 1, 2 or 4 bytes (the layout holds no more), each as a C long long before its
            # shift (an unsigned char shifted is a C int, whose bit 31 made a sign; P51)
            raw = q[off]
            if n > 1:
                byte = q[off + 1]
                raw |= byte << 8
                if n > 2:
                    byte = q[off + 2]
                    raw |= byte << 16
                    if n > 3:
                        byte = q[off + 3]
                        raw |= byte << 24
            if spec & 8 and raw > _SPEC_HI[spec]:  # a signed field's negative value
                raw -= _SPEC_HI[spec] - _SPEC_LO[spec] + 1
            e = entries[i]
            e.value = raw
        return 0

    def get_inputs(self, now_ns: int) -> bytes:
        self.update_inputs(now_ns)
        return self.pack_inputs()

    def update_inputs(self, now_ns: int) -> None:
        """The device's values as of ``now_ns`` (``get_inputs`` without the bytes: the
        firmware then fills SM3 in place, decision P71)."""
        dev = self._dev
        if dev is not None:
            dev.update_inputs(now_ns)
        else:
            self._device.update_inputs(now_ns)

    def pack_inputs(self) -> bytes:
        """The input image from the OD values, as they are now."""
        st = self._tx_st
        layout = self._tx_layout
        if layout is not None:
            fast = self._pack_small()
            if fast is not None:
                # compiled, already bytes; Python's slice of the bytearray is made bytes
                return fast if type(fast) is bytes else bytes(fast)
        dev = self._dev
        if dev is not None:
            dev.pub_flush()  # the entries as the device has them now (P38)
        if st is not None:
            entries: tuple[Entry, ...] = self._tx_entries
            values = []
            for i in range(len(entries)):
                e = entries[i]
                values.append(e.value)
            try:
                return st.pack(*values)
            except struct.error:
                pass  # a value out of its type's range: encoded (masked) entry by entry
        out = bytearray(self.plan.tx_size)
        for f in self.plan.tx:
            if f.entry is not None:
                if f.whole_bytes:
                    out[f.offset : f.offset + f.size] = f.entry.encode()[: f.size]
                else:
                    f.write(out, int.from_bytes(f.entry.encode(), "little"))
        return bytes(out)

    def _pack_small(self) -> bytes | bytearray | None:
        """The struct's bytes, encoded in C into the image buffer where every value is an
        int within its field's type; None (the struct path decides) for any other (P33).
        A value the device keeps for its entry is taken from the device (P38)."""
        if not self._pack_buf():
            return None
        out = self._tx_buf
        p = out  # compiled: a pointer to the buffer
        # compiled, the pointer's slice is made as bytes at once, with no call and no
        # buffer export (P51); in Python it is a bytearray, which pack_inputs makes bytes
        return p[: len(out)]

    def fill(self, mem: bytearray, base: int, n: int) -> bool:
        """``_pack_small``'s bytes straight into an SM's buffer at ``base`` of the ESC
        memory (``Pdi.sm_fill``, decision P71): encoded into the image buffer, then copied
        (its padding zero), so a value that does not fit leaves the SM's buffer untouched.
        False, with nothing written there, where ``pack_inputs`` must make the bytes (no
        layout, another size, a value not an int in its field's range)."""
        if self._tx_layout is None or n != len(self._tx_buf) or not self._pack_buf():
            return False
        self._copy_to(mem, base, self._tx_bp, n)  # compiled: pointers (range checked)
        return True

    def _copy_to(self, dst: bytearray, d: int, src: bytearray, n: int) -> None:
        """``dst[d:d + n] = src[:n]`` for ranges the caller checked, four bytes a step."""
        k = 0
        while k + 4 <= n:
            dst[d + k] = src[k]
            dst[d + k + 1] = src[k + 1]
            dst[d + k + 2] = src[k + 2]
            dst[d + k + 3] = src[k + 3]
            k += 4
        while k < n:
            dst[d + k] = src[k]
            k += 1

    def _pack_buf(self) -> bool:
        """Encode the TxPDO entries' values into the image buffer (its padding stays zero)
        in C where every value is an int within its field's type; False for any other
        (P33), the buffer then partly written and the struct path deciding."""
        entries: tuple[Entry, ...] = self._tx_entries
        p = self._tx_bp  # the image buffer's bytes (every field lies inside it)
        dev = self._dev
        # the device's values where it keeps them (the field itself in the compiled core,
        # not a local view acquired and released per call: P51), every slot inside them
        pending = self._tx_slots_on and dev is not None and dev.pub_pending
        if pending and len(dev.pub_values) < self._tx_top:  # type: ignore[union-attr]
            raise IndexError("the device keeps fewer values than its tx_slots")
        t = self._tx_tp  # the layout's table with the slots (P89), one row per entry
        for i in range(len(entries)):
            j = 4 * i
            slot = t[j + 3]  # the slot + 1 (0: the entry)
            if pending and slot:
                c = dev.pub_values[slot - 1]  # type: ignore[union-attr]  # not None: pending
            else:
                e = entries[i]
                v = e.value
                if type(v) is not int:
                    return False
                try:
                    c = _c_int(v)
                except OverflowError:
                    return False
            off = t[j] | t[j + 1] << 8
            spec = t[j + 2]
            n = spec & 7
            if c < _SPEC_LO[spec] or c > _SPEC_HI[spec]:  # not in its field's range
                return False
            p[off] = c & 0xFF  # 1, 2 or 4 bytes (the layout holds no more), unrolled
            if n > 1:
                p[off + 1] = (c >> 8) & 0xFF
                if n > 2:
                    p[off + 2] = (c >> 16) & 0xFF
                    if n > 3:
                        p[off + 3] = (c >> 24) & 0xFF
        return True

    def al_state_changed(self, state: AlState, now_ns: int) -> None:
        self.device.al_state_changed(state, now_ns)

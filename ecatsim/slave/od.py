"""The CoE object dictionary: objects, entries, typed values, access rules.

Objects are data (from the device description); this module only types, encodes and
checks them. Every refusal is an ``SdoAbort`` carrying the CiA 301 abort code; the SDO
server turns it into an abort frame in one place.
Ref: ETG.1000.6 §5.6.2 (SDO), Table 41 (abort codes), Table 63 (data types);
CiA 301 §7.4 (object dictionary, object codes VAR/ARRAY/RECORD).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum

from ecatsim.device.description import DATA_TYPES


class ObjectCode(IntEnum):
    """Object codes. Ref: CiA 301 Table 42 / ETG.1000.6 Table 62."""

    VAR = 7
    ARRAY = 8
    RECORD = 9


#: Data types of the standard's records, for the SDO Info object description.
#: Ref: CiA 301 §7.4.4 Table 44 (complex data types); ETG.1000.6 §5.6.7.
PDO_MAPPING_TYPE = 0x0021
IDENTITY_TYPE = 0x0023
#: any other record (a manufacturer's structure without its own type index): decision C17
RECORD_TYPE = 0x002A

# SDO abort codes used here. Ref: ETG.1000.6 Table 41.
ABORT_TOGGLE = 0x0503_0000
ABORT_COMMAND = 0x0504_0001
ABORT_OUT_OF_MEMORY = 0x0504_0005
ABORT_UNSUPPORTED_ACCESS = 0x0601_0000
ABORT_WRITE_ONLY = 0x0601_0001
ABORT_READ_ONLY = 0x0601_0002
ABORT_SI0_NOT_ZERO = 0x0601_0003
ABORT_CA_UNSUPPORTED = 0x0601_0004
ABORT_NO_OBJECT = 0x0602_0000
ABORT_NOT_MAPPABLE = 0x0604_0041
ABORT_PDO_LENGTH = 0x0604_0042
ABORT_PARAM_INCOMPATIBLE = 0x0604_0043
ABORT_LENGTH = 0x0607_0010
ABORT_LENGTH_HIGH = 0x0607_0012
ABORT_LENGTH_LOW = 0x0607_0013
ABORT_NO_SUBINDEX = 0x0609_0011
ABORT_VALUE_RANGE = 0x0609_0030
ABORT_VALUE_HIGH = 0x0609_0031
ABORT_VALUE_LOW = 0x0609_0032
ABORT_GENERAL = 0x0800_0000
ABORT_STATE = 0x0800_0022

#: what each abort code means, as ETG.1000.6 Table 41 (CiA 301 Table 22) words it
ABORT_TEXT: dict[int, str] = {
    ABORT_TOGGLE: "toggle bit not changed",
    ABORT_COMMAND: "client/server command specifier not valid or unknown",
    ABORT_OUT_OF_MEMORY: "out of memory",
    ABORT_UNSUPPORTED_ACCESS: "unsupported access to an object",
    ABORT_WRITE_ONLY: "attempt to read a write-only object",
    ABORT_READ_ONLY: "attempt to write a read-only object",
    ABORT_SI0_NOT_ZERO: "subindex cannot be written, SI0 must be 0 for write access",
    ABORT_CA_UNSUPPORTED: "complete access not supported for variable-length objects",
    ABORT_NO_OBJECT: "object does not exist",
    ABORT_NOT_MAPPABLE: "object cannot be mapped to the PDO",
    ABORT_PDO_LENGTH: (
        "the number and length of the objects to be mapped would exceed the PDO length"
    ),
    ABORT_PARAM_INCOMPATIBLE: "general parameter incompatibility",
    ABORT_LENGTH: "data type does not match, length of service parameter does not match",
    ABORT_LENGTH_HIGH: "data type does not match, length of service parameter too high",
    ABORT_LENGTH_LOW: "data type does not match, length of service parameter too low",
    ABORT_NO_SUBINDEX: "subindex does not exist",
    ABORT_VALUE_RANGE: "value range of parameter exceeded",
    ABORT_VALUE_HIGH: "value of parameter written too high",
    ABORT_VALUE_LOW: "value of parameter written too low",
    ABORT_GENERAL: "general error",
    ABORT_STATE: "data cannot be transferred or stored because of the present device state",
}


def abort_text(code: int) -> str:
    """``0x06020000 object does not exist``: the code and its meaning."""
    return f"0x{code:08X} {ABORT_TEXT.get(code, 'unknown abort code')}"


class SdoAbort(Exception):
    """An SDO request refused with a CiA 301 abort code."""

    def __init__(self, code: int, msg: str = "") -> None:
        super().__init__(f"0x{code:08X} {msg}".strip())
        self.code = code


_INT_FORMATS = {8: "b", 16: "h", 32: "i", 64: "q"}


def _signed(dtype: str) -> bool:
    return dtype.startswith("INTEGER")


class Entry:
    """One subindex: type, access, limits and the current value.

    A plain class, not a dataclass: compiled, it is an extension type whose fields the
    drive and the process image read and write directly every cycle (od.pxd, decision
    P15); its constructor, ``repr`` and equality are a slots dataclass's."""

    __slots__ = FIELDS = (
        "sub", "name", "dtype", "access", "pdo", "minimum", "maximum", "default", "unit",
        "values", "write_states", "value", "bits", "pdo_bits",
    )  # fmt: skip

    sub: int
    name: str
    dtype: str
    access: str  # ro, rw, wo
    pdo: bool
    minimum: int | None
    maximum: int | None
    default: int | str
    unit: str
    values: tuple[int, ...]
    #: states (AL codes) in which a write is allowed; empty = any state
    write_states: tuple[int, ...]
    value: int | str | bytes
    bits: int
    #: shorter lengths a PDO may map the entry with besides ``bits`` (the low bits, sign-
    #: extended on the way in), where a datasheet's default mapping uses one
    pdo_bits: tuple[int, ...]

    def __init__(
        self,
        sub: int,
        name: str,
        dtype: str,
        access: str = "ro",
        pdo: bool = False,
        minimum: int | None = None,
        maximum: int | None = None,
        default: int | str = 0,
        unit: str = "",
        values: tuple[int, ...] = (),
        write_states: tuple[int, ...] = (),
        value: int | str | bytes = 0,
        bits: int = 0,
        pdo_bits: tuple[int, ...] = (),
    ) -> None:
        if dtype not in DATA_TYPES:
            raise ValueError(f"unknown data type {dtype}")
        self.sub = sub
        self.name = name
        self.dtype = dtype
        self.access = access
        self.pdo = pdo
        self.minimum = minimum
        self.maximum = maximum
        self.default = default
        self.unit = unit
        self.values = values
        self.write_states = write_states
        self.bits = bits or DATA_TYPES[dtype][1]
        self.pdo_bits = pdo_bits
        self.value = default  # ``value`` is accepted and, as ever, starts at the default

    def __repr__(self) -> str:
        return "Entry(" + ", ".join(f"{f}={getattr(self, f)!r}" for f in Entry.FIELDS) + ")"

    def __eq__(self, other: object) -> bool:
        if other.__class__ is not self.__class__:
            return NotImplemented
        fields = Entry.FIELDS  # compared as field tuples, as a dataclass does
        return tuple(getattr(self, f) for f in fields) == tuple(getattr(other, f) for f in fields)

    __hash__ = None  # type: ignore[assignment]  # mutable, compared by value

    @property
    def type_code(self) -> int:
        return DATA_TYPES[self.dtype][0]

    @property
    def is_string(self) -> bool:
        return self.dtype in ("VISIBLE_STRING", "OCTET_STRING", "UNICODE_STRING")

    @property
    def size(self) -> int:
        """Encoded size in bytes (strings: current length)."""
        if self.is_string:
            return len(self.encode())
        return (self.bits + 7) // 8

    def encode(self) -> bytes:
        """The current value as little-endian bytes. Ref: ETG.1000.6 §5.6.2 data encoding."""
        v = self.value
        if self.is_string:
            if isinstance(v, bytes):
                return v
            return str(v).encode("latin-1", "replace")
        n = (self.bits + 7) // 8
        if self.dtype == "REAL32" and isinstance(v, float):
            return struct.pack("<f", v)  # a float set from the application side
        # an integer is the raw value: for REAL32/REAL64 its IEEE 754 bits, as decoded
        iv = int(v) if not isinstance(v, bytes) else int.from_bytes(v, "little")
        return (iv & ((1 << (8 * n)) - 1)).to_bytes(n, "little")

    def decode(self, data: bytes | bytearray) -> int | str | bytes:
        if self.is_string:
            return data.decode("latin-1") if self.dtype == "VISIBLE_STRING" else bytes(data)
        return int.from_bytes(data, "little", signed=_signed(self.dtype))

    def check_write(self, data: bytes) -> int | str | bytes:
        """Validate a download of ``data``; return the decoded value or raise SdoAbort.

        Ref: ETG.1000.6 Table 41: 0x06070010 length, 0x06090030/31/32 value range.
        """
        if self.is_string:
            return self.decode(data)
        n = (self.bits + 7) // 8
        if len(data) != n:
            raise SdoAbort(ABORT_LENGTH, f"{len(data)} bytes for a {n}-byte entry")
        v = self.decode(data)
        assert isinstance(v, int)
        if self.values and v not in self.values:
            raise SdoAbort(ABORT_VALUE_RANGE, f"{v} not one of {self.values}")
        if self.maximum is not None and v > self.maximum:
            raise SdoAbort(ABORT_VALUE_HIGH, f"{v} > {self.maximum}")
        if self.minimum is not None and v < self.minimum:
            raise SdoAbort(ABORT_VALUE_LOW, f"{v} < {self.minimum}")
        return v


@dataclass(slots=True)
class OdObject:
    """One index with its entries (subindex 0 included for ARRAY/RECORD)."""

    index: int
    name: str
    code: ObjectCode
    entries: dict[int, Entry] = field(default_factory=dict)
    source: str = ""
    beyond_sheet: bool = False
    #: called after a successful write of any entry (index, sub)
    on_write: Callable[[int, int], None] | None = None
    #: checks the object after a write (sub written, 0 for complete access) and raises
    #: SdoAbort to reject it; the previous values are then restored
    validate: Callable[[int], None] | None = None
    #: a RECORD's data type when the standard defines one (IDENTITY 0x0023, PDO_MAPPING
    #: 0x0021; ETG.1000.6 §5.6.7, CiA 301 §7.4.4); 0 for the generic record type
    record_type: int = 0

    def commit(self, changes: list[tuple[Entry, int | str | bytes]], sub: int) -> None:
        """Store values, let ``validate`` veto the new state, then notify ``on_write``."""
        old = [(e, e.value) for e, _v in changes]
        for e, v in changes:
            e.value = v
        if self.validate is not None:
            try:
                self.validate(sub)
            except SdoAbort:
                for e, v in old:
                    e.value = v
                raise
        if self.on_write is not None:
            self.on_write(self.index, sub)

    @property
    def max_sub(self) -> int:
        return max(self.entries) if self.entries else 0

    @property
    def data_type(self) -> int:
        """Object data type for the SDO Info object description. Ref: ETG.1000.6 §5.6.3.5."""
        if self.code == ObjectCode.VAR:
            return self.entries[0].type_code
        if self.code == ObjectCode.ARRAY and 1 in self.entries:
            return self.entries[1].type_code  # an array's element type (1C12: UNSIGNED16)
        if self.code == ObjectCode.RECORD:
            return self.record_type or RECORD_TYPE
        return 0


class ObjectDictionary:
    """Objects by index, sorted."""

    def __init__(self, objects: list[OdObject]) -> None:
        self.objects = {o.index: o for o in sorted(objects, key=lambda o: o.index)}
        #: set by the application: brings values no PDO carries up to date before a read
        self.refresh: Callable[[], None] | None = None
        #: set by the application: writes the values it keeps for entries (as C integers,
        #: between cycles) into them; called before any entry is handed out (decision P38)
        self.flush: Callable[[], None] | None = None

    def __contains__(self, index: int) -> bool:
        return index in self.objects

    def __getitem__(self, index: int) -> OdObject:
        if self.flush is not None:
            self.flush()
        return self.objects[index]

    def entry(self, index: int, sub: int) -> Entry:
        """The entry or the matching abort (object / subindex does not exist)."""
        if self.flush is not None:
            self.flush()
        obj = self.objects.get(index)
        if obj is None:
            raise SdoAbort(ABORT_NO_OBJECT, f"0x{index:04X}")
        e = obj.entries.get(sub)
        if e is None:
            raise SdoAbort(ABORT_NO_SUBINDEX, f"0x{index:04X}:{sub}")
        return e

    def value(self, index: int, sub: int = 0) -> int | str | bytes:
        return self.entry(index, sub).value

    def set(self, index: int, sub: int, value: int | str | bytes) -> None:
        """Set a value from the application side (no access check)."""
        self.entry(index, sub).value = value

    # -- SDO side -------------------------------------------------------------------

    def read(self, index: int, sub: int) -> bytes:
        """SDO upload of one entry. Ref: ETG.1000.6 §5.6.2.4."""
        e = self.entry(index, sub)
        if self.refresh is not None:
            self.refresh()
        if e.access == "wo":
            raise SdoAbort(ABORT_WRITE_ONLY)
        return e.encode()

    def write(self, index: int, sub: int, data: bytes, state: int) -> None:
        """SDO download of one entry. Ref: ETG.1000.6 §5.6.2.1."""
        e = self.entry(index, sub)
        obj = self.objects[index]
        if e.access == "ro":
            raise SdoAbort(ABORT_READ_ONLY)
        if e.write_states and state not in e.write_states:
            raise SdoAbort(ABORT_STATE)
        obj.commit([(e, e.check_write(data))], sub)

    def read_complete(self, index: int, sub: int) -> bytes:
        """Complete Access upload from subindex 0 or 1; subindex 0 takes 16 bits.

        Ref: ETG.1000.6 §5.6.2.4 (complete access); SOEM's ecx_readPDOassignCA.
        """
        if self.flush is not None:
            self.flush()
        if self.refresh is not None:
            self.refresh()
        obj = self.objects.get(index)
        if obj is None:
            raise SdoAbort(ABORT_NO_OBJECT)
        if obj.code == ObjectCode.VAR or sub > 1:
            raise SdoAbort(ABORT_UNSUPPORTED_ACCESS, "complete access needs an ARRAY/RECORD")
        out = b""
        if sub == 0:
            out += struct.pack("<H", int(obj.entries[0].value))
        n = int(obj.entries[0].value)
        for s in range(1, n + 1):
            e = obj.entries.get(s)
            if e is None:
                continue
            if e.access == "wo":
                raise SdoAbort(ABORT_WRITE_ONLY)
            out += e.encode()
        return out

    def write_complete(self, index: int, sub: int, data: bytes, state: int) -> None:
        """Complete Access download from subindex 0 or 1 (subindex 0 as 16 bits).

        The whole write is validated before anything is stored.
        Ref: ETG.1000.6 §5.6.2.1 (complete access).
        """
        if self.flush is not None:
            self.flush()
        obj = self.objects.get(index)
        if obj is None:
            raise SdoAbort(ABORT_NO_OBJECT)
        if obj.code == ObjectCode.VAR or sub > 1:
            raise SdoAbort(ABORT_UNSUPPORTED_ACCESS, "complete access needs an ARRAY/RECORD")
        p = 0
        plan: list[tuple[Entry, int | str | bytes]] = []
        if sub == 0:
            if len(data) < 2:
                raise SdoAbort(ABORT_LENGTH_LOW)
            n = struct.unpack_from("<H", data)[0]
            p = 2
            e0 = obj.entries[0]
            if e0.access == "ro" and n != int(e0.value):
                raise SdoAbort(ABORT_READ_ONLY)
            if e0.write_states and state not in e0.write_states:
                raise SdoAbort(ABORT_STATE)
            if n > obj.max_sub:
                raise SdoAbort(ABORT_VALUE_HIGH)
        else:
            n = int(obj.entries[0].value)
        for s in range(1, n + 1):
            e = obj.entries.get(s)
            if e is None:
                raise SdoAbort(ABORT_NO_SUBINDEX)
            size = (e.bits + 7) // 8
            if p + size > len(data):
                raise SdoAbort(ABORT_LENGTH_LOW)
            if e.access == "ro":
                if e.encode() != data[p : p + size]:
                    raise SdoAbort(ABORT_READ_ONLY)
            elif e.write_states and state not in e.write_states:
                raise SdoAbort(ABORT_STATE)
            plan.append((e, e.check_write(bytes(data[p : p + size]))))
            p += size
        s = n + 1
        while p < len(data) and s in obj.entries:  # data for the unused subindices too
            e = obj.entries[s]
            size = (e.bits + 7) // 8
            if p + size > len(data) or e.access == "ro":
                break
            plan.append((e, e.check_write(bytes(data[p : p + size]))))
            p += size
            s += 1
        if p != len(data):
            raise SdoAbort(ABORT_LENGTH_HIGH)
        if sub == 0:
            plan.insert(0, (obj.entries[0], n))
        obj.commit(plan, 0)

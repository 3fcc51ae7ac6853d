"""ESI data type names -> the OD's base types and bit lengths.

Ref: ETG.2000 §5 (Dictionary/DataTypes: BOOL, BIT1-8, BYTE, WORD, DWORD, SINT ... ULINT,
REAL, LREAL, STRING(n), ARRAY types); ETG.1000.6 Table 63 (CoE data type codes).
"""

from __future__ import annotations

import re

from ecatsim.device.description import DATA_TYPES

#: ESI name -> (OD data type, bits)
BASE_TYPES: dict[str, tuple[str, int]] = {
    "BOOL": ("BOOLEAN", 1),
    "BIT": ("BOOLEAN", 1),
    "BYTE": ("UNSIGNED8", 8),
    "WORD": ("UNSIGNED16", 16),
    "DWORD": ("UNSIGNED32", 32),
    "LWORD": ("UNSIGNED64", 64),
    "BITARR8": ("UNSIGNED8", 8),
    "BITARR16": ("UNSIGNED16", 16),
    "BITARR32": ("UNSIGNED32", 32),
    "SINT": ("INTEGER8", 8),
    "INT": ("INTEGER16", 16),
    "INT24": ("INTEGER24", 24),
    "DINT": ("INTEGER32", 32),
    "LINT": ("INTEGER64", 64),
    "USINT": ("UNSIGNED8", 8),
    "UINT": ("UNSIGNED16", 16),
    "UINT24": ("UNSIGNED24", 24),
    "UDINT": ("UNSIGNED32", 32),
    "ULINT": ("UNSIGNED64", 64),
    "REAL": ("REAL32", 32),
    "LREAL": ("REAL64", 64),
    **{k: (k, v[1]) for k, v in DATA_TYPES.items() if v[1]},
}

STRING_RE = re.compile(r"^(STRING|OCTET_STRING|UNICODE_STRING)\((\d+)\)$")
STRING_TYPES = {
    "STRING": "VISIBLE_STRING",
    "OCTET_STRING": "OCTET_STRING",
    "UNICODE_STRING": "UNICODE_STRING",
}


def base_type(name: str, bits: int = 0) -> tuple[str, int] | None:
    """(OD data type, bits) of an ESI base or string type name; None if it is not one."""
    n = name.strip()
    if n in BASE_TYPES:
        return BASE_TYPES[n]
    m = STRING_RE.match(n)
    if m:
        return STRING_TYPES[m.group(1)], 8 * int(m.group(2))
    if n in ("STRING", "VISIBLE_STRING", "OCTET_STRING", "UNICODE_STRING"):
        return STRING_TYPES.get(n, n), bits
    return None


def by_bits(bits: int) -> str:
    """The unsigned type that holds ``bits`` (an unknown type of that size)."""
    if bits <= 1:
        return "BOOLEAN"
    for b, t in ((8, "UNSIGNED8"), (16, "UNSIGNED16"), (24, "UNSIGNED24"), (32, "UNSIGNED32")):
        if bits <= b:
            return t
    return "UNSIGNED64"


def pdo_entry_type(name: str, bits: int) -> str:
    """The OD type of a PDO entry's <DataType> (any size: unknown names go by bits)."""
    bt = base_type(name, bits) if name else None
    if bt is None or bt[0] not in DATA_TYPES:
        return by_bits(bits)
    return bt[0]

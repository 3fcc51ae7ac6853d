"""PDO mapping values for tests that go over every mapping a device allows.
Ref: TMC8670 §5.1.15-5.1.16 (PDO mapping objects 1600h/1A00h: up to 9 entries, 256 bits)."""

from __future__ import annotations

from ecatsim.slave.od import ObjectDictionary


def every_mapping(od: ObjectDictionary, rx: bool) -> list[list[int]]:
    """Mapping values covering every entry the direction may map, at every length it
    allows, with 8- and 16-bit padding between them: chunks of at most 9 entries and 256
    bits (the TMC8670's limits)."""
    values = []
    for index in sorted(od.objects):
        for e in od.objects[index].entries.values():
            if e.pdo and not (rx and e.access == "ro"):
                values += [index << 16 | e.sub << 8 | bits for bits in (e.bits, *e.pdo_bits)]
    values.insert(3, 0x0000_0008)
    values.insert(7, 0x0000_0010)
    chunks: list[list[int]] = []
    chunk: list[int] = []
    size = 0
    for v in values + values[::-1]:
        if len(chunk) == 9 or size + (v & 0xFF) > 256:
            chunks.append(chunk)
            chunk, size = [], 0
        chunk.append(v)
        size += v & 0xFF
    return [*chunks, chunk]


def set_mapping(od: ObjectDictionary, index: int, mapping: list[int]) -> None:
    """Write ``mapping`` into the mapping object ``index`` as a master does: subindex 0
    to 0, the entries, then subindex 0 to their count."""
    od.set(index, 0, 0)
    for sub, value in enumerate(mapping, 1):
        od.set(index, sub, value)
    od.set(index, 0, len(mapping))

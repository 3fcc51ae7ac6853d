"""Golden mailbox exchanges: exact CoE/SDO/EMCY/mailbox-error bytes, in process.

Ref: ETG.1000.4 §5.6 (mailbox); ETG.1000.6 §5.6 (CoE, SDO, SDO Info, EMCY).
"""

from __future__ import annotations

import struct

import pytest

from ecatsim.slave.firmware import Firmware
from tests.support.tinymaster import TinyMaster, firmware_of, segment_of

SDO_REQ = struct.pack("<H", 2 << 12)


def preop(tx_len: int = 128) -> tuple[TinyMaster, Firmware]:
    seg, _ = segment_of(1, device="tmc8670")
    m = TinyMaster(seg)
    m.apwr(0, 0x0800, struct.pack("<HHBBBB", 0x1000, 128, 0x26, 0, 1, 0))
    m.apwr(0, 0x0808, struct.pack("<HHBBBB", 0x1080, tx_len, 0x22, 0, 1, 0))
    m.apwr(0, 0x0120, b"\x02\x00")
    assert m.aprd(0, 0x0130, 1).data == b"\x02"
    fw = firmware_of(seg)
    return m, fw


def send(m: TinyMaster, data: bytes, counter: int, mtype: int = 3, channel: int = 0) -> None:
    frame = struct.pack("<HHBB", len(data), 0, channel, mtype | (counter << 4)) + data
    assert m.apwr(0, 0x1000, frame.ljust(128, b"\x00")).wkc == 1


def recv(m: TinyMaster, size: int = 128) -> bytes | None:
    r = m.aprd(0, 0x1080, size)
    return r.data if r.wkc else None


def test_expedited_upload_exact_bytes() -> None:
    m, _ = preop()
    send(m, SDO_REQ + struct.pack("<BHBI", 0x40, 0x1018, 1, 0), 1)
    r = recv(m)
    assert r is not None
    assert r[:16] == bytes.fromhex("0a00 0000 0013 0030 4318 1001 8602 0000".replace(" ", ""))
    assert recv(m) is None  # read once: the mailbox is empty again


def test_normal_upload_of_device_name() -> None:
    m, _ = preop()
    send(m, SDO_REQ + struct.pack("<BHBI", 0x40, 0x1008, 0, 0), 1)
    r = recv(m)
    assert r is not None
    length = struct.unpack_from("<H", r)[0]
    assert length == 2 + 8 + 7
    assert r[8] == 0x41 and struct.unpack_from("<I", r, 12)[0] == 7 and r[16:23] == b"TMC8670"


def test_segmented_download_toggle_error() -> None:
    m, _ = preop()
    new = struct.pack("<H3I", 3, 0x60400010, 0x607A0020, 0x60FF0020)
    send(m, SDO_REQ + struct.pack("<BHBI", 0x21 | 0x10, 0x1600, 0, len(new)) + new[:4], 1)
    r = recv(m)
    assert r is not None and r[8] == 0x60
    seg = bytes([0x10]) + new[4:11]  # toggle 1 where 0 is expected
    send(m, SDO_REQ + seg, 2)
    r = recv(m)
    assert r is not None and r[8] == 0x80 and struct.unpack_from("<I", r, 12)[0] == 0x05030000


def test_segmented_download_complete_access() -> None:
    m, fw = preop()
    new = struct.pack("<H3I", 3, 0x60400010, 0x607A0020, 0x60FF0020)
    send(m, SDO_REQ + struct.pack("<BHBI", 0x21 | 0x10, 0x1600, 0, len(new)) + new[:4], 1)
    assert recv(m) is not None
    send(m, SDO_REQ + bytes([0x00]) + new[4:11], 2)
    assert (r := recv(m)) is not None and r[8] == 0x20
    last = new[11:]
    send(m, SDO_REQ + bytes([0x10 | ((7 - len(last)) << 1) | 1]) + last.ljust(7, b"\0"), 3)
    assert (r := recv(m)) is not None and r[8] == 0x30
    assert fw.od is not None and fw.od.value(0x1600, 0) == 3
    assert fw.od.value(0x1600, 3) == 0x60FF0020


def test_write_only_bad_command_and_mailbox_errors() -> None:
    m, _ = preop()
    send(m, SDO_REQ + struct.pack("<BHBI", 0xE0, 0x1000, 0, 0), 1)
    assert (r := recv(m)) is not None and struct.unpack_from("<I", r, 12)[0] == 0x05040001
    cases = [
        (dict(mtype=2), 0x0002),  # EoE: unsupported protocol
        (dict(channel=1), 0x0003),  # invalid channel
        (dict(mtype=0), 0x0001),  # syntax: an error reply sent to the slave
    ]
    counter = 2
    for kw, code in cases:
        send(m, SDO_REQ + bytes(8), counter, **kw)
        counter += 1
        r = recv(m)
        assert r is not None and r[5] & 0x0F == 0 and struct.unpack_from("<HH", r, 6) == (1, code)
    send(m, struct.pack("<H", 4 << 12) + bytes(8), counter)  # CoE TxPDO service
    r = recv(m)
    assert r is not None and struct.unpack_from("<HH", r, 6) == (1, 0x0004)
    frame = struct.pack("<HHBB", 1, 0, 0, 3 | (6 << 4)) + b"\x00"
    m.apwr(0, 0x1000, frame.ljust(128, b"\x00"))
    r = recv(m)
    assert r is not None and struct.unpack_from("<HH", r, 6) == (1, 0x0006)  # size too short
    frame = struct.pack("<HHBB", 200, 0, 0, 3 | (7 << 4))
    m.apwr(0, 0x1000, frame.ljust(128, b"\x00"))
    r = recv(m)
    assert r is not None and struct.unpack_from("<HH", r, 6) == (1, 0x0008)  # invalid size


def test_duplicate_counter_is_ignored() -> None:
    m, _ = preop()
    req = SDO_REQ + struct.pack("<BHBI", 0x40, 0x1000, 0, 0)
    send(m, req, 3)
    assert recv(m) is not None
    send(m, req, 3)  # same counter: a repeated mailbox, not served again
    assert recv(m) is None
    send(m, req, 4)
    assert recv(m) is not None


def test_emergency_updates_error_objects() -> None:
    m, fw = preop()
    assert fw.emergency is not None and fw.od is not None
    fw.emergency.raise_error(0x2310, 0x02, b"\x01")
    m.seg.service()
    r = recv(m)
    assert r is not None
    assert r[5] & 0x0F == 3 and struct.unpack_from("<H", r, 6)[0] >> 12 == 1
    assert r[8:16] == bytes([0x10, 0x23, 0x03, 0x01, 0, 0, 0, 0])
    assert fw.od.value(0x1001) == 0x03
    if 0x603F in fw.od:
        assert fw.od.value(0x603F) == 0x2310


SDO_INFO_REQ = struct.pack("<H", 8 << 12)


def object_description(index: int) -> bytes:
    """The whole reply mailbox to SDO Info "get object description" for ``index``."""
    m, _ = preop()
    send(m, SDO_INFO_REQ + struct.pack("<BBHH", 0x03, 0, 0, index), 1)
    r = recv(m)
    assert r is not None
    return r[: 6 + struct.unpack_from("<H", r)[0]]


def test_sdo_info_object_description_of_identity_exact_bytes() -> None:
    """0x1018 is the IDENTITY record, data type 0x0023 (CiA 301 §7.4.4; ETG.1000.6 §5.6.3.5
    Table 48: index, data type, max subindex, object code, name)."""
    assert object_description(0x1018) == bytes.fromhex(
        "1b00 0000 0013"  # mailbox: 27 bytes, CoE, counter 1
        "0080 0400 0000"  # CoE SDO Info, get object description response, no fragments left
        "1810 2300 03 09"  # 0x1018, IDENTITY, max subindex 3, RECORD
        "4964656e74697479206f626a656374"  # "Identity object"
    )


@pytest.mark.parametrize(
    ("index", "data_type", "max_sub", "code", "name"),
    [
        (0x1600, 0x0021, 9, 9, b"Receive PDO mapping"),  # PDO_MAPPING record
        (0x1A00, 0x0021, 9, 9, b"Transmit PDO mapping"),
        (0x1C12, 0x0006, 1, 8, b"Sync manager 2 PDO assignment"),  # ARRAY of UNSIGNED16
        (0x1C13, 0x0006, 1, 8, b"Sync manager 3 PDO assignment"),
        (0x1C00, 0x0005, 4, 8, b"Sync manager communication type"),  # ARRAY of UNSIGNED8
        (0x1008, 0x0009, 0, 7, b"Manufacturer device name"),  # VAR: its own type
    ],
)
def test_sdo_info_object_description_types(
    index: int, data_type: int, max_sub: int, code: int, name: bytes
) -> None:
    """The object's data type: a record's standard type, an array's element type.
    Ref: ETG.1000.6 §5.6.3.5 Table 48, §5.6.7.4 (1C00, 1C12, 1C13); CiA 301 §7.4.4."""
    body = struct.pack("<HHBB", index, data_type, max_sub, code) + name
    head = struct.pack("<HHBB", 6 + len(body), 0, 0, 0x13)
    assert object_description(index) == head + bytes.fromhex("0080 0400 0000") + body

"""The SII read loop exactly as KickCAT 2.5 runs it at its INIT scan, byte for byte.

KickCAT reads the SII two words at a time: a BWR of 6 bytes to 0x0502 (read command 0x0100,
the word address, 0x0000) whose WKC must equal the slave count, then (after 200 us) an FPRD
of 2 bytes of 0x0502 repeated while the busy bit 15 is set (10 tries), then an FPRD of 4 bytes
of 0x0508 whose WKC must be 1. It stops after more than 32 double words, at the first one
holding 0xFFFF (the end category) in either half. Any other answer ends its scan with
"Invalid working counter", "Timeout" or "Error while fetching eeprom data".
Ref: TMC8460 §5.45 Tables 59-65; ETG.1000.4 §5.4 (WKC); ETG.2010 §2 (SII layout).
"""

from __future__ import annotations

import struct

from tests.support.tinymaster import TinyMaster, segment_of

STATION = 0x03E9  # the first station address KickCAT gives (1001)
BUSY = 0x8000
ERROR_BITS = 0x7800  # ack/command error, write-enable error, checksum error, not loaded
END = 0xFFFF


def test_kickcat_sii_read_loop_gets_every_word_at_once() -> None:
    seg, _ = segment_of(1, device="tmc8670")
    m = TinyMaster(seg)
    image = bytes(seg.escs[0].eeprom.image)
    assert m.bwr(0x0500, b"\x00\x00").wkc == 1  # "eeprom to master"
    assert m.apwr(0, 0x0010, struct.pack("<H", STATION)).wkc == 1
    dwords: list[int] = []
    pos = 0
    while True:
        req = struct.pack("<HHH", 0x0100, pos, 0)
        w = m.bwr(0x0502, req)
        assert (w.wkc, w.data) == (1, req)
        st = m.fprd(STATION, 0x0502, 2)
        assert st.wkc == 1
        (status,) = struct.unpack("<H", st.data)
        assert status & (BUSY | ERROR_BITS) == 0, hex(status)
        assert status == 0x0080  # 32 kbit: two address bytes, done at the first look
        d = m.fprd(STATION, 0x0508, 4)
        assert d.wkc == 1
        assert d.data == image[2 * pos : 2 * pos + 4], pos
        (word,) = struct.unpack("<I", d.data)
        dwords.append(word)
        pos += 2
        if len(dwords) > 32 and (word >> 16 == END or word & END == END):
            break
        assert 2 * pos < len(image), "no end category: KickCAT would read on forever"
    # the loop ends at the end category, the last thing the SII image holds
    assert image[2 * pos - 4 : 2 * pos].find(b"\xff\xff") in (0, 2)

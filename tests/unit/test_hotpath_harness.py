"""The in-process DC cycle of tests/perf/hotpath.py (``CspCycle``, which
tools/cycle_profile.py and tools/icount.sh time) sends a cycle's process data as a master
does: in frames of at most 1514 bytes, cut where SOEM's config_map cuts its IO map.

Ref: ETG.1000.4 §5.2 (frame size); docs/performance.md "How to measure".
"""

from __future__ import annotations

import itertools
import struct

from ecatsim.wire import datagram as dg
from tests.perf.hotpath import IN, MAX_LRW, OUT, CspCycle, segments


def test_the_image_is_cut_where_soem_cuts_it() -> None:
    # the LRWs' logical addresses SOEM sent in the bench's captures: pysoem at 128 drives
    # (0x5B8, 0xB83), red_test at 199 (0x5B8, 0xB85, 0x114C)
    assert segments(128) == [(0, 0x5B8), (0x5B8, 0xB83), (0xB83, 128 * (OUT + IN))]
    assert [a for a, _ in segments(199)] == [0, 0x5B8, 0xB85, 0x114C]
    assert segments(50) == [(0, 50 * (OUT + IN))]  # one frame, the FRMW behind its LRW
    for n in (1, 51, 64, 199, 512):
        cuts = segments(n)
        assert cuts[0][0] == 0 and cuts[-1][1] == n * (OUT + IN)
        assert all(b == c for (_, b), (c, _) in itertools.pairwise(cuts))
        assert cuts[0][1] <= MAX_LRW - 20 and all(b - a <= MAX_LRW for a, b in cuts[1:])


def test_a_cycle_of_64_drives_is_two_frames_each_answered_in_full() -> None:
    c = CspCycle(64)
    frames = c.frames(0x0F)
    assert [len(f) for f in frames] == [14 + 2 + 10 + 1465 + 2 + 10 + 8 + 2, 14 + 2 + 10 + 391 + 2]
    replies = c.exchange()
    assert len(replies) == sum(len(f) for f in frames)
    first, second = replies[: len(frames[0])], replies[len(frames[0]) :]
    wkc = 14 + 2 + 10 + 1465
    # the first LRW: 64 output blocks written (2 each) and 41 input blocks read (1 each);
    # the FRMW: the reference read and 63 writers; the second LRW: 23 input blocks read
    assert struct.unpack_from("<H", first, wkc)[0] == 64 * 2 + 41
    assert struct.unpack_from("<H", first, wkc + 2 + 10 + 8)[0] == 64
    assert struct.unpack_from("<H", second, 14 + 2 + 10 + 391)[0] == 23
    # the inputs of drive 0 (in the first frame) and drive 63 (in the second): statusword
    # of an enabled drive (0x37 in the low byte)
    assert first[14 + 2 + 10 + 64 * OUT] & 0x6F == 0x27
    assert second[14 + 2 + 10 + 391 - IN] & 0x6F == 0x27
    assert frames[1][16] == dg.Cmd.LRW

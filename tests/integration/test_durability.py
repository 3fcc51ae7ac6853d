"""EEPROM write-back survives kill -9 at any moment: the image file is always the old or the
new one, never torn. Ref: issue "durability"; ecatsim/files.py (atomic replace)."""

from __future__ import annotations

import random
import signal
import struct
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from ecatsim.sii.crc import crc8

pytestmark = pytest.mark.integration
WORDS = range(0x20, 0x38)


def value(round_: int, word: int) -> int:
    return (round_ * 0x1000 + word * 7) & 0xFFFF


def check_image(path: Path, rounds_done: int) -> None:
    img = path.read_bytes()
    assert len(img) == 4096
    assert crc8(img[:14]) == img[14]
    words = [struct.unpack_from("<H", img, w * 2)[0] for w in WORDS]
    # the file is the state after some prefix of the writes of the current round
    new = [value(rounds_done, w) for w in WORDS]
    old = [value(rounds_done - 1, w) if rounds_done > 1 else 0 for w in WORDS]
    assert any(words == new[:k] + old[k:] for k in range(len(new) + 1)), (
        rounds_done,
        words,
        new,
        old,
    )


def test_kill_minus_nine_during_eeprom_writes(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    image = tmp_path / "drive.bin"
    cfg = tmp_path / "seg.yaml"
    cfg.write_text(f"slaves:\n  - device: tmc8670\n    eeprom: {image}\n")
    daemon = daemon_factory("--config", str(cfg))
    rng = random.Random(5)
    for round_ in range(1, 6):
        master = master_factory()
        assert master.config_init() == 1
        s = master.slaves[0]
        kill_at = rng.uniform(0.002, 0.05)
        proc = daemon.proc
        assert proc is not None
        killer = threading.Timer(kill_at, lambda p=proc: p.send_signal(signal.SIGKILL))
        killer.start()
        try:
            for w in WORDS:
                s.eeprom_write(w, struct.pack("<H", value(round_, w)), 20_000)
        except Exception:
            pass  # the daemon died under the master's feet: expected
        killer.join()
        proc.wait(5)
        master.close()
        check_image(image, round_)
        # bring the words to the full new round so the next round's "old" is known
        daemon.start()
        master = master_factory()
        assert master.config_init() == 1
        for w in WORDS:
            master.slaves[0].eeprom_write(w, struct.pack("<H", value(round_, w)), 50_000)
        time.sleep(0.1)
        check_image(image, round_)
        master.close()

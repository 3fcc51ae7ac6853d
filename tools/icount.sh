#!/usr/bin/env bash
# Instructions per DC cycle, counted by callgrind: the difference between a run of 600 and a
# run of 100 cycles of tools/cycle_profile.py, divided by 500 (set-up cost cancels out).
# Repeatable to a fraction of a percent whatever else the machine does (a few per cent with
# --responder, whose wait depends on the time); wall time is not.
#   tools/icount.sh DRIVES [cycle_profile options]     e.g.  tools/icount.sh 16 --idle
#
# --cold: what a cyclic frame misses when it arrives to cold caches, as on a CPU shared with
# the master: callgrind's cache simulation (L1 32/48 KiB, L2 2 MiB, this machine's sizes)
# over the responder's per-frame work (the wait's return, the walk, the reply, the work
# after it), 4 MiB read between frames (cycle_profile.py --responder --evict 4); per frame
# the instructions and the code and data lines missed in L2, each a trip to L3 or memory.
#   tools/icount.sh 1 --cold                 Ref: docs/performance.md (target 1)
#
# --footprint: what a whole DC cycle (the SYNC0 pulse, the drives' work, the frame) reads
# from memory when it finds every cache cold, as a daemon that slept while the master and
# the host ran: the same cache simulation over the whole process, 8 MiB written (memset)
# before each cycle (cycle_profile.py --cold-cycle 8), the difference of 150 and 50 cycles
# over 100; per cycle the data lines and the code lines missed in L2 (the memset's own
# 131 072 written lines taken off).
#   tools/icount.sh 64 --footprint --hold    Ref: docs/performance.md (targets 9-11)
set -euo pipefail
cd "$(dirname "$0")/.."
drives="${1:-1}"; shift || true
cold=0
footprint=0
extra=()
for a in "$@"; do
    case "$a" in
        --cold) cold=1 ;;
        --footprint) footprint=1 ;;
        *) extra+=("$a") ;;
    esac
done
vg=(valgrind --tool=callgrind)
if [ "$cold" -eq 1 ] || [ "$footprint" -eq 1 ]; then
    vg+=(--cache-sim=yes --I1=32768,8,64 --D1=49152,12,64 --LL=2097152,16,64)
fi
if [ "$footprint" -eq 1 ]; then
    extra+=(--responder --cold-cycle 8)
fi
if [ "$cold" -eq 1 ]; then
    for f in wait_frame answer after; do
        vg+=("--toggle-collect=__pyx_f_7ecatsim_8ethercat_9responder_9Responder_$f")
    done
    extra+=(--responder --evict 4)
fi
count() {
    local out; out=$(mktemp)
    # a fixed hash seed: the start-up's dict lookups land alike in both runs
    PYTHONHASHSEED=0 "${vg[@]}" --callgrind-out-file="$out" .venv/bin/python \
        tools/cycle_profile.py --drives "$drives" --cycles "$1" "${extra[@]}" >/dev/null 2>&1
    # events: Ir [Dr Dw I1mr D1mr D1mw ILmr DLmr DLmw]
    grep -m1 '^summary:\|^totals:' "$out" | awk '{print $2, $8 + 0, $9 + $10}'
    rm -f "$out"
}
if [ "$footprint" -eq 1 ]; then
    read -r ia ca da <<<"$(count 50)"
    read -r ib cb db <<<"$(count 150)"
    # the memset's 8 MiB: 131 072 lines written each cycle, each a miss
    echo "$drives drives ${extra[*]}: per cycle $(( (cb - ca) / 100 )) code lines and" \
        "$(( (db - da) / 100 - 131072 )) data lines read from memory (missed in L2)"
    exit 0
fi
read -r ia ca da <<<"$(count 100)"
read -r ib cb db <<<"$(count 600)"
if [ "$cold" -eq 1 ]; then
    echo "$drives drives ${extra[*]}: per frame $(( (ib - ia) / 500 )) instructions," \
        "$(( (cb - ca) / 500 )) code lines and $(( (db - da) / 500 )) data lines missed in L2"
else
    echo "$drives drives ${extra[*]}: $(( (ib - ia) / 500 )) instructions per cycle"
fi

#!/usr/bin/env bash
# Code and data a cyclic frame misses in the L2 cache when it arrives to cold caches, as it
# does on a CPU shared with the master: callgrind's cache simulation (L1 32/48 KiB, L2 2 MiB,
# the machine's sizes) over the responder's per-frame work (the wait's return, the walk, the
# reply, the work after it), with 4 MiB read between frames (tools/cycle_profile.py
# --evict 4). Per frame: the difference between a run of 300 and of 100 cycles, / 200.
# Each missed line is a trip to the L3 cache or memory; the count, unlike wall time, does not
# move with the machine's load. Ref: docs/performance.md (target 1).
#   tools/coldmiss.sh DRIVES [cycle_profile options]      e.g.  tools/coldmiss.sh 1
set -euo pipefail
cd "$(dirname "$0")/.."
drives="${1:-1}"; shift || true
extra=("$@")
count() {
    local out; out=$(mktemp)
    valgrind --tool=callgrind --cache-sim=yes --I1=32768,8,64 --D1=49152,12,64 \
        --LL=2097152,16,64 --callgrind-out-file="$out" \
        --toggle-collect='__pyx_f_7ecatsim_9responder_9Responder_wait_frame' \
        --toggle-collect='__pyx_f_7ecatsim_9responder_9Responder_answer' \
        --toggle-collect='__pyx_f_7ecatsim_9responder_9Responder_after' \
        .venv/bin/python tools/cycle_profile.py --drives "$drives" --cycles "$1" --responder \
        --evict 4 "${extra[@]}" >/dev/null 2>&1
    # events: Ir Dr Dw I1mr D1mr D1mw ILmr DLmr DLmw
    grep -m1 '^summary:\|^totals:' "$out" | awk '{print $2, $8, $9 + $10}'
    rm -f "$out"
}
read -r ia ca da <<<"$(count 100)"
read -r ib cb db <<<"$(count 300)"
echo "$drives drives ${extra[*]}: per frame $(( (ib - ia) / 200 )) instructions," \
    "$(( (cb - ca) / 200 )) code lines and $(( (db - da) / 200 )) data lines missed in L2"

#!/usr/bin/env bash
# Instructions per DC cycle, counted by callgrind: the difference between a run of 600 and a
# run of 100 cycles of tools/cycle_profile.py, divided by 500 (set-up cost cancels out).
# Repeatable to a fraction of a percent whatever else the machine does; wall time is not.
#   tools/icount.sh DRIVES [cycle_profile options]     e.g.  tools/icount.sh 16 --idle
set -euo pipefail
cd "$(dirname "$0")/.."
drives="${1:-1}"; shift || true
extra=("$@")
count() {
    local out; out=$(mktemp)
    valgrind --tool=callgrind --callgrind-out-file="$out" .venv/bin/python \
        tools/cycle_profile.py --drives "$drives" --cycles "$1" "${extra[@]}" >/dev/null 2>&1
    grep -m1 '^summary:\|^totals:' "$out" | awk '{print $2}'
    rm -f "$out"
}
a=$(count 100)
b=$(count 600)
echo "$drives drives ${extra[*]}: $(( (b - a) / 500 )) instructions per cycle"

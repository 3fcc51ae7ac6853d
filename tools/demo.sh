#!/usr/bin/env bash
# The main job on the embedded default: venv + pinned deps, a veth pair, the daemon on one
# end and the demo master on the other. Needs root (veth, raw sockets).
#   sudo tools/demo.sh            # one TMC8670 drive
#   sudo tools/demo.sh --slaves 4
set -euo pipefail
cd "$(dirname "$0")/.."
MASTER_IF=${ECATSIM_MASTER_IF:-ecat0}
SLAVE_IF=${ECATSIM_SLAVE_IF:-ecat1}

if [ "$(id -u)" != 0 ]; then
    echo "demo: needs root for the veth pair and raw sockets: sudo $0 $*" >&2
    exit 2
fi
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
.venv/bin/python -m pip install --quiet --disable-pip-version-check -r requirements-test.lock
.venv/bin/python -m pip install --quiet --disable-pip-version-check --no-deps -e .

if ! ip link show "$MASTER_IF" >/dev/null 2>&1; then
    ip link add "$MASTER_IF" type veth peer name "$SLAVE_IF"
fi
ip link set "$MASTER_IF" up
ip link set "$SLAVE_IF" up

OUT=${ECATSIM_DEMO_OUT:-demo-out}
mkdir -p "$OUT"
LOG="$OUT/daemon.log"
.venv/bin/ecatsim run --iface "$SLAVE_IF" --rt-priority 40 --trace "$OUT/trace.csv" "$@" \
    >"$LOG" 2>&1 &
DAEMON=$!
trap 'kill $DAEMON 2>/dev/null || true; wait $DAEMON 2>/dev/null || true' EXIT
for _ in $(seq 100); do
    grep -q ready "$LOG" && break
    kill -0 $DAEMON 2>/dev/null || { cat "$LOG"; exit 1; }
    sleep 0.05
done
echo "daemon on $SLAVE_IF (log: $LOG); demo master on $MASTER_IF"
.venv/bin/python tools/demo_master.py --iface "$MASTER_IF"
kill "$DAEMON"; wait "$DAEMON" 2>/dev/null || true
trap - EXIT
.venv/bin/ecatsim plot "$OUT/trace.csv" -o "$OUT/plot.png"

#!/usr/bin/env bash
# The main job on the embedded default: venv + pinned deps, a veth pair, the daemon on one
# end and the demo master on the other. Needs root (veth, raw sockets): run it as root, or
# as a user with sudo (it asks for it).
#   tools/demo.sh                 # one TMC8670 drive
#   tools/demo.sh --slaves 4
#   tools/demo.sh --mfcio         # a TMC8460 MFCIO slave beside the drive (demo_mfcio.py);
#                                 # the plot shows its stepper: steps, position, encoder
#   ECATSIM_KEEP_LINKS=1 tools/demo.sh   # leave the veth pair up afterwards
# A veth pair the demo creates is removed on exit; one that existed before is left as it was
# found (the master's promiscuous mode switched off again).
set -euo pipefail
cd "$(dirname "$0")/.."
MASTER_IF=${ECATSIM_MASTER_IF:-ecat0}
SLAVE_IF=${ECATSIM_SLAVE_IF:-ecat1}

if [ "$(id -u)" != 0 ]; then
    if command -v sudo >/dev/null; then
        exec sudo --preserve-env=ECATSIM_MASTER_IF,ECATSIM_SLAVE_IF,ECATSIM_KEEP_LINKS,ECATSIM_DEMO_OUT \
            "$0" "$@"
    fi
    echo "demo: needs root for the veth pair and raw sockets (and sudo is not installed)" >&2
    exit 2
fi
tools/ensure-venv.sh

created=0
if ! ip link show "$MASTER_IF" >/dev/null 2>&1; then
    ip link add "$MASTER_IF" type veth peer name "$SLAVE_IF"
    created=1
fi
ip link set "$MASTER_IF" up
ip link set "$SLAVE_IF" up

DAEMON=
cleanup() {
    if [ -n "$DAEMON" ]; then
        kill "$DAEMON" 2>/dev/null || true
        wait "$DAEMON" 2>/dev/null || true
    fi
    if [ "${ECATSIM_KEEP_LINKS:-0}" = 1 ]; then
        echo "demo: leaving $MASTER_IF/$SLAVE_IF up (ECATSIM_KEEP_LINKS=1)"
    elif [ "$created" = 1 ]; then
        ip link del "$MASTER_IF" 2>/dev/null || true
    else
        ip link set "$MASTER_IF" promisc off 2>/dev/null || true
        ip link set "$SLAVE_IF" promisc off 2>/dev/null || true
    fi
}
trap cleanup EXIT

MASTER=tools/demo_master.py
PLOT_FROM=trace.csv # the drive's trace; --mfcio: the stepper's (FILE.mfcio.csv)
if [ "${1:-}" = "--mfcio" ]; then
    shift
    set -- --config config/tmc8460-beside-tmc8670.yaml "$@"
    MASTER=tools/demo_mfcio.py
    PLOT_FROM=trace.mfcio.csv
fi

OUT=${ECATSIM_DEMO_OUT:-demo-out}
mkdir -p "$OUT"
LOG="$OUT/daemon.log"
.venv/bin/ecatsim run --iface "$SLAVE_IF" --rt-priority 40 --trace "$OUT/trace.csv" "$@" \
    >"$LOG" 2>&1 &
DAEMON=$!
for _ in $(seq 100); do
    grep -q ready "$LOG" && break
    kill -0 "$DAEMON" 2>/dev/null || { cat "$LOG"; exit 1; }
    sleep 0.05
done
echo "daemon on $SLAVE_IF (log: $LOG); demo master on $MASTER_IF"
.venv/bin/python "$MASTER" --iface "$MASTER_IF"
kill "$DAEMON"
wait "$DAEMON" 2>/dev/null || true
DAEMON=
.venv/bin/ecatsim plot "$OUT/$PLOT_FROM" -o "$OUT/plot.png"

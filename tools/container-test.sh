#!/usr/bin/env bash
# Build the ecatsim image from the Dockerfile and bring its slave to OP with a real master.
#
#   sudo tools/container-test.sh
#   sudo tools/container-test.sh --base-only   # step 1 only: the base image the Dockerfile
#                                              # uses by default, then exit
#
# 1. Base image: docker.io/library/python:3.11-slim only if ECATSIM_TRY_REGISTRY=1 and the
#    pull works; otherwise a local Debian bookworm image, localhost/ecatsim-base:bookworm,
#    made with debootstrap (mirror: DEBIAN_MIRROR) and kept for the next run.
# 2. The project image, localhost/ecatsim:test, built with the same Dockerfile; it prints
#    the core the image runs (`ecatsim --version`: core: compiled) and the image's size.
# 3. Two private network namespaces joined by a veth pair; the container runs
#    `ecatsim run --iface <slave end>` in the slave namespace (podman --network ns:PATH)
#    and tools/container_master.py (pysoem, the project's .venv) drives it to OP from the
#    master namespace. The daemon must then stop cleanly (exit 0) on SIGTERM.
#
# Needs root (debootstrap, ip netns, raw sockets) and podman (or docker). Exit 0: the slave
# reached OP; 77: no working container engine; anything else: a failure. The container and
# both namespaces are removed on exit, also after a failure.
set -euo pipefail
cd "$(dirname "$0")/.."
REPO=$(pwd)
BASE_ONLY=0
case "${1:-}" in
--base-only) BASE_ONLY=1 ;;
"") ;;
*)
    echo "usage: $0 [--base-only]" >&2
    exit 2
    ;;
esac

REGISTRY_BASE=docker.io/library/python:3.11-slim
LOCAL_BASE=localhost/ecatsim-base:bookworm
IMAGE=localhost/ecatsim:test
MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
PY="$REPO/.venv/bin/python"
MASTER_NS="ecs-ct-m-$$"
SLAVE_NS="ecs-ct-s-$$"
MASTER_IF="vcm$$"
SLAVE_IF="vcs$$"
CONTAINER="ecatsim-ct-$$"
READY_TIMEOUT=30

say() { echo "container-test: $*"; }
die() {
    echo "container-test: $*" >&2
    exit 1
}

if [ "$(id -u)" != 0 ]; then
    echo "container-test: needs root (debootstrap, network namespaces, raw sockets): sudo $0" >&2
    exit 2
fi

CT=""
for c in podman docker; do
    if command -v "$c" >/dev/null 2>&1 && "$c" info >/dev/null 2>&1; then
        CT=$c
        break
    fi
done
if [ -z "$CT" ]; then
    echo "container-test: skipped: neither podman nor docker works here" >&2
    exit 77
fi
[ -x "$PY" ] || [ "$BASE_ONLY" = 1 ] || die "no project venv at $PY: python3 -m venv .venv && .venv/bin/pip install -r requirements-test.lock && .venv/bin/pip install --no-deps -e ."

# Engine options for hosts that are containers themselves (e.g. CI sandboxes):
# - crun refuses to run anything when cgroup v1 and v2 are mixed ("hybrid") and v2 has a
#   controller enabled; runc copes, so use it there.
# - without CAP_SYS_RESOURCE a root podman cannot raise the container's RLIMIT_NOFILE and
#   RLIMIT_NPROC to its defaults (2^20): ask for modest limits instead (ample for one daemon).
CT_OPTS=()
LIMITS=()
if [ "$CT" = podman ]; then
    controllers=$(cat /sys/fs/cgroup/unified/cgroup.controllers 2>/dev/null || true)
    runtime=$(podman info --format '{{.Host.OCIRuntime.Name}}' 2>/dev/null || true)
    if [ "$(stat -fc %T /sys/fs/cgroup)" = tmpfs ] && [ -n "$controllers" ] &&
        [ "$runtime" = crun ]; then
        command -v runc >/dev/null 2>&1 ||
            die "crun cannot run containers with hybrid cgroups here: apt-get install runc"
        CT_OPTS=(--runtime runc)
    fi
    capeff=$(awk '/^CapEff:/ { print $2 }' /proc/self/status)
    if ((((16#$capeff >> 24) & 1) == 0)); then # no CAP_SYS_RESOURCE
        nofile=$(ulimit -Hn)
        if [ "$nofile" = unlimited ] || [ "$nofile" -gt 65536 ]; then nofile=65536; fi
        nproc=$(ulimit -Hu)
        if [ "$nproc" = unlimited ] || [ "$nproc" -gt 4096 ]; then nproc=4096; fi
        LIMITS=(--ulimit "nofile=$nofile:$nofile" --ulimit "nproc=$nproc:$nproc")
    fi
fi
ct() { "$CT" "${CT_OPTS[@]}" "$@"; }

ROOTFS=""
DAEMON_LOG=""
CHILD=""
BUILD_BEFORE="" # set while podman builds: the buildah containers that existed before
working_containers() { podman ps -a --external --format '{{.ID}} {{.Names}}' | sort; }
# Long steps run as their own process group in the background, so that a signal to this
# script is handled at once (bash runs traps only between foreground commands) and the
# cleanup can stop the step before it removes what the step works on.
bg_run() {
    setsid "$@" &
    CHILD=$!
    local rc=0
    wait "$CHILD" || rc=$?
    CHILD=""
    return "$rc"
}
cleanup() {
    local rc=$?
    set +e
    if [ -n "$CHILD" ]; then
        # SIGTERM to the step itself, then to its whole group, then SIGKILL; a zombie
        # (stat Z) has ended
        for target in "$CHILD" "-$CHILD"; do
            kill -TERM -- "$target" 2>/dev/null
            for _ in $(seq 25); do
                ps -o stat= -p "$CHILD" | grep -qv '^Z' || break 2
                sleep 0.2
            done
        done
        kill -KILL -- "-$CHILD" 2>/dev/null
        wait "$CHILD" 2>/dev/null
    fi
    if [ -n "$BUILD_BEFORE" ]; then
        # an interrupted podman build leaves its buildah working containers behind
        comm -13 <(echo "$BUILD_BEFORE") <(working_containers) |
            awk '$2 ~ /-working-container$/ { print $1 }' |
            while read -r id; do podman rm -f "$id" >/dev/null 2>&1; done
    fi
    if [ -n "$CT" ] && "$CT" container inspect "$CONTAINER" >/dev/null 2>&1; then
        if [ "$rc" != 0 ]; then
            echo "--- container log ($CONTAINER)" >&2
            "$CT" logs "$CONTAINER" >&2 2>&1
        fi
        ct stop -t 5 "$CONTAINER" >/dev/null 2>&1
        ct rm -f "$CONTAINER" >/dev/null 2>&1
    fi
    for ns in "$MASTER_NS" "$SLAVE_NS"; do
        if [ -e "/run/netns/$ns" ]; then
            ip netns del "$ns"
        fi
    done
    if [ -n "$ROOTFS" ] && [ -d "$ROOTFS" ]; then
        # debootstrap may leave proc/sys mounted inside the rootfs when it fails
        awk -v d="$ROOTFS/" 'index($2, d) == 1 { print $2 }' /proc/mounts | sort -r |
            while read -r m; do umount -l "$m"; done
        rm -rf --one-file-system "$ROOTFS" "$ROOTFS.log"
    fi
    [ -n "$DAEMON_LOG" ] && rm -f "$DAEMON_LOG"
    exit "$rc"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

now() { echo "$EPOCHREALTIME"; }
since() { awk -v a="$1" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.1f", b - a }'; }

image_exists() {
    if [ "$CT" = podman ]; then
        podman image exists "$1"
    else
        docker image inspect "$1" >/dev/null 2>&1
    fi
}

# the CA bundle the host's pip trusts
HOST_CA=${PIP_CERT:-${REQUESTS_CA_BUNDLE:-${SSL_CERT_FILE:-/etc/ssl/certs/ca-certificates.crt}}}

T0=$(now)

# --- 1. base image
T=$(now)
BASE=""
if [ "${ECATSIM_TRY_REGISTRY:-0}" = 1 ]; then
    say "base: pulling $REGISTRY_BASE"
    if timeout 300 "$CT" pull "$REGISTRY_BASE"; then
        BASE=$REGISTRY_BASE
    else
        say "base: pull failed, building the local base instead"
    fi
fi
if [ -z "$BASE" ]; then
    BASE=$LOCAL_BASE
    if image_exists "$LOCAL_BASE"; then
        say "base: $LOCAL_BASE (cached)"
    else
        command -v debootstrap >/dev/null 2>&1 || die "debootstrap not found: apt-get install debootstrap"
        ROOTFS=$(mktemp -d /var/tmp/ecatsim-rootfs.XXXXXX)
        say "base: debootstrap bookworm from $MIRROR into $ROOTFS"
        bg_run debootstrap --variant=minbase --include=python3,python3-venv,iproute2 \
            bookworm "$ROOTFS" "$MIRROR" >"$ROOTFS.log" 2>&1 || {
            tail -n 30 "$ROOTFS.log" >&2
            rm -f "$ROOTFS.log"
            die "debootstrap failed"
        }
        rm -f "$ROOTFS.log"
        rm -rf "$ROOTFS"/var/cache/apt/archives/*.deb "$ROOTFS"/var/lib/apt/lists/*
        # pip in the image builds trusts what the host trusts (a TLS-intercepting proxy's
        # CA, say): the host's CA bundle, where it has one, is the base's
        CA_ENV=()
        if [ -f "$HOST_CA" ] && [ -r "$HOST_CA" ]; then
            mkdir -p "$ROOTFS/etc/ssl/certs"
            cp "$(readlink -f "$HOST_CA")" "$ROOTFS/etc/ssl/certs/ca-certificates.crt"
            CA_ENV=(--change 'ENV PIP_CERT=/etc/ssl/certs/ca-certificates.crt')
        fi
        tar -C "$ROOTFS" -c . | "$CT" import "${CA_ENV[@]}" \
            --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
            --change 'ENV LANG=C.UTF-8' \
            --change 'CMD ["/bin/bash"]' \
            - "$LOCAL_BASE" >/dev/null
        rm -rf --one-file-system "$ROOTFS"
        ROOTFS=""
        say "base: imported $LOCAL_BASE"
    fi
fi
T_BASE=$(since "$T")
if [ "$BASE_ONLY" = 1 ]; then
    say "base image $BASE ready (${T_BASE} s)"
    exit 0
fi

# --- 2. project image (pip needs PyPI: host network for the build)
T=$(now)
BUILD_OPTS=(--network host --build-arg "BASE=$BASE")
# pip in the build trusts what the host's pip trusts (a TLS-intercepting proxy's CA, say):
# the bundle is mounted for the RUN steps only and does not end up in the image
if [ -f "$HOST_CA" ] && [ -r "$HOST_CA" ]; then
    BUILD_OPTS+=(-v "$(readlink -f "$HOST_CA"):/run/ecatsim-build-ca.pem:ro"
        --build-arg PIP_CA_BUNDLE=/run/ecatsim-build-ca.pem)
fi
say "build: $IMAGE (BASE=$BASE)"
OLD_IMAGE=$("$CT" image inspect -f '{{.Id}}' "$IMAGE" 2>/dev/null || true)
[ "$CT" = podman ] && BUILD_BEFORE=$( (working_containers; echo .) | sort)
bg_run "$CT" "${CT_OPTS[@]}" build "${LIMITS[@]}" "${BUILD_OPTS[@]}" -t "$IMAGE" . ||
    die "image build failed"
BUILD_BEFORE=""
if [ -n "$OLD_IMAGE" ] && [ "$OLD_IMAGE" != "$("$CT" image inspect -f '{{.Id}}' "$IMAGE")" ]; then
    "$CT" rmi "$OLD_IMAGE" >/dev/null 2>&1 || true # the previous run's image, now untagged
fi
T_BUILD=$(since "$T")
# what the image is: the core it runs (a build stage compiles it) and its size
CORE=$(ct run --rm "${LIMITS[@]}" "$IMAGE" --version | grep '^core: ') ||
    die "ecatsim --version failed in the image"
say "image $CORE"
say "image size $("$CT" image inspect -f '{{.Size}}' "$IMAGE") bytes"

# --- 3. run: container in the slave namespace, pysoem master in the master namespace
T=$(now)
for ns in "$MASTER_NS" "$SLAVE_NS"; do
    ip netns add "$ns"
    # IPv6 off before the veth exists (it inherits 'default'): no router solicitations
    ip netns exec "$ns" sysctl -q -w net.ipv6.conf.default.disable_ipv6=1 \
        net.ipv6.conf.all.disable_ipv6=1 >/dev/null 2>&1 || true
    ip -n "$ns" link set lo up
done
ip link add "$MASTER_IF" netns "$MASTER_NS" type veth peer name "$SLAVE_IF" netns "$SLAVE_NS"
ip -n "$MASTER_NS" link set "$MASTER_IF" up
ip -n "$SLAVE_NS" link set "$SLAVE_IF" up
if [ "$CT" = podman ]; then
    # join the slave namespace. ('ip netns exec NS podman run --network host' would do the
    # same for the network, but it also remounts /sys, hiding the cgroup mounts from podman)
    NET=(--network "ns:/run/netns/$SLAVE_NS")
else
    # docker's --network host is the docker daemon's namespace, whoever calls it: the slave
    # end goes there (the veth pair is still removed with the master namespace)
    ip -n "$SLAVE_NS" link set "$SLAVE_IF" netns 1
    ip link set "$SLAVE_IF" up
    NET=(--network host)
fi

say "run: $CONTAINER on $SLAVE_IF ($SLAVE_NS), master on $MASTER_IF ($MASTER_NS)"
ct run -d "${LIMITS[@]}" "${NET[@]}" --cap-add NET_RAW --name "$CONTAINER" \
    "$IMAGE" run --iface "$SLAVE_IF" --log-format json >/dev/null ||
    die "container did not start"
DAEMON_LOG=$(mktemp /tmp/ecatsim-ct-log.XXXXXX)
deadline=$((SECONDS + READY_TIMEOUT))
while :; do
    "$CT" logs "$CONTAINER" >"$DAEMON_LOG" 2>&1
    grep -q '"event": *"ready"' "$DAEMON_LOG" && break
    [ "$("$CT" inspect -f '{{.State.Running}}' "$CONTAINER")" = true ] ||
        die "container exited before the daemon was ready"
    [ "$SECONDS" -lt "$deadline" ] || die "daemon not ready after $READY_TIMEOUT s"
    sleep 0.2
done
bg_run ip netns exec "$MASTER_NS" "$PY" tools/container_master.py "$MASTER_IF" ||
    die "master did not bring the container's slave to OP"
ct stop -t 10 "$CONTAINER" >/dev/null
rc=$("$CT" inspect -f '{{.State.ExitCode}}' "$CONTAINER")
[ "$rc" = 0 ] || die "daemon exited with $rc on SIGTERM"
ct rm "$CONTAINER" >/dev/null
T_RUN=$(since "$T")

say "timings: base image ${T_BASE} s, build ${T_BUILD} s, run ${T_RUN} s, total $(since "$T0") s"

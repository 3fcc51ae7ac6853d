# ecatsim in a container. Needs the host network (or a network namespace holding the
# interface) and CAP_NET_RAW:
#   podman build -t ecatsim .
#   podman run --rm --network host --cap-add NET_RAW ecatsim run --iface veth-ecat
# Where no registry is reachable, build a local Debian bookworm base image and pass it
# (tools/container-test.sh does this with debootstrap, then builds and runs the image
# against a pysoem master):
#   podman build --network host --build-arg BASE=localhost/ecatsim-base:bookworm -t ecatsim .
# The base needs python3 (3.11 or later) with the venv module. ecatsim goes into a venv at
# /opt/ecatsim/venv (Debian's python3 refuses system-wide pip installs, PEP 668), with the
# runtime dependencies pinned to the versions in requirements-test.lock. The venv's bin/ is
# first on PATH, so the entry point is the venv's `ecatsim`.
# Build argument PIP_CA_BUNDLE (optional): a CA bundle for pip inside the build, for networks
# that intercept TLS (tools/container-test.sh mounts the host's bundle for the build only).
ARG BASE=docker.io/library/python:3.11-slim
FROM ${BASE}
ARG PIP_CA_BUNDLE=""

ENV VIRTUAL_ENV=/opt/ecatsim/venv \
    PATH=/opt/ecatsim/venv/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    PYTHONDONTWRITEBYTECODE=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

WORKDIR /opt/ecatsim
COPY pyproject.toml README.md requirements-test.lock ./
COPY ecatsim ./ecatsim
COPY config ./config
RUN grep -iE '^(pyyaml|click|structlog)==' requirements-test.lock > constraints.txt \
    && test "$(wc -l < constraints.txt)" -eq 3 \
    && python3 -m venv "$VIRTUAL_ENV" \
    && env ${PIP_CA_BUNDLE:+PIP_CERT="$PIP_CA_BUNDLE"} \
        "$VIRTUAL_ENV/bin/pip" install --no-cache-dir -c constraints.txt . \
    && useradd --system --no-create-home ecatsim

ENTRYPOINT ["ecatsim"]
CMD ["run", "--help"]

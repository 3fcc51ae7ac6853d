# ecatsim in a container: a build stage compiles the core (Cython, the C compiler and the
# Python headers stay there), a slim runtime stage gets the finished venv.
#
#   sudo tools/container-test.sh --base-only     # once: the base image, built offline
#   podman build --network host -t ecatsim .
#   podman run --rm --network host --cap-add NET_RAW \
#       --ulimit nofile=4096:4096 --ulimit nproc=4096:4096 ecatsim run --iface ecat1
#
# BASE (build argument): an image with python3 (3.11 or later) and its venv module. The
# default, localhost/ecatsim-base:bookworm, is a Debian bookworm rootfs made with
# debootstrap and imported by tools/container-test.sh (no registry needed: apt and pip
# reach their package mirrors). --build-arg BASE=docker.io/library/python:3.11-slim works too
# where docker.io is reachable.
# ecatsim goes into a venv at /opt/ecatsim/venv (Debian's python3 refuses system-wide pip
# installs, PEP 668), with the runtime dependencies pinned to the versions in
# requirements-test.lock. The venv's bin/ is first on PATH, so the entry point is the venv's
# `ecatsim`.
# Build argument PIP_CA_BUNDLE (optional): a CA bundle for pip inside the build, for networks
# that intercept TLS (tools/container-test.sh mounts the host's bundle for the build only).
ARG BASE=localhost/ecatsim-base:bookworm

FROM ${BASE} AS build
ARG PIP_CA_BUNDLE=""
ENV VIRTUAL_ENV=/opt/ecatsim/venv \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    DEBIAN_FRONTEND=noninteractive
RUN if ! command -v cc >/dev/null || ! python3 -c 'import sysconfig, os, sys; \
        sys.exit(not os.path.exists(sysconfig.get_path("include") + "/Python.h"))'; then \
        apt-get update -qq \
        && apt-get install -y -qq --no-install-recommends gcc libc6-dev python3-dev binutils \
        && rm -rf /var/lib/apt/lists/*; \
    fi
WORKDIR /src
# README.md is only the package's long description: a stub, so that editing the README
# does not compile the core again
COPY pyproject.toml setup.py requirements-test.lock ./
RUN echo "ecatsim: see the project's README" > README.md
COPY ecatsim ./ecatsim
COPY config ./config
# the wheel with the compiled core; the build fails unless `ecatsim --version` says
# `core: compiled`; the extensions lose their symbol tables (a third of their size)
RUN grep -iE '^(pyyaml|click|structlog)==' requirements-test.lock > constraints.txt \
    && test "$(wc -l < constraints.txt)" -eq 3 \
    && python3 -m venv "$VIRTUAL_ENV" \
    && if [ -n "$PIP_CA_BUNDLE" ]; then export PIP_CERT="$PIP_CA_BUNDLE"; fi \
    && "$VIRTUAL_ENV/bin/pip" wheel --no-cache-dir --no-deps -w /wheels . \
    && "$VIRTUAL_ENV/bin/pip" install --no-cache-dir -c constraints.txt /wheels/ecatsim-*.whl \
    && "$VIRTUAL_ENV/bin/pip" uninstall -q -y pip setuptools \
    && find "$VIRTUAL_ENV" -name '*.so' -exec strip --strip-unneeded {} + \
    && "$VIRTUAL_ENV/bin/ecatsim" --version \
    && "$VIRTUAL_ENV/bin/ecatsim" --version | grep -qx 'core: compiled'

FROM ${BASE}
ENV VIRTUAL_ENV=/opt/ecatsim/venv \
    PATH=/opt/ecatsim/venv/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    PYTHONDONTWRITEBYTECODE=1
WORKDIR /opt/ecatsim
COPY --from=build /opt/ecatsim/venv /opt/ecatsim/venv
COPY config ./config
RUN useradd --system --no-create-home ecatsim

ENTRYPOINT ["ecatsim"]
CMD ["run", "--help"]

# ecatsim in a container. Needs the host network (or a network namespace holding the
# interface) and CAP_NET_RAW:
#   podman build -t ecatsim .
#   podman run --rm --network host --cap-add NET_RAW ecatsim run --iface veth-ecat
# Where no registry is reachable, build a local base image and pass it:
#   podman build --build-arg BASE=localhost/debian-python:bookworm -t ecatsim .
ARG BASE=docker.io/library/python:3.11-slim
FROM ${BASE}

WORKDIR /opt/ecatsim
COPY pyproject.toml README.md ./
COPY ecatsim ./ecatsim
COPY config ./config
RUN python3 -m pip install --no-cache-dir . \
    && useradd --system --no-create-home ecatsim

ENTRYPOINT ["ecatsim"]
CMD ["run", "--help"]

# phytrace-edge from the package index: a Python base, the bridge and ROS 2 Jazzy's
# rclpy as wheels (the `jazzy` extra: ros-jazzy-rclpy[fastrtps] and the common
# interfaces). No ROS apt repository, nothing sourced. x86_64 only: there are no
# aarch64 wheels of rclpy; on an arm64 robot build Dockerfile.ros (ros:jazzy-ros-base).
#
#   docker build -t phytrace-edge .
#   docker run --network host --ipc host -v phytrace-queue:/var/lib/phytrace-edge \
#     -e PHYCLOUD_ENDPOINT=... -e PHYCLOUD_API_KEY=... -e SOURCE_ID=... phytrace-edge
#
# The tests build it on a stand-in base made on the machine (tests/container/standin.py:
# Debian bookworm with Python 3.11 and venv, no ROS): --build-arg BASE_IMAGE=<stand-in>.
ARG BASE_IMAGE=python:3.12-slim-bookworm
FROM ${BASE_IMAGE}
# the ROS wheels (jazzy), the ROS-free DDS input (dds), rosbag replay (bag), the dev stub
ARG EXTRAS=jazzy,dds,bag,stub

SHELL ["/bin/bash", "-o", "pipefail", "-c"]
ENV PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PYTHONUNBUFFERED=1

WORKDIR /src
COPY pyproject.toml README.md ./
COPY phytrace_edge ./phytrace_edge
COPY migrations ./migrations
RUN python3 -m venv /opt/phytrace-edge \
    && /opt/phytrace-edge/bin/pip install "/src[${EXTRAS}]" \
    && rm -rf /src

# A non-root user (UID: the user the robot's ROS nodes run as, for shared memory with
# them; docs/operations.md); the queue lives on a volume so the backlog survives the
# container. /run/phytrace-edge: the live status stays the container's own even with
# --ipc host, where /dev/shm is the host's.
ARG UID=10001
RUN useradd --system --uid "${UID}" --home-dir /var/lib/phytrace-edge --shell /usr/sbin/nologin phytrace \
    && install -d -o phytrace -g phytrace -m 0700 /var/lib/phytrace-edge /run/phytrace-edge
VOLUME ["/var/lib/phytrace-edge"]

# Fast DDS is the RMW the wheels bring (the robot's nodes may run any RMW that speaks
# DDS: Cyclone, Connext). rcl's own log files in /tmp, not on the queue's volume: the
# container's output is its log.
ENV PATH=/opt/phytrace-edge/bin:$PATH \
    PHYTRACE_STATE_DIR=/var/lib/phytrace-edge \
    PHYTRACE_CONTAINER=1 \
    RMW_IMPLEMENTATION=rmw_fastrtps_cpp \
    ROS_LOG_DIR=/tmp/ros-log

USER ${UID}:${UID}
WORKDIR /var/lib/phytrace-edge

# Unhealthy when the heartbeat is stale, the key is refused, the queue is nearly full
# or nothing has been sent for HEALTH_NO_PROGRESS_S (docs/operations.md).
HEALTHCHECK --interval=30s --timeout=10s --start-period=30s --retries=3 \
    CMD ["phytrace-edge", "status", "--quiet"]

CMD ["phytrace-edge", "run"]

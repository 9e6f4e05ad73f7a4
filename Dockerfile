# phytrace-edge on the ROS 2 Jazzy base image: rclpy and the common interfaces are there
# for BRIDGE_INPUT=ros; the dds and bag inputs and the dev stub come from the extras.
#
#   docker build -t phytrace-edge .
#   docker run --network host -v phytrace-queue:/var/lib/phytrace-edge \
#     -e PHYCLOUD_ENDPOINT=... -e PHYCLOUD_API_KEY=... -e SOURCE_ID=... phytrace-edge
#
# The tests build it on a stand-in base made on the machine (tests/container/standin.py:
# Debian with Python, no ROS): --build-arg BASE_IMAGE=<stand-in> --build-arg ROS_PACKAGES=
# (empty: the stand-in has python3-venv and no ROS repository). Production uses neither.
ARG BASE_IMAGE=ros:jazzy-ros-base
FROM ${BASE_IMAGE}
ARG ROS_PACKAGES="ros-jazzy-rmw-cyclonedds-cpp"

SHELL ["/bin/bash", "-o", "pipefail", "-c"]
ENV DEBIAN_FRONTEND=noninteractive \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PYTHONUNBUFFERED=1

# Cyclone DDS as the RMW (what the dds input speaks, and what the tests checked);
# python3-venv for an isolated install that still sees rclpy and the system numpy
# rclpy was built against.
# hadolint ignore=DL3008
RUN if [ -n "${ROS_PACKAGES}" ]; then \
        apt-get update \
        && apt-get install -y --no-install-recommends python3-venv ${ROS_PACKAGES} \
        && rm -rf /var/lib/apt/lists/*; \
    fi

WORKDIR /src
COPY pyproject.toml README.md ./
COPY phytrace_edge ./phytrace_edge
COPY migrations ./migrations
RUN python3 -m venv --system-site-packages /opt/phytrace-edge \
    && /opt/phytrace-edge/bin/pip install "/src[dds,bag,stub]" \
    && rm -rf /src

# A non-root user; the queue lives on a volume so the backlog survives the container.
RUN useradd --system --uid 10001 --home-dir /var/lib/phytrace-edge --shell /usr/sbin/nologin phytrace \
    && install -d -o phytrace -g phytrace -m 0700 /var/lib/phytrace-edge
VOLUME ["/var/lib/phytrace-edge"]

ENV PATH=/opt/phytrace-edge/bin:$PATH \
    PHYTRACE_STATE_DIR=/var/lib/phytrace-edge \
    PHYTRACE_CONTAINER=1 \
    RMW_IMPLEMENTATION=rmw_cyclonedds_cpp

USER 10001:10001
WORKDIR /var/lib/phytrace-edge

# Unhealthy when the heartbeat is stale, the key is refused, the queue is nearly full
# or nothing has been sent for HEALTH_NO_PROGRESS_S (docs/operations.md).
HEALTHCHECK --interval=30s --timeout=10s --start-period=30s --retries=3 \
    CMD ["phytrace-edge", "status", "--quiet"]

# ros_entrypoint.sh sources /opt/ros/jazzy/setup.bash, so rclpy imports.
ENTRYPOINT ["/ros_entrypoint.sh"]
CMD ["phytrace-edge", "run"]

"""Incident windows (issue 35) through the ``ros`` input, on real rclpy and on the mock
with the same bodies: the bridge's ``~/mark`` service (``std_srvs/srv/Trigger``)
called from the robot's node, ``phytrace-edge mark`` against the same bridge, the
window topics delivered on every message (an incident holds the odometry at the rate
it was published, the sample tick at 5 Hz), and the hourly limit as the service
answers it. And the bridge without std_srvs: one WARNING, no service, nothing else
changed.
"""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from phytrace_edge.udm.event import parse_timestamp
from tests.processes import python_env, wait_for
from tests.ros.conftest import FLAVOURS, why_no_rclpy
from tests.ros.known import KNOWN, STAMP
from tests.ros.rig import ROS_PYTHONS, Rig, private_domain, ros_env

MARK = "/phytrace_edge/mark"  # ~/mark of the node phytrace_edge, namespace /
MARK_REASON = "~/mark service call"
NO_STD_SRVS = str(Path(__file__).with_name("no_std_srvs.py"))


def start_quick(rig: Rig, before_s: str = "2", max_per_hour: str = "") -> None:
    """The bridge with short windows (``before_s``, then 1 s after) and marks as the
    only triggers; ``max_per_hour`` "" leaves INCIDENT_MAX_PER_HOUR unset."""
    rig.start_bridge(
        SAMPLE_RATE_HZ="5",
        INCIDENT_BEFORE_S=before_s,
        INCIDENT_AFTER_S="1",
        INCIDENT_DIAGNOSTICS_LEVEL="off",
        INCIDENT_ROSOUT_LEVEL="off",
        INCIDENT_MAX_PER_HOUR=max_per_hour,
    )


def window_s(body: dict[str, Any]) -> float:
    start, end = (parse_timestamp(body["window"][k]) for k in ("start", "end"))
    return end - start


def test_the_mark_service_records_an_incident(rig: Rig) -> None:
    """``ros2 service call /phytrace_edge/mark std_srvs/srv/Trigger``: success, the
    incident's id in the message, and that incident at the stub, marked by hand."""
    start_quick(rig)
    answer = rig.call_trigger(MARK)
    assert answer is not None, "the bridge did not answer ~/mark within 10 s"
    assert answer["success"] is True, answer
    parts = rig.wait_incident()
    body = parts[0]["incident"]
    assert answer["message"].startswith(f"incident {body['id']} opened"), answer
    assert body["trigger"]["kind"] == "manual"
    assert body["trigger"]["message"] == MARK_REASON
    assert window_s(body) == pytest.approx(3.0, abs=0.01)  # 2 s before, 1 s after
    assert {p["incident"]["id"] for p in rig.events("incident")} == {body["id"]}


def test_phytrace_edge_mark_reaches_the_ros_bridge(rig: Rig) -> None:
    """``phytrace-edge mark --reason`` with the bridge's QUEUE_PATH: exit 0, and the
    incident it names at the stub with the reason as its trigger's message."""
    start_quick(rig)
    rig.wait_running()
    reason = "operator saw the robot wobble"
    done = subprocess.run(
        [sys.executable, "-m", "phytrace_edge", "mark", "--reason", reason],
        capture_output=True,
        text=True,
        timeout=60,
        env=python_env(QUEUE_PATH=str(rig.queue_path)),
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("incident "), done.stdout
    incident = done.stdout.split()[1]
    body = rig.wait_incident(incident)[0]["incident"]
    assert (body["trigger"]["kind"], body["trigger"]["message"]) == ("manual", reason)
    assert window_s(body) == pytest.approx(3.0, abs=0.01)


def test_an_incident_holds_the_odometry_at_the_rate_it_was_published(rig: Rig) -> None:
    """Odometry published at 50 Hz for 3 s into a 5 Hz sample tick, then a mark: the
    incident's /odom samples (its parts joined by part number) are at 40 Hz or more
    over the stretch where the robot published, nearly every message published, each
    with the published values; the tick alone would give 5 a second."""
    type_name, qos, fields = KNOWN["/odom"]
    odom = rig.publisher("/odom", type_name, qos)
    start_quick(rig, before_s="6")  # the sample tick at 5 Hz
    rig.publish_until(odom, fields, lambda e: "location" in e, "the odometry")
    moved = copy.deepcopy(fields)
    moved["pose"]["pose"]["position"]["x"] = 77.0  # the stretch at 50 Hz, told apart
    sent = rig.publish_at(odom, moved, hz=50, seconds=3)
    assert sent >= 140, sent
    answer = rig.call_trigger(MARK)
    assert answer is not None and answer["success"] is True, answer
    parts = rig.wait_incident()
    assert [p["incident"]["part"] for p in parts] == list(range(1, len(parts) + 1))
    samples = [s for part in parts for s in part["incident"]["samples"].get("/odom", [])]
    times = [parse_timestamp(s["t"]) for s in samples]
    assert times == sorted(times), "the parts joined in order are in time order"
    stretch = [t for s, t in zip(samples, times, strict=True) if s["local"]["x_m"] == 77.0]
    rate_hz = (len(stretch) - 1) / (stretch[-1] - stretch[0])
    assert rate_hz >= 40, (rate_hz, len(stretch), sent)
    assert len(stretch) >= 0.9 * sent, (len(stretch), sent)  # best effort, on loopback
    stamp_ns = STAMP["sec"] * 10**9 + STAMP["nanosec"]
    for sample in samples:  # the stretch's and the warm-up's: what was published
        assert sample["local"]["x_m"] in (77.0, 12.34), sample
        assert sample["local"]["y_m"] == 5.67
        assert sample["local"]["yaw_deg"] == pytest.approx(45.2)
        assert sample["linear_velocity"]["x_mps"] == 0.85
        assert (sample["frame_id"], sample["stamp_ns"]) == ("odom", stamp_ns)


def test_a_mark_beyond_the_hourly_limit_is_refused_by_the_mark_service(rig: Rig) -> None:
    """INCIDENT_MAX_PER_HOUR=1: a second ``~/mark`` after the first incident closed is
    answered not accepted, saying why, and ``status`` counts it as rate-limited."""
    start_quick(rig, max_per_hour="1")
    first = rig.call_trigger(MARK)
    assert first is not None and first["success"] is True, first
    rig.wait_incident()  # closed and sent
    second = rig.call_trigger(MARK)
    assert second is not None, "the bridge did not answer the second ~/mark"
    assert second["success"] is False, second
    assert "rate-limited" in second["message"]
    assert "INCIDENT_MAX_PER_HOUR" in second["message"]

    def counted() -> dict[str, Any] | None:  # the heartbeat's: seconds behind
        incidents = rig.status_json().get("incidents", {})
        return incidents if incidents.get("rate_limited", 0) >= 1 else None

    incidents = wait_for(counted, 30, "status to count the rate-limited mark", every=0.5)
    assert incidents["recorded"] == 1 and incidents["opened"] == 1


@pytest.mark.parametrize("flavour", FLAVOURS)
@pytest.mark.parametrize("std_srvs", ["installed", "missing"])
def test_without_std_srvs_the_bridge_runs_with_no_mark_service(
    flavour: str, std_srvs: str, tmp_path: Path
) -> None:
    """The ``ros`` input started where std_srvs cannot be imported: one WARNING naming
    it, no ``~/mark``, the node and its subscriptions as ever; where it can, the
    service and no WARNING."""
    if flavour != "mock" and (missing := why_no_rclpy(flavour)):
        if os.environ.get("CI"):  # in CI the real thing must run, never skip (the rig's rule)
            pytest.fail(missing)
        pytest.skip(missing)
    python = sys.executable if flavour == "mock" else str(ROS_PYTHONS[flavour])
    argv = [python, NO_STD_SRVS, *(["--mock"] if flavour == "mock" else [])]
    argv += ["--hide-std-srvs"] if std_srvs == "missing" else []
    env = python_env() | ros_env(private_domain(), tmp_path / "ros-logs", flavour)
    done = subprocess.run(argv, capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout)
    assert seen["subscribed"], seen  # the input itself started
    if std_srvs == "missing":
        assert seen["mark_service"] is None
        [warning] = seen["warnings"]
        assert "std_srvs" in warning and "~/mark" in warning
    else:
        assert seen["mark_service"] == MARK
        assert seen["warnings"] == []

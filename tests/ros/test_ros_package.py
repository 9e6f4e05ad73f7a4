"""phytrace-edge as a ROS 2 package: package.xml agrees with pyproject.toml, and a real
``colcon build`` (ament_cmake from the ROS 2 wheels) installs what ``ros2 launch
phytrace_edge ...`` and ``ros2 run phytrace_edge ...`` use; the installed ``bridge``
then runs on real rclpy."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package

from phytrace_edge import __version__

if sys.version_info >= (3, 11):
    import tomllib
else:  # the project's fallback before tomllib
    import tomli as tomllib
from tests.processes import ROOT
from tests.ros.conftest import why_no_rclpy
from tests.ros.known import KNOWN
from tests.ros.rig import ROS_PYTHON, Rig

# the core's Python dependencies -> their rosdep keys (None: rosdep has none)
ROSDEP_KEYS = {
    "httpx": "python3-httpx",
    "tenacity": None,
    "orjson": "python3-orjson",
    "zstandard": None,
    "fastjsonschema": "python3-fastjsonschema",
    "numpy": "python3-numpy",
    "tomli": None,  # Python < 3.11 only; ROS 2 Jazzy runs 3.12
    "tqdm": "python3-tqdm",
    "prometheus-client": "python3-prometheus-client",
    "mcap": None,
    "cryptography": "python3-cryptography",
}
ROS_DEPENDENCIES = {
    "rclpy",
    "launch",
    "ament_index_python",
    "std_msgs",
    "sensor_msgs",
    "nav_msgs",
    "geometry_msgs",
    "diagnostic_msgs",
    "rcl_interfaces",
}


def requirement_name(requirement: str) -> str:
    return requirement.split(";")[0].split(">")[0].split("=")[0].split("[")[0].strip()


def test_package_xml_is_format_3_and_agrees_with_pyproject() -> None:
    package = parse_package(str(ROOT / "package.xml"))
    package.validate()
    assert (package.name, package.package_format) == ("phytrace_edge", 3)
    assert package.version == __version__
    assert package.get_build_type() == "ament_cmake"
    exec_depends = {d.name for d in package.exec_depends}
    assert exec_depends >= ROS_DEPENDENCIES
    core = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    assert {requirement_name(r) for r in core} == set(ROSDEP_KEYS)  # none left unmapped
    keys = {key for key in ROSDEP_KEYS.values() if key}
    assert {d for d in exec_depends if d.startswith("python3-")} == keys | {"python3-yaml"}
    ros_docs = (ROOT / "docs" / "ros2.md").read_text()
    for name, key in ROSDEP_KEYS.items():
        if key is None and name != "tomli":
            assert "pip install" in ros_docs and name in ros_docs, name


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``colcon build`` of a workspace whose src/ holds this repository: the install."""
    if missing := why_no_rclpy():
        if os.environ.get("CI"):
            pytest.fail(missing)
        pytest.skip(missing)
    workspace = tmp_path_factory.mktemp("ws")
    (workspace / "src").mkdir()
    (workspace / "src" / "phytrace_edge").symlink_to(ROOT)
    venv = ROS_PYTHON.parent.parent
    env = os.environ | {
        "PATH": f"{venv / 'bin'}:{os.environ['PATH']}",
        "CMAKE_PREFIX_PATH": str(venv),
        "AMENT_PREFIX_PATH": str(venv),
    }
    build = subprocess.run(
        [str(venv / "bin" / "colcon"), "build", "--base-paths", "src"],
        cwd=workspace,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert build.returncode == 0, build.stdout + build.stderr
    return workspace / "install" / "phytrace_edge"


def sourced(install: Path) -> dict[str, str]:
    """The environment ``source install/setup.bash`` gives: this install (and not the
    checkout) on the Python path, in the ament index, its python3 first on PATH."""
    site = install / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PHYCLOUD_", "QUEUE_"))}
    return env | {
        "PYTHONPATH": str(site / "site-packages"),
        "AMENT_PREFIX_PATH": str(install),
        "PATH": f"{ROS_PYTHON.parent}:{os.environ['PATH']}",
        "PYTHONUNBUFFERED": "1",
    }


def test_colcon_installs_the_launch_files_params_and_executables(installed: Path) -> None:
    share = installed / "share" / "phytrace_edge"
    assert (
        installed / "share" / "ament_index" / "resource_index" / "packages" / "phytrace_edge"
    ).exists()
    for name in ("bridge_only.launch.py", "delivery_robot.launch.py", "phytrace_edge.params.yaml"):
        assert (share / "launch" / name).is_file(), name
    assert (share / "package.xml").is_file()
    for name in ("phytrace-edge", "bridge"):
        assert os.access(installed / "lib" / "phytrace_edge" / name, os.X_OK), name
    env = sourced(installed)
    where = subprocess.run(  # outside the checkout: `-c` puts the cwd first on the path
        [str(ROS_PYTHON), "-c", FIND_PACKAGE],
        env=env,
        cwd=installed,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert where.returncode == 0, where.stderr
    prefix, module, migrations, executable = where.stdout.split()
    assert Path(prefix) == installed  # what `ros2 pkg prefix phytrace_edge` prints
    assert Path(module).is_relative_to(installed)  # the installed code, not the checkout
    assert int(migrations) == len(list((ROOT / "migrations").glob("*.sql")))
    # the launch file runs the package's own executable
    assert Path(executable) == installed / "lib" / "phytrace_edge" / "phytrace-edge"
    version = subprocess.run(
        [str(installed / "lib" / "phytrace_edge" / "phytrace-edge"), "--version"],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert version.stdout.strip() == f"phytrace-edge {__version__}", version.stderr


FIND_PACKAGE = """
import runpy, sys, types
from ament_index_python.packages import get_package_prefix
import phytrace_edge
from phytrace_edge.queue.storage.migrate import migration_files

class Recorded:
    def __init__(self, *args, **kwargs): pass

sys.modules["launch"] = types.SimpleNamespace(LaunchDescription=Recorded)
sys.modules["launch.actions"] = types.SimpleNamespace(
    DeclareLaunchArgument=Recorded, ExecuteProcess=Recorded, OpaqueFunction=Recorded)
sys.modules["launch.substitutions"] = types.SimpleNamespace(LaunchConfiguration=Recorded)
share = get_package_prefix("phytrace_edge") + "/share/phytrace_edge/launch/bridge_only.launch.py"
print(get_package_prefix("phytrace_edge"), phytrace_edge.__file__, len(migration_files()),
      runpy.run_path(share)["bridge_executable"]())
"""


def test_the_installed_bridge_runs_on_real_rclpy(installed: Path, tmp_path: Path, stub) -> None:
    """``ros2 run phytrace_edge bridge``, without ros2cli (it has no wheel): the
    installed executable hears a real robot and delivers to the stub."""
    rig = Rig("kilted", tmp_path, stub)
    try:
        odom = rig.publisher("/odom", *KNOWN["/odom"][:2])
        rig.start_bridge(
            command=[str(installed / "lib" / "phytrace_edge" / "bridge")],
            process_env=sourced(installed),
        )
        event = rig.publish_until(odom, KNOWN["/odom"][2], lambda e: "location" in e, "odometry")
        assert event["location"]["local"]["x_m"] == 12.34
        code, log = rig.stop_bridge(signal.SIGTERM)
        assert code == 0, log
    finally:
        rig.close()

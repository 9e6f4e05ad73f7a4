"""Settings: sources and precedence, the names of the product's original description
(docs/configuration.md), validation messages."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from phytrace_edge.cli import main
from phytrace_edge.config import load_settings, setting_infos, settings_from_environment
from phytrace_edge.config.parsers import known_topics
from phytrace_edge.errors import ConfigError
from phytrace_edge.redact import Secret
from phytrace_edge.units import GIB, MIB


def test_defaults_match_the_reference_guide() -> None:
    s = load_settings(env={"HOME": "/home/op"}).settings
    assert s.phycloud_endpoint == "http://localhost:8000/api/v1"
    assert s.phycloud_api_key == Secret("")
    assert (s.source_id, s.source_type) == ("delivery-robot-001", "delivery_robot")
    assert (s.fleet_id, s.site_id) == (None, None)
    assert (s.sample_rate_hz, s.batch_size) == (5.0, 10)
    assert s.queue_max_bytes == GIB and s.queue_ttl_s == 604800
    assert s.queue_path == "/home/op/.local/state/phytrace-edge/queue.db"


def test_reference_env_file_is_read_exactly() -> None:
    env = {
        "PHYCLOUD_ENDPOINT": "https://api.phycloud.phyware.io/v1",
        "PHYCLOUD_API_KEY": "phk_live_xxxxxxxxxxxxxxxx",
        "SOURCE_ID": "warehouse-amr-07",
        "SOURCE_TYPE": "amr",
        "FLEET_ID": "chicago-dc-fleet",
        "SITE_ID": "chicago-dc-01",
        "SAMPLE_RATE_HZ": "10.0",
        "BATCH_SIZE": "20",
    }
    loaded = load_settings(env=env)
    s = loaded.settings
    assert s.phycloud_endpoint == "https://api.phycloud.phyware.io/v1"
    assert s.phycloud_api_key.reveal() == "phk_live_xxxxxxxxxxxxxxxx"
    assert (s.source_id, s.source_type, s.fleet_id, s.site_id) == (
        "warehouse-amr-07",
        "amr",
        "chicago-dc-fleet",
        "chicago-dc-01",
    )
    assert (s.sample_rate_hz, s.batch_size) == (10.0, 20)
    assert loaded.origins["source_id"] == "env SOURCE_ID"


def test_robot_aliases_and_primary_name_wins() -> None:
    s = load_settings(env={"ROBOT_ID": "r-9", "ROBOT_TYPE": "agv"}).settings
    assert (s.source_id, s.source_type) == ("r-9", "agv")
    s = load_settings(env={"ROBOT_ID": "r-9", "SOURCE_ID": "s-1"}).settings
    assert s.source_id == "s-1"


def test_precedence_flag_env_file_ros_default() -> None:
    loaded = load_settings(
        flags={"batch_size": "4"},
        env={"BATCH_SIZE": "3", "SAMPLE_RATE_HZ": "2"},
        config_file={"batch_size": 2, "sample_rate_hz": 1.5, "site_id": "file-site"},
        ros_params={
            "batch_size": 1,
            "sample_rate_hz": 1.0,
            "site_id": "ros-site",
            "fleet_id": "ros-fleet",
        },
    )
    s = loaded.settings
    assert (s.batch_size, s.sample_rate_hz, s.site_id, s.fleet_id) == (
        4,
        2.0,
        "file-site",
        "ros-fleet",
    )
    assert loaded.origins["batch_size"] == "flag --batch-size"
    assert loaded.origins["sample_rate_hz"] == "env SAMPLE_RATE_HZ"
    assert loaded.origins["site_id"] == "file"
    assert loaded.origins["fleet_id"] == "ros param"
    assert loaded.origins["http_timeout_s"] == "default"


def test_empty_env_values_count_as_unset() -> None:
    assert load_settings(env={"FLEET_ID": "", "SOURCE_ID": " "}).settings.source_id == (
        "delivery-robot-001"
    )


@pytest.mark.parametrize(
    ("env", "message"),
    [
        (
            {"SOURCE_TYPE": "boat"},
            "SOURCE_TYPE='boat': must be one of delivery_robot, amr, agv, drone, humanoid, arm",
        ),
        ({"SAMPLE_RATE_HZ": "-1"}, "SAMPLE_RATE_HZ='-1': must be a number > 0 and <= 1000"),
        ({"SAMPLE_RATE_HZ": "nan"}, "SAMPLE_RATE_HZ='nan': must be a number > 0"),
        ({"PHYCLOUD_ENDPOINT": "api.example.com"}, "PHYCLOUD_ENDPOINT='api.example.com': must be"),
        ({"BATCH_SIZE": "ten"}, "BATCH_SIZE='ten': must be a whole number from 1 to 10000"),
        ({"QUEUE_MAX_BYTES": "12 potatoes"}, "QUEUE_MAX_BYTES='12 potatoes': must be a size"),
        ({"QUEUE_ON_FULL": "panic"}, "QUEUE_ON_FULL='panic': must be one of thin, drop_oldest"),
        ({"BRIDGE_INPUT": "bag:"}, "BRIDGE_INPUT='bag:': must be ros, dds, sim or bag:PATH"),
        ({"TOPIC_REMAP": "/nope=/x"}, "TOPIC_REMAP='/nope=/x': must be topic=name pairs"),
        ({"TOPICS_DISABLED": "/scan,/laser"}, "TOPICS_DISABLED='/scan,/laser': must be known"),
        ({"METRICS_PORT": "70000"}, "METRICS_PORT='70000': must be a whole number from 0"),
        ({"RETRY_MIN_S": "10", "RETRY_MAX_S": "5"}, "RETRY_MAX_S=5: must be >= RETRY_MIN_S (10)"),
        ({"ROBOT_TYPE": "boat"}, "ROBOT_TYPE='boat': must be one of"),
        ({"CA_BUNDLE": "/no/such/ca.pem"}, "CA_BUNDLE='/no/such/ca.pem': must be the path of"),
    ],
)
def test_bad_values_name_setting_value_and_rule(env: dict, message: str) -> None:
    with pytest.raises(ConfigError) as info:
        load_settings(env=env)
    assert str(info.value).startswith(message)
    assert "\n" not in str(info.value)


def test_api_key_never_shows_in_repr_or_str() -> None:
    settings = load_settings(env={"PHYCLOUD_API_KEY": "phk_live_secret"}).settings
    assert "phk_live_secret" not in repr(settings)
    assert "phk_live_secret" not in repr(Secret("phk_live_secret"))
    assert "phk_live_secret" not in str(Secret("phk_live_secret"))


def test_sizes_parse_with_units() -> None:
    s = load_settings(env={"QUEUE_MAX_BYTES": "512MiB", "BATCH_MAX_BYTES": "2048"}).settings
    assert (s.queue_max_bytes, s.batch_max_bytes) == (512 * MIB, 2048)
    assert load_settings(env={"QUEUE_MAX_BYTES": "1.5GB"}).settings.queue_max_bytes == 1_500_000_000


def test_topic_remap_and_disable_shape_the_topic_set() -> None:
    s = load_settings(
        env={"TOPIC_REMAP": "/odom=/wheel/odom, /scan=/front/scan", "TOPICS_DISABLED": "/gps/fix"}
    ).settings
    assert s.topics["/odom"] == "/wheel/odom"
    assert s.topics["/scan"] == "/front/scan"
    assert "/gps/fix" not in s.topics
    assert len(s.topics) == len(known_topics()) - 1


def test_state_dir_follows_systemd_then_container_then_xdg() -> None:
    def path(env: dict) -> str | None:
        return load_settings(env=env).settings.queue_path

    assert path({"STATE_DIRECTORY": "/var/lib/phytrace-edge:/other"}) == (
        "/var/lib/phytrace-edge/queue.db"
    )
    assert path({"PHYTRACE_STATE_DIR": "/data"}) == "/data/queue.db"
    assert path({"XDG_STATE_HOME": "/x"}) == "/x/phytrace-edge/queue.db"
    assert path({"QUEUE_PATH": "/q/queue.db", "STATE_DIRECTORY": "/s"}) == "/q/queue.db"


def test_config_file_unknown_key_and_bad_toml(tmp_path: Path) -> None:
    from phytrace_edge.config import read_config_file

    good = tmp_path / "good.toml"
    good.write_text('source_id = "from-file"\nsample_rate_hz = 2.5\n')
    assert load_settings(config_file=read_config_file(str(good))).settings.sample_rate_hz == 2.5
    with pytest.raises(ConfigError, match="unknown setting 'sample_rate'"):
        load_settings(config_file={"sample_rate": 2})
    bad = tmp_path / "bad.toml"
    bad.write_text("source_id = \n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        read_config_file(str(bad))
    with pytest.raises(ConfigError, match="not found"):
        read_config_file(str(tmp_path / "missing.toml"))


def test_every_setting_has_a_doc_line_and_is_in_the_configuration_doc() -> None:
    doc = (Path(__file__).parents[2] / "docs" / "configuration.md").read_text()
    for info in setting_infos():
        assert info.doc
        assert f"`{info.env}`" in doc, f"{info.env} is missing from docs/configuration.md"


def test_config_command_shows_sources_and_redacts_key(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PHYCLOUD_API_KEY", "phk_live_secret")
    monkeypatch.setenv("SOURCE_ID", "bot-7")
    assert main(["config", "--batch-size", "25"]) == 0
    out = capsys.readouterr().out
    assert "phk_live_secret" not in out
    lines = {line.split()[0]: line.split() for line in out.splitlines()}
    assert lines["PHYCLOUD_API_KEY"][1] == "***"
    assert lines["SOURCE_ID"][1:] == ["bot-7", "env", "SOURCE_ID"]
    assert lines["BATCH_SIZE"][1:] == ["25", "flag", "--batch-size"]


@pytest.mark.parametrize(
    ("env", "setting"),
    [
        ({"SOURCE_TYPE": "boat"}, "SOURCE_TYPE"),
        ({"SAMPLE_RATE_HZ": "-2"}, "SAMPLE_RATE_HZ"),
        ({"PHYCLOUD_ENDPOINT": "not a url"}, "PHYCLOUD_ENDPOINT"),
    ],
)
def test_config_command_bad_value_is_one_line_no_traceback(env: dict, setting: str) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "phytrace_edge", "config"],
        env={**env, "PATH": "/usr/bin:/bin", "HOME": "/tmp"},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1
    assert result.stderr.startswith(f"phytrace-edge: error: {setting}=")
    assert "Traceback" not in result.stderr


def test_config_piped_into_a_closed_reader_exits_quietly_every_time_on_a_busy_machine() -> None:
    """`phytrace-edge config | head -1`: the reader is gone before the output is written.
    Fifty runs, five at a time, beside two processes that keep both cores busy. Output
    to a pipe is block-buffered (as in a shell), so it is written when it is flushed."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        for _ in range(10):
            runs = []
            for _ in range(5):
                read_end, write_end = os.pipe()
                os.close(read_end)
                runs.append(
                    subprocess.Popen(
                        [sys.executable, "-m", "phytrace_edge", "config"],
                        stdout=write_end,
                        stderr=subprocess.PIPE,
                        text=True,
                        env=env,
                    )
                )
                os.close(write_end)
            for run in runs:
                _, stderr = run.communicate(timeout=60)
                assert "Traceback" not in stderr
                assert run.returncode == 0, stderr
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()


def test_topics_extra_as_text_and_as_toml_tables() -> None:
    from phytrace_edge.ingest.topics import ExtraTopic

    text = load_settings(
        env={
            "TOPICS_EXTRA": "/acme/drive type=acme_msgs/msg/DriveStatus rate_hz=2 "
            "mode=on_change deadband=0.5; /tf",
            "TOPIC_NAMESPACE": "/robot1",
        }
    ).settings
    table = load_settings(
        config_file={
            "topics_extra": {
                "/acme/drive": {
                    "type": "acme_msgs/msg/DriveStatus",
                    "rate_hz": 2,
                    "mode": "on_change",
                    "deadband": 0.5,
                },
                "/tf": {},
            },
            "topic_namespace": "/robot1",
        }
    ).settings
    expected = (
        ExtraTopic("/acme/drive", "acme_msgs/msg/DriveStatus", 2.0, "on_change", 0.5),
        ExtraTopic("/tf"),
    )
    assert text.topics_extra == table.topics_extra == expected
    assert text.extra_topics == {"/acme/drive": "/robot1/acme/drive", "/tf": "/robot1/tf"}


@pytest.mark.parametrize(
    "raw",
    [
        "/odom",  # a table topic
        "/x rate_hz=0",
        "/x rate_hz=-1",
        "/x rate_hz=nan",
        "/x mode=sometimes",
        "/x deadband=1",  # deadband without on_change
        "/x type=Temperature",
        "/x colour=red",
        "/x rate_hz",
        "/x; /x",
        "not-a-topic",
    ],
)
def test_topics_extra_rejects_bad_entries_in_one_line(raw: str) -> None:
    with pytest.raises(ConfigError) as caught:
        load_settings(env={"TOPICS_EXTRA": raw})
    assert str(caught.value).startswith("TOPICS_EXTRA=")
    assert "\n" not in str(caught.value)


def test_the_service_env_file_gives_status_the_service_queue(tmp_path: Path) -> None:
    """`status --env-file` reads the settings the unit's EnvironmentFile gives the
    service (comments, quotes and all), so an operator gets the service's queue."""
    from phytrace_edge.config.loading import read_env_file

    shipped = read_env_file(str(Path(__file__).parents[2] / "systemd" / "phytrace-edge.env"))
    assert shipped["QUEUE_PATH"] == "/var/lib/phytrace-edge/queue.db"
    env_file = tmp_path / "phytrace-edge.env"
    env_file.write_text(
        "# the service's settings\n\n; also a comment\n"
        f"QUEUE_PATH='{tmp_path / 'service' / 'queue.db'}'\n"
        'SOURCE_ID="robot-9"\nQUEUE_MAX_BYTES=2GiB\n'
    )
    result = subprocess.run(
        [sys.executable, "-m", "phytrace_edge", "status", "--env-file", str(env_file)],
        capture_output=True,
        text=True,
        timeout=60,
        env={k: v for k, v in os.environ.items() if not k.startswith(("QUEUE_", "SOURCE_"))},
    )
    assert result.returncode == 3
    assert result.stderr.strip() == (
        f"phytrace-edge: error: no queue at {tmp_path / 'service' / 'queue.db'}: "
        "the bridge never ran with this QUEUE_PATH"
    )
    loaded = settings_from_environment(None, {"SOURCE_ID": "from-env"}, env_file=str(env_file))
    assert loaded.settings.source_id == "from-env"  # the environment wins over the file
    assert loaded.settings.queue_max_bytes == 2 * 1024**3


def test_a_bad_env_file_is_one_line(tmp_path: Path) -> None:
    env_file = tmp_path / "bad.env"
    env_file.write_text("QUEUE_PATH=/q.db\nnot a setting\n")
    with pytest.raises(ConfigError, match=r"bad.env: line 2 is not KEY=VALUE$"):
        settings_from_environment(None, {}, env_file=str(env_file))
    with pytest.raises(ConfigError, match=r"env file .*missing\.env: not found"):
        settings_from_environment(None, {}, env_file=str(tmp_path / "missing.env"))


def test_a_params_file_and_p_flags_apply_in_order(tmp_path: Path) -> None:
    from phytrace_edge.config import ros_parameters

    shipped = Path(__file__).parents[2] / "phytrace_edge" / "launch" / "phytrace_edge.params.yaml"
    other = tmp_path / "other.yaml"
    other.write_text("other_node:\n  ros__parameters:\n    source_id: not-ours\n")
    params = ros_parameters(
        ["-p", "source_id:=overridden", "--params-file", str(shipped), "--params-file",
         str(other), "-p", "sample_rate_hz:=7.5"]
    )  # fmt: skip
    assert params["source_id"] == "warehouse-amr-07"  # the file came after the -p
    assert params["sample_rate_hz"] == "7.5"  # and this -p after the file
    assert params["use_sim_time"] is False  # from /**
    loaded = settings_from_environment(None, {}, ros_params=params)
    assert loaded.settings.source_type == "amr" and loaded.settings.sample_rate_hz == 7.5
    assert loaded.settings.topics_extra[0].mode == "on_change"
    assert loaded.origins["fleet_id"] == "ros param"


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("phytrace_edge: [1, 2]\n", "has no ros__parameters mapping"),
        ("- a\n- b\n", "not a mapping of node names"),
        ("a: [unclosed\n", "not valid YAML"),
    ],
)
def test_a_bad_params_file_is_one_line(tmp_path: Path, text: str, says: str) -> None:
    from phytrace_edge.config import ros_parameters

    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=says) as caught:
        ros_parameters(["--params-file", str(path)])
    assert "\n" not in str(caught.value)

"""The API key from a file, as a credential store gives it: PHYCLOUD_API_KEY_FILE,
systemd's credentials ($CREDENTIALS_DIRECTORY/phycloud_api_key), the file read again
when PhyCloud refuses the key (a rotation needs no restart) and on SIGHUP, which never
ends the bridge. Real bridge processes and a real stub that requires the key."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from tests.network.delivery import delivered_everything, start_bridge, unhealthy_naming
from tests.processes import run_cli, status_json, wait_for

OLD_KEY = "phk_live_old_key_AAAAAAAAAAAAAAAA"
NEW_KEY = "phk_live_new_key_BBBBBBBBBBBBBBBB"


def key_file(tmp_path: Path, key: str, mode: int = 0o600) -> Path:
    path = tmp_path / "api_key"
    path.write_text(key + "\n")
    path.chmod(mode)
    return path


def test_a_rotated_key_file_is_used_without_a_restart(tmp_path: Path, stub_factory) -> None:
    """The robot starts with the old key, PhyCloud wants the new one: status names the
    refused key; the new key written to the file is used at the next retry, and every
    event built meanwhile is delivered."""
    stub = stub_factory("--api-key", NEW_KEY)
    path = key_file(tmp_path, OLD_KEY)
    bridge, settings = start_bridge(tmp_path, stub.endpoint, PHYCLOUD_API_KEY_FILE=str(path))
    try:
        code, document = wait_for(
            lambda: unhealthy_naming(settings, "refuses the API key"), 30, "the refusal"
        )
        assert f"PHYCLOUD_API_KEY_FILE {path}" in " ".join(document["problems"])
        assert code == 1
        path.write_text(NEW_KEY + "\n")  # the rotation, by an operator or an agent
        wait_for(lambda: stub.stats()["unique"] > 0, 30, "delivery with the new key")
        wait_for(lambda: status_json(**settings)[0] == 0, 30, "status healthy again")
        accounting = delivered_everything(bridge, settings, stub)
        assert accounting["built"] == accounting["delivered"]
    finally:
        bridge.stop()
    log = (tmp_path / "bridge.log").read_text()
    assert "holds a new one: sending with it" in log
    assert OLD_KEY not in log and NEW_KEY not in log


def test_a_systemd_credential_is_the_key(tmp_path: Path, stub_factory) -> None:
    stub = stub_factory("--api-key", NEW_KEY)
    credentials = tmp_path / "credentials"
    credentials.mkdir()
    key_file(credentials, NEW_KEY, 0o400).rename(credentials / "phycloud_api_key")
    bridge, settings = start_bridge(tmp_path, stub.endpoint, CREDENTIALS_DIRECTORY=str(credentials))
    try:
        delivered_everything(bridge, settings, stub)
    finally:
        bridge.stop()


@pytest.mark.parametrize("source", ["file", "environment"])
def test_sighup_reads_the_key_again_and_never_ends_the_bridge(
    tmp_path: Path, stub_factory, source: str
) -> None:
    stub = stub_factory("--api-key", NEW_KEY)
    key = (
        {"PHYCLOUD_API_KEY_FILE": str(key_file(tmp_path, NEW_KEY))}
        if source == "file"
        else {"PHYCLOUD_API_KEY": NEW_KEY}
    )
    bridge, settings = start_bridge(tmp_path, stub.endpoint, **key)
    log = tmp_path / "bridge.log"
    try:
        wait_for(lambda: stub.stats()["unique"] > 0, 60, "delivery")
        bridge.signal(signal.SIGHUP)
        expected = (
            "SIGHUP: read the API key again from PHYCLOUD_API_KEY_FILE"
            if source == "file"
            else "restart the service to change it"
        )
        wait_for(lambda: expected in log.read_text(), 30, "the SIGHUP line")
        assert bridge.process is not None and bridge.process.poll() is None  # still running
        delivered_everything(bridge, settings, stub)
    finally:
        bridge.stop()


def test_a_key_file_others_can_read_gets_a_warning(tmp_path: Path, stub_factory) -> None:
    stub = stub_factory("--api-key", NEW_KEY)
    path = key_file(tmp_path, NEW_KEY, 0o644)
    bridge, settings = start_bridge(tmp_path, stub.endpoint, PHYCLOUD_API_KEY_FILE=str(path))
    try:
        delivered_everything(bridge, settings, stub)
    finally:
        bridge.stop()
    log = (tmp_path / "bridge.log").read_text()
    assert f"is readable by other users (mode 0644): chmod 600 {path}" in log


@pytest.mark.parametrize(
    ("content", "extra", "words"),
    [
        ("", {}, "is empty"),
        ("two words\n", {}, "holds characters an API key cannot have"),
        (NEW_KEY, {"PHYCLOUD_API_KEY": OLD_KEY}, "both set: keep one"),
        (None, {}, "cannot be read (No such file or directory)"),
    ],
    ids=["empty", "spaces", "both", "missing"],
)
def test_a_bad_key_file_is_one_line_that_never_shows_its_content(
    tmp_path: Path, content: str | None, extra: dict[str, str], words: str
) -> None:
    path = tmp_path / "api_key"
    if content is not None:
        path.write_text(content)
    done = run_cli(
        "run",
        timeout=60,
        BRIDGE_INPUT="sim",
        QUEUE_PATH=str(tmp_path / "queue.db"),
        PHYCLOUD_API_KEY_FILE=str(path),
        **extra,
    )
    assert done.returncode == 2, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and words in lines[0], done.stderr
    for secret in ("two words", NEW_KEY, OLD_KEY):
        assert secret not in done.stderr


def test_the_key_file_is_a_setting_of_the_config_file(tmp_path: Path) -> None:
    path = key_file(tmp_path, NEW_KEY)
    config = tmp_path / "bridge.toml"
    config.write_text(f'phycloud_api_key_file = "{path}"\n')
    done = run_cli("config", "--config", str(config), timeout=60)
    assert done.returncode == 0, done.stderr
    assert str(path) in done.stdout and NEW_KEY not in done.stdout


def test_a_config_file_holding_the_key_readable_by_others_gets_a_warning(
    tmp_path: Path,
) -> None:
    config = tmp_path / "bridge.toml"
    config.write_text(f'phycloud_api_key = "{NEW_KEY}"\n')
    for mode, warned in ((0o644, True), (0o600, False)):
        config.chmod(mode)
        done = run_cli("config", "--config", str(config), timeout=60)
        assert done.returncode == 0, done.stderr
        assert ("is readable by other users (mode 0644)" in done.stderr) is warned
        assert NEW_KEY not in done.stderr + done.stdout

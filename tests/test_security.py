"""The secrets folder and the access rules generated from the role table (common/security.py). Pure."""

import os
import stat

import pytest

from common.security import (
    SecurityError,
    access_control,
    init_secrets,
    may_publish,
    password_for,
    read_passwords,
    read_secrets,
)


def test_init_writes_private_files_and_keeps_existing_passwords(tmp_path):
    sec = init_secrets(tmp_path / "s")
    assert stat.S_IMODE(os.stat(sec.passwords_file).st_mode) == 0o600
    first = read_passwords(sec.passwords_file)
    assert set(first) == {"camera", "vision", "gesture", "speech", "fusion", "ros2", "mic", "cli"}
    assert len(set(first.values())) == len(first) and all(len(p) >= 24 for p in first.values())
    sec = init_secrets(tmp_path / "s", {"operator": ["reader", "keyboard"]})
    again = read_passwords(sec.passwords_file)
    assert {u: again[u] for u in first} == first and "operator" in again
    assert read_secrets(tmp_path / "s").users["operator"] == ["reader", "keyboard"]
    assert password_for(tmp_path / "s", "vision") == first["vision"]


def test_errors_say_what_to_do(tmp_path):
    with pytest.raises(SecurityError, match="hri secure init"):
        password_for(tmp_path, "vision")
    init_secrets(tmp_path / "s")
    with pytest.raises(SecurityError, match="no password for user 'robot'"):
        password_for(tmp_path / "s", "robot")
    with pytest.raises(SecurityError, match="unknown role"):
        init_secrets(tmp_path / "s", {"eve": ["root"]})


def test_each_user_publishes_only_its_own_keys(tmp_path):
    sec = init_secrets(tmp_path / "s", {"operator": ["reader", "keyboard"]})
    allowed = {
        (u, k)
        for u in sec.users
        for k in ("hri/fusion/command", "hri/camera/cam0/frame", "hri/vision/cam0/objects", "hri/speech/kbd/transcript")
        if may_publish(sec, u, k, "hri")
    }
    assert allowed == {
        ("fusion", "hri/fusion/command"),
        ("camera", "hri/camera/cam0/frame"),
        ("ros2", "hri/camera/cam0/frame"),  # a ROS 2 camera as the stack's
        ("vision", "hri/vision/cam0/objects"),
        ("speech", "hri/speech/kbd/transcript"),
        ("operator", "hri/speech/kbd/transcript"),
    }
    acl = access_control(sec, "lab/robot7")
    assert acl["default_permission"] == "deny"
    puts = {r["id"]: r["key_exprs"] for r in acl["rules"] if "put" in r["messages"] and r["flows"] == ["ingress"]}
    assert puts["fusion-publish"] == [
        "lab/robot7/fusion/command",
        "lab/robot7/fusion/clarification",
        "lab/robot7/robot/profile",
    ]
    assert "reader-publish" not in puts
    subjects = {s["id"]: s["usernames"] for s in acl["subjects"]}
    assert subjects["role-fusion"] == ["fusion"] and subjects["role-reader"] == ["cli", "operator"]

"""The shipped ROS 2 message definitions (ros2/msg/): type hashes agree with two independent implementations,
the standard ones are the texts ROS ships, and the project's own package builds with colcon as declared."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

pytest.importorskip("rosbags")
zenoh_ros2_sdk_utils = pytest.importorskip("zenoh_ros2_sdk.utils")

from rosbags.typesys import Stores, get_typestore  # noqa: E402

from services.ros2 import types  # noqa: E402

SHIPPED = types.shipped_types()
OWN = types.MSG_ROOT / "hri_fusion_msgs"


def test_every_package_the_service_speaks_is_shipped():
    packages = {name.split("/")[0] for name in SHIPPED}
    assert packages == {
        "builtin_interfaces",
        "std_msgs",
        "sensor_msgs",
        "geometry_msgs",
        "vision_msgs",
        "hri_msgs",
        "hri_fusion_msgs",
        "tf2_msgs",
    }
    assert {"hri_msgs/msg/IdsList", "hri_msgs/msg/Skeleton2D", "hri_msgs/msg/LiveSpeech"} <= set(SHIPPED)
    assert {"vision_msgs/msg/Detection2DArray", "vision_msgs/msg/Detection3DArray"} <= set(SHIPPED)


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_type_hash_agrees_with_zenoh_ros2_sdk(name: str) -> None:
    """zenoh-ros2-sdk computes RIHS01 with its own parser and serialiser; rosbags (ours) must give the same."""
    dependencies = {other: text for other, text in SHIPPED.items() if other != name}
    theirs = zenoh_ros2_sdk_utils.compute_type_hash_from_msg(name, SHIPPED[name], dependencies)
    assert types.type_hash(name) == theirs
    assert re.fullmatch(r"RIHS01_[0-9a-f]{64}", theirs)


def test_standard_definitions_hash_as_ros_jazzy_ships_them():
    """The std/sensor/geometry texts we ship hash like rosbags' built-in Jazzy definitions (taken from ROS)."""
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    standard = [
        n
        for n in SHIPPED
        if n.split("/")[0] in ("builtin_interfaces", "std_msgs", "sensor_msgs", "geometry_msgs", "tf2_msgs")
    ]
    assert len(standard) >= 15
    for name in standard:
        assert types.type_hash(name) == jazzy.hash_rihs01(name), name


def test_no_char_fields():
    """rosbags and rosidl disagree on `char` hashes; none of ours uses it."""
    for name, text in SHIPPED.items():
        fields = [line.split("#")[0].split() for line in text.splitlines()]
        assert not any(f and f[0].startswith("char") for f in fields), name


def test_own_package_declares_every_message_and_its_dependencies():
    cmake = (OWN / "CMakeLists.txt").read_text()
    package = (OWN / "package.xml").read_text()
    own = sorted(p.name for p in (OWN / "msg").glob("*.msg"))
    assert own == ["Clarification.msg", "FusedCommand.msg", "Speaker.msg", "Target.msg"]
    for msg in own:
        assert f'"msg/{msg}"' in cmake
    used = {
        m.group(1)
        for p in (OWN / "msg").glob("*.msg")
        for m in re.finditer(r"^\s*(\w+)/\w+", p.read_text(), re.MULTILINE)
    }
    for dependency in used:
        assert f"<depend>{dependency}</depend>" in package and dependency in cmake


def test_own_messages_document_every_field():
    """Each field of hri_fusion_msgs has a comment saying what it is (docs/ros2.md points here)."""
    for path in sorted((OWN / "msg").glob("*.msg")):
        for line in Path(path).read_text().splitlines():
            code = line.split("#")[0].strip()
            if code and "=" not in code and code.split()[1] not in ("header",):
                assert "#" in line or _documented_below(path, code), f"{path.name}: {line}"


def _documented_below(path: Path, code: str) -> bool:
    """Grouped fields (weight_speech, weight_vision, ...) share the comment of the first of the group."""
    lines = [line.split("#") for line in path.read_text().splitlines()]
    codes = [(parts[0].strip(), len(parts) > 1) for parts in lines]
    index = [c for c, _ in codes].index(code)
    return any(has_comment for _, has_comment in codes[max(0, index - 3) : index])


def test_payloads_round_trip_through_cdr():
    """Every shipped type's default-ish message serialises and comes back equal (rosbags, our store)."""
    from services.ros2 import core
    from services.ros2.config import Ros2Config
    from testkit.examples import examples

    config, latch = Ros2Config(), core.Latch()
    convert = {
        "Persons": lambda s: core.persons_messages(s, config, latch),
        "Bodies": lambda s: core.bodies_messages(s, config),
        "Faces": lambda s: core.faces_messages(s, config),
        "Detections": lambda s: core.detections_messages(s, config),
        "FusedCommand": lambda s: core.fused_command_messages(s, config),
        "Clarification": lambda s: core.clarification_messages(s, config),
        "Frame": lambda s: core.camera_info_messages(s, config, latch),
    }
    seen = set()
    for sample in examples():
        for out in convert.get(type(sample).__name__, lambda s: [])(sample):
            data = types.serialize(out.message, out.type)
            assert data[:4] == b"\x00\x01\x00\x00"  # CDR little-endian encapsulation, as rmw publishes
            back = types.deserialize(data, out.type)
            assert types.serialize(back, out.type) == data
            seen.add(out.type)
    assert len(seen) >= 12

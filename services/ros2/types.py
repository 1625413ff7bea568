"""The ROS 2 message types hri-fusion speaks, read from the .msg text the project ships (ros2/msg/).

Nothing is fetched: every definition (std_msgs, sensor_msgs, geometry_msgs, vision_msgs, hri_msgs and the
project's own hri_fusion_msgs) is a file under ros2/msg/<package>/msg/<Name>.msg, parsed by `rosbags` into one
type store that serialises CDR and computes the RIHS01 type hashes rmw_zenoh puts in its key expressions.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

MSG_ROOT = Path(__file__).resolve().parent.parent.parent / "ros2" / "msg"


def shipped_types(root: Path = MSG_ROOT) -> dict[str, str]:
    """Every shipped definition: 'pkg/msg/Name' -> its .msg text."""
    return {f"{path.parent.parent.name}/msg/{path.stem}": path.read_text() for path in sorted(root.glob("*/msg/*.msg"))}


@cache
def typestore() -> Typestore:
    """A store holding the shipped definitions only (an empty store to start: nothing built in is used)."""
    store = get_typestore(Stores.EMPTY)
    for name, text in shipped_types().items():
        store.register(get_types_from_msg(text, name))
    return store


@cache
def type_hash(name: str) -> str:
    """RIHS01_<sha256 hex> of a shipped type, as rosidl computes it."""
    return typestore().hash_rihs01(name)


def dds_type_name(name: str) -> str:
    """'std_msgs/msg/String' -> 'std_msgs::msg::dds_::String_' (the type chunk of rmw_zenoh's key)."""
    package, kind, message = name.split("/")
    return f"{package}::{kind}::dds_::{message}_"


def message_class(name: str) -> Any:
    return typestore().types[name]


def serialize(message: Any, name: str) -> bytes:
    return bytes(typestore().serialize_cdr(message, name))


def deserialize(data: bytes, name: str) -> Any:
    return typestore().deserialize_cdr(data, name)

"""The ros2 service's settings: domain, namespace and topic names (standard library only: `hri export --help` and
`hri up --help` show them without rosbags installed)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from common.settings import setting


@dataclass(frozen=True)
class Ros2Config:
    """Where the ROS 2 side lives: domain, namespace and topic names (docs/ros2.md)."""

    key_layout: Literal["rmw_zenoh", "bridge"] = setting(
        "rmw_zenoh",
        "rmw_zenoh: ROS 2 nodes with rmw_zenoh_cpp (keys with type hash, liveliness, attachment); bridge: "
        "zenoh-bridge-ros2dds for DDS systems (the topic name as key, raw CDR)",
    )
    domain_id: int = setting(0, "ROS_DOMAIN_ID of the ROS 2 graph to join", at_least=0, at_most=232)
    namespace: str = setting(
        "/hri_fusion", "namespace of this node and of its own topics (command, objects, ...)", flag="--ros-namespace"
    )
    node_name: str = setting("hri_fusion", "the ROS 2 node's name (ros2 node list)")
    humans: str = setting("/humans", "root of the REP-155 people topics")
    image_topic: str = setting(
        "/camera/color/image_raw", "a ROS camera's sensor_msgs/Image to use as the stack's camera; '' = none"
    )
    compressed_topic: str = setting("", "or its sensor_msgs/CompressedImage (jpeg/png); '' = none")
    camera_info_topic: str = setting("/camera/color/camera_info", "the camera's sensor_msgs/CameraInfo")
    depth_topic: str = setting(
        "/camera/aligned_depth_to_color/image_raw", "depth aligned to the colour image (16UC1 mm or 32FC1 m); '' = none"
    )
    text_topic: str = setting("text_command", "std_msgs/String commands typed or said by the robot's own stack")
    busy_topic: str = setting("", "std_msgs/Bool, true while the robot is busy (only stop passes then); '' = none")
    state_topic: str = setting(
        "", "std_msgs/String, the robot's state as JSON (docs/robot.md): RobotState on the stack for fusion; '' = none"
    )
    cam: str = setting("ros0", "the camera id the ROS camera's frames get on the stack")

    def own(self, name: str) -> str:
        """A topic of this node: absolute as given, else under the namespace."""
        if name.startswith("/"):
            return name
        return f"{self.namespace.rstrip('/')}/{name}"

    def human(self, *parts: str) -> str:
        return "/".join([self.humans.rstrip("/"), *parts])

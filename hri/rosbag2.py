"""`hri export --rosbag2 IN.mcap OUT_DIR`: an `hri record` session as a rosbag2 bag (MCAP storage, CDR, ROS types).

The bag holds what the ros2 service would have published live (services/ros2/core.py: REP-155 people, vision_msgs
objects, hri_fusion_msgs commands and clarifications, the target pose, the planner prompt, CameraInfo), plus the
cameras as sensor_msgs/Image or CompressedImage, depth as 16UC1/32FC1 Images and transcripts as hri_msgs/LiveSpeech.
`ros2 bag play OUT_DIR` and Foxglove open it (the message definitions travel in the bag). Recordings are read
through hri/recording.py's SessionReader; each message is stamped with its receive time in the recording.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from common.codec import decode
from common.depth import depth_units
from common.keys import Keys
from common.schema import (
    Bodies,
    Clarification,
    DepthFrame,
    Detections,
    Faces,
    Frame,
    FusedCommand,
    InvalidSample,
    Persons,
    Sample,
    Transcript,
)
from services.ros2.config import Ros2Config

if TYPE_CHECKING:  # the core imports rosbags: only when an export runs
    from services.ros2.core import Latch, Outgoing

EXPORT_EXAMPLES = """\
examples:
  hri export --rosbag2 session.mcap session_bag        # then: ros2 bag play session_bag
  hri export --rosbag2 session.mcap bag --ros-namespace /robot7/hri
"""


def bag_messages(sample: Sample, config: Ros2Config, latch: Latch) -> list[Outgoing]:
    """The ROS messages one recorded sample becomes (none for a sample with no ROS counterpart, e.g. hands)."""
    from services.ros2 import core

    converters: dict[type, Callable[[Any], list[Outgoing]]] = {
        Persons: lambda s: core.persons_messages(s, config, latch),
        Bodies: lambda s: core.bodies_messages(s, config),
        Faces: lambda s: core.faces_messages(s, config),
        Detections: lambda s: core.detections_messages(s, config),
        FusedCommand: lambda s: core.fused_command_messages(s, config),
        Clarification: lambda s: core.clarification_messages(s, config),
        Frame: lambda s: core.camera_info_messages(s, config, latch) + core.image_messages(s, config),
        DepthFrame: lambda s: core.depth_messages(s, depth_units(s), config),
        Transcript: lambda s: core.transcript_messages(s, config),
    }
    convert = converters.get(type(sample))
    return convert(sample) if convert is not None else []


@dataclass
class ExportSummary:
    topics: Counter[str] = field(default_factory=Counter)  # ROS topic -> messages written
    skipped: Counter[str] = field(default_factory=Counter)  # why samples were left out -> how many


def qos_profile(latched: bool) -> Any:
    """The QoS a topic is offered with in the bag (`ros2 bag play` republishes with it): reliable, keep-last;
    latched topics transient local."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    never = QosTime(sec=0, nsec=0)
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=1 if latched else 10,
        reliability=QosReliability.RELIABLE,
        durability=QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
        deadline=never,
        lifespan=never,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=never,
        avoid_ros_namespace_conventions=False,
    )


def export_rosbag2(source: Path, target: Path, config: Ros2Config, prefix: str = "hri") -> ExportSummary:
    """Write `target` (a new folder: metadata.yaml + one .mcap) from the recording `source`."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from hri.recording import SessionReader
    from services.ros2.core import Latch
    from services.ros2.types import serialize, typestore

    keys, latch, summary = Keys(prefix), Latch(), ExportSummary()
    reader = SessionReader(source)
    connections: dict[str, Any] = {}
    try:
        with Writer(target, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            for recorded in reader.messages():
                schema = keys.schema_for(recorded.key)
                if schema is None:
                    summary.skipped["not a contract key"] += 1
                    continue
                try:
                    outs = bag_messages(decode(recorded.payload, schema), config, latch)
                except (InvalidSample, ValueError) as exc:
                    summary.skipped[f"undecodable ({type(exc).__name__})"] += 1
                    continue
                for out in outs:
                    connection = connections.get(out.topic)
                    if connection is None:
                        connection = connections[out.topic] = writer.add_connection(
                            out.topic, out.type, typestore=typestore(), offered_qos_profiles=[qos_profile(out.latched)]
                        )
                    writer.write(connection, recorded.log_ns, serialize(out.message, out.type))
                    summary.topics[out.topic] += 1
    finally:
        reader.close()
    return summary


def add_export_arguments(p: argparse.ArgumentParser) -> None:
    from common.settings import add_settings

    p.add_argument(
        "--rosbag2", nargs=2, required=True, metavar=("IN.mcap", "OUT_DIR"), help="recording, new bag folder"
    )
    add_settings(p.add_argument_group("ROS 2 names (as the ros2 service)"), Ros2Config)
    p.set_defaults(func=cmd_export)


def cmd_export(args: argparse.Namespace) -> int:
    from common.settings import from_args
    from hri.recording import RecordingError

    source, target = (Path(p) for p in args.rosbag2)
    if target.exists():
        print(f"hri export: {target} exists; a bag is written into a new folder", file=sys.stderr)
        return 2
    try:
        summary = export_rosbag2(source, target, from_args(Ros2Config, args), args.prefix or "hri")
    except RecordingError as exc:
        print(f"hri export: {exc}", file=sys.stderr)
        return 2
    for topic, n in sorted(summary.topics.items()):
        print(f"{n:8d}  {topic}")
    for reason, n in summary.skipped.items():
        print(f"{n:8d}  samples skipped: {reason}")
    print(f"wrote {target} ({sum(summary.topics.values())} messages on {len(summary.topics)} topics)")
    return 0

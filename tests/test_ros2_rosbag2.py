"""`hri export --rosbag2`: a recording with real RGB-D captures and the contract's samples becomes a rosbag2 bag
that two independent readers open: rosbags (metadata.yaml + MCAP storage) and mcap-ros2-support (decoding with
the message definitions stored in the bag, not ours)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import msgspec
import numpy as np
import pytest

pytest.importorskip("rosbags")
mcap_ros2_reader = pytest.importorskip("mcap_ros2.reader")

import yaml  # noqa: E402
from rosbags.rosbag2 import Reader  # noqa: E402

from common.codec import encode  # noqa: E402
from common.depth import depth_frame  # noqa: E402
from common.keys import Keys  # noqa: E402
from common.schema import CameraInfo, Detections, Frame, FusedCommand, Target  # noqa: E402
from hri.recording import SessionWriter  # noqa: E402
from services.ros2.types import deserialize  # noqa: E402
from testkit.examples import T, examples  # noqa: E402
from testkit.shared import shared_path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
NS = 1_000_000_000


@pytest.fixture(scope="module")
def realsense() -> dict[str, np.ndarray]:
    path = shared_path("data/rgbd/realsense_tabletop/realsense_frame.npz")  # skips, saying why, when absent
    with np.load(path) as npz:
        return {k: npz[k] for k in npz.files}


def recording(path: Path, capture: dict[str, np.ndarray]) -> dict[str, object]:
    """A session as `hri record` writes it: a real RealSense frame and its depth, and the contract's samples."""
    width, height = (int(v) for v in capture["image_size"])
    fx, fy, cx, cy = (float(v) for v in capture["intrinsics"])
    info = CameraInfo(width=width, height=height, k=[fx, 0, cx, 0, fy, cy, 0, 0, 1], frame_id="rs_optical")
    bgr = np.ascontiguousarray(capture["color"][:, :, ::-1])
    millimetres = capture["depth"].reshape(height, width)
    frame = Frame(
        stamp=T, source="camera/t", seq=1, cam="rs", width=width, height=height, encoding="bgr8", data=bgr.tobytes()
    )
    frame = msgspec.structs.replace(frame, camera_info=info)
    depth = depth_frame(
        millimetres, stamp=T, source="camera/t", seq=1, cam="rs", depth_scale=0.001, camera_info=info, compression="png"
    )
    samples: dict[str, object] = {"hri/camera/rs/frame": frame, "hri/camera/rs/depth": depth}
    for sample in examples():
        kind = type(sample).__name__
        keys = {
            "Persons": "hri/gesture/cam0/persons",
            "Faces": "hri/gesture/cam0/faces",
            "Bodies": "hri/gesture/cam0/bodies",
            "Detections": "hri/vision/cam0/objects",
            "Transcript": "hri/speech/mic0/transcript",
            "Clarification": "hri/fusion/clarification",
            "Hands": "hri/gesture/cam0/hands",  # no ROS counterpart: left out
        }
        if kind in keys:
            samples[keys[kind]] = sample
        if kind == "FusedCommand":
            target = Target(**{**msgspec.structs.asdict(sample.target), "position": [0.1, -0.05, 0.9]})
            samples["hri/fusion/command"] = msgspec.structs.replace(sample, target=target)
    with open(path, "wb") as stream:
        writer = SessionWriter(stream, Keys("hri"), compression="zstd")
        for i, (key, sample) in enumerate(samples.items()):
            writer.add(key, encode(sample), int(T * NS) + i * 1000)  # type: ignore[arg-type]
        writer.finish()
    return samples


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory, realsense: dict[str, np.ndarray]) -> tuple[Path, dict[str, object]]:
    folder = tmp_path_factory.mktemp("export")
    samples = recording(folder / "session.mcap", realsense)
    out = folder / "bag"
    done = subprocess.run(
        [sys.executable, "-m", "hri.cli", "export", "--rosbag2", str(folder / "session.mcap"), str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert "/hri_fusion/command" in done.stdout
    return out, samples


def test_bag_layout_is_rosbag2_mcap(bag: tuple[Path, dict[str, object]]):
    out, _ = bag
    metadata = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert metadata["storage_identifier"] == "mcap"
    assert [Path(p).suffix for p in metadata["relative_file_paths"]] == [".mcap"]
    topics = {t["topic_metadata"]["name"]: t["topic_metadata"] for t in metadata["topics_with_message_count"]}
    assert topics["/hri_fusion/command"]["type"] == "hri_fusion_msgs/msg/FusedCommand"
    assert all(t["serialization_format"] == "cdr" for t in topics.values())
    latched = topics["/humans/persons/person_1/face_id"]["offered_qos_profiles"][0]  # ros2 bag play re-latches it
    assert (latched["durability"], latched["depth"]) == ("transient_local", 1)
    assert topics["/hri_fusion/command"]["offered_qos_profiles"][0]["durability"] == "volatile"


def test_rosbags_reads_every_message_back(bag: tuple[Path, dict[str, object]], realsense: dict[str, np.ndarray]):
    out, samples = bag
    with Reader(out) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        decoded = {c.topic: deserialize(raw, c.msgtype) for c, _, raw in reader.messages()}
    assert types["/hri_fusion/rs/image_raw"] == "sensor_msgs/msg/Image"
    assert types["/hri_fusion/rs/depth/image_raw"] == "sensor_msgs/msg/Image"
    assert types["/humans/persons/tracked"] == "hri_msgs/msg/IdsList"
    assert types["/hri_fusion/objects/detections_3d"] == "vision_msgs/msg/Detection3DArray"
    assert not any("hands" in t for t in types)

    image = decoded["/hri_fusion/rs/image_raw"]
    height, width = realsense["color"].shape[:2]
    pixels = np.asarray(image.data).reshape(height, width, 3)
    assert image.encoding == "bgr8" and np.array_equal(pixels[:, :, ::-1], realsense["color"])
    depth = decoded["/hri_fusion/rs/depth/image_raw"]
    assert depth.encoding == "16UC1" and depth.header.frame_id == "rs_optical"
    assert np.array_equal(np.asarray(depth.data).view("<u2"), realsense["depth"].reshape(-1))  # millimetres, exact
    info = decoded["/hri_fusion/rs/camera_info"]
    assert info.k[0] == pytest.approx(float(realsense["intrinsics"][0]))
    command = decoded["/hri_fusion/command"]
    expected = samples["hri/fusion/command"]
    assert isinstance(expected, FusedCommand)
    assert command.id == expected.id and command.target.position.z == pytest.approx(0.9)
    assert decoded["/hri_fusion/target_pose"].pose.position.z == pytest.approx(0.9)


def test_mcap_ros2_support_decodes_with_the_bags_own_definitions(bag: tuple[Path, dict[str, object]]):
    out, samples = bag
    (path,) = out.glob("*.mcap")
    seen = {m.channel.topic: m.ros_msg for m in mcap_ros2_reader.read_ros2_messages(str(path))}
    detections = samples["hri/vision/cam0/objects"]
    assert isinstance(detections, Detections)
    in_3d = seen["/hri_fusion/objects/detections_3d"].detections
    placed = [o for o in detections.objects if o.position is not None]
    assert [d.id for d in in_3d] == [o.id for o in placed]
    assert in_3d[0].bbox.center.position.z == pytest.approx(placed[0].position[2])  # type: ignore[index]
    assert seen["/hri_fusion/command"].intent == "pick_up"
    assert seen["/hri_fusion/clarification"].question
    assert len(seen["/humans/bodies/person_1/skeleton2d"].skeleton) == 18
    assert seen["/hri_fusion/speech/mic0"].final == "pick up that cup"
    assert seen["/hri_fusion/rs/depth/image_raw"].width == 1280

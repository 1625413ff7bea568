"""The ros2 service's pure core: the stack's samples as ROS 2 messages and a ROS camera/text as the stack's."""

from __future__ import annotations

import math
from pathlib import Path

import msgspec
import numpy as np
import pytest

pytest.importorskip("rosbags")

from common.image import decode_image, jpeg_size  # noqa: E402
from common.schema import (  # noqa: E402
    Bodies,
    Clarification,
    Detections,
    Face,
    Faces,
    FusedCommand,
    InvalidSample,
    Person,
    Persons,
    Target,
    Weights,
)
from services.ros2 import core  # noqa: E402
from services.ros2.config import Ros2Config  # noqa: E402
from services.ros2.core import Outgoing  # noqa: E402
from testkit.examples import T, examples  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
PHOTO = ROOT / "data" / "images" / "apple.jpg"
CONFIG = Ros2Config()


def example(kind: type) -> object:
    return next(e for e in examples() if isinstance(e, kind))


def by_topic(outs: list[Outgoing]) -> dict[str, Outgoing]:
    return {o.topic: o for o in outs}


def person(pid: str, **fields: object) -> Person:
    return Person(id=pid, bbox=[10.0, 10.0, 100.0, 300.0], score=0.9, **fields)  # type: ignore[arg-type]


def persons(*people: Person) -> Persons:
    return Persons(stamp=T, source="gesture/a", seq=1, cam="cam0", width=640, height=480, persons=list(people))


# -- people ------------------------------------------------------------------------------------------------------
def test_ids_become_ros_name_tokens():
    assert core.ros_id("person-1") == "person_1"
    assert core.ros_id("7") == "id_7"
    assert core.ros_id("abc_D9") == "abc_D9"


def test_persons_tracked_links_engagement_and_voices():
    latch = core.Latch()
    sample = persons(
        person("p-1", face="f-1", has_body=True, speaking=0.7, engaged=True),
        person("p-2", speaking=0.2, engaged=False),
        person("p-3"),
        person("p-4", engaged=True, engagement="disengaging"),  # the REP-155 level, when given, is published
    )
    outs = by_topic(core.persons_messages(sample, CONFIG, latch))
    assert list(outs["/humans/persons/tracked"].message.ids) == ["p_1", "p_2", "p_3", "p_4"]
    assert list(outs["/humans/voices/tracked"].message.ids) == ["p_1", "p_2"]  # speaking measured: a voice
    assert outs["/humans/persons/p_1/face_id"].message.data == "f_1"
    assert outs["/humans/persons/p_1/body_id"].message.data == "p_1"
    assert outs["/humans/persons/p_2/body_id"].message.data == ""  # no skeleton
    assert outs["/humans/persons/p_1/voice_id"].message.data == "p_1"
    assert all(o.latched for t, o in outs.items() if t.endswith("_id"))
    levels = {t.split("/")[3]: o.message.level for t, o in outs.items() if t.endswith("engagement_status")}
    assert levels == {"p_1": 3, "p_2": 1, "p_3": 0, "p_4": 4}  # ENGAGED, DISENGAGED, UNKNOWN, DISENGAGING
    assert outs["/humans/voices/p_1/is_speaking"].message.data is True
    assert outs["/humans/voices/p_2/is_speaking"].message.data is False
    assert "/humans/voices/p_3/is_speaking" not in outs
    assert outs["/humans/persons/tracked"].message.header.stamp.sec == int(T)


def test_latched_ids_are_sent_again_only_when_they_change():
    latch = core.Latch()
    first = persons(person("p-1", face="f-1"))
    core.persons_messages(first, CONFIG, latch)
    again = by_topic(core.persons_messages(first, CONFIG, latch))
    assert not any(o.latched for o in again.values())  # nothing changed
    assert "/humans/persons/tracked" in again  # the lists go out every frame
    moved = by_topic(core.persons_messages(persons(person("p-1", face="f-2")), CONFIG, latch))
    assert [t for t, o in moved.items() if o.latched] == ["/humans/persons/p_1/face_id"]
    assert moved["/humans/persons/p_1/face_id"].message.data == "f_2"


def test_skeleton_is_openpose_coco_from_mediapipe_normalised():
    bodies = example(Bodies)
    assert isinstance(bodies, Bodies)
    outs = core.bodies_messages(bodies, CONFIG)
    body = bodies.bodies[0]
    assert body.person is not None
    tracked, skeleton = outs[0].message, outs[1]
    assert list(tracked.ids) == [core.ros_id(body.person)]
    assert skeleton.topic == f"/humans/bodies/{core.ros_id(body.person)}/skeleton2d"
    points = skeleton.message.skeleton
    assert len(points) == 18
    w, h = bodies.width, bodies.height
    assert points[0].x == pytest.approx(body.landmarks[0][0] / w, abs=1e-6)  # NOSE
    left_wrist = points[7]  # Skeleton2D.LEFT_WRIST = MediaPipe 15
    assert (left_wrist.x, left_wrist.y) == pytest.approx((body.landmarks[15][0] / w, body.landmarks[15][1] / h))
    neck = points[1]  # between the shoulders (MediaPipe 11, 12)
    assert neck.x == pytest.approx((body.landmarks[11][0] + body.landmarks[12][0]) / 2 / w, abs=1e-6)
    assert all(0.0 <= p.x <= 1.0 and 0.0 <= p.y <= 1.0 and p.c == pytest.approx(0.9) for p in points)


def test_bodies_of_unknown_people_are_not_listed():
    bodies = example(Bodies)
    assert isinstance(bodies, Bodies)
    anonymous = msgspec.structs.replace(bodies, bodies=[msgspec.structs.replace(b, person=None) for b in bodies.bodies])
    assert list(core.bodies_messages(anonymous, CONFIG)[0].message.ids) == []


def test_faces_tracked_and_normalised_roi():
    faces = Faces(
        stamp=T,
        source="gesture/a",
        seq=1,
        cam="cam0",
        width=640,
        height=480,
        faces=[Face(id="face-1", bbox=[320.0, 120.0, 64.0, 96.0], score=0.8)],
    )
    outs = by_topic(core.faces_messages(faces, CONFIG))
    assert list(outs["/humans/faces/tracked"].message.ids) == ["face_1"]
    roi = outs["/humans/faces/face_1/roi"].message
    assert (roi.xmin, roi.ymin, roi.xmax, roi.ymax) == pytest.approx((0.5, 0.25, 0.6, 0.45))
    assert roi.c == pytest.approx(0.8)


# -- objects and commands ----------------------------------------------------------------------------------------
def test_detections_2d_for_all_3d_in_metres_for_those_with_depth():
    detections = example(Detections)
    assert isinstance(detections, Detections)
    outs = by_topic(core.detections_messages(detections, CONFIG))
    in_2d = outs["/hri_fusion/objects/detections_2d"].message.detections
    assert [d.id for d in in_2d] == [o.id for o in detections.objects]
    first = detections.objects[0]
    assert in_2d[0].results[0].hypothesis.class_id == first.label
    assert in_2d[0].bbox.center.position.x == pytest.approx(first.bbox[0] + first.bbox[2] / 2)
    assert in_2d[0].bbox.size_y == pytest.approx(first.bbox[3])
    placed = [o for o in detections.objects if o.position is not None]
    in_3d = outs["/hri_fusion/objects/detections_3d"].message
    assert [d.id for d in in_3d.detections] == [o.id for o in placed]
    centre = in_3d.detections[0].bbox.center.position
    assert placed[0].position is not None and placed[0].extent is not None
    assert (centre.x, centre.y, centre.z) == pytest.approx(placed[0].position)
    size = in_3d.detections[0].bbox.size
    assert (size.x, size.y, size.z) == pytest.approx(placed[0].extent)
    assert in_3d.header.frame_id == (detections.frame_id or detections.cam)


def test_no_detections_3d_without_depth():
    detections = example(Detections)
    assert isinstance(detections, Detections)
    flat = msgspec.structs.replace(detections, objects=[detections.objects[0]])
    assert [o.type for o in core.detections_messages(flat, CONFIG)] == [core.DETECTIONS_2D]


def placed_target() -> Target:
    return Target(
        id="o2",
        label="cup",
        color="red",
        bbox=[5, 6, 7, 8],
        center=[8.5, 10.0],
        score=0.8,
        cam="cam0",
        position=[0.1, -0.05, 0.9],
        extent=[0.08, 0.1, 0.06],
        frame_id="cam0_optical",
    )


def test_command_target_pose_in_the_optical_frame_prompt_and_speech():
    cmd = example(FusedCommand)
    assert isinstance(cmd, FusedCommand)
    cmd = msgspec.structs.replace(cmd, target=placed_target())
    outs = by_topic(core.fused_command_messages(cmd, CONFIG))
    message = outs["/hri_fusion/command"].message
    assert (message.id, message.intent, message.text) == (cmd.id, cmd.intent, cmd.text)
    assert message.has_target and message.target.has_position and message.target.id == "o2"
    assert message.header.frame_id == "cam0_optical"
    assert message.speaker.person_id == "person_1" and message.speaker.addressed == 1
    assert message.confidence == pytest.approx(cmd.confidence)
    pose = outs["/hri_fusion/target_pose"].message
    assert pose.header.frame_id == "cam0_optical"
    assert (pose.pose.position.x, pose.pose.position.y, pose.pose.position.z) == pytest.approx((0.1, -0.05, 0.9))
    assert pose.pose.orientation.w == 1.0
    assert outs["/hri_fusion/planner_prompt"].message.data == cmd.prompt
    speech = outs["/humans/voices/person_1/speech"].message
    assert speech.final == cmd.text


def test_a_stop_has_no_target_nor_pose_and_unsaid_motion_is_nan():
    stop = FusedCommand(
        stamp=T,
        source="fusion/a",
        id="c9",
        intent="stop",
        confidence=1.0,
        weights=Weights(speech=0.0, vision=0.0, gesture=1.0),
        inputs={"gesture": T},
        explanation="open palm",
        prompt="Command: stop",
        gesture="open_palm",
    )
    outs = by_topic(core.fused_command_messages(stop, CONFIG))
    assert set(outs) == {"/hri_fusion/command", "/hri_fusion/planner_prompt"}
    message = outs["/hri_fusion/command"].message
    assert not message.has_target and not message.has_location
    assert math.isnan(message.motion_distance) and message.speaker.method == "unknown"


def test_clarification_with_candidates():
    question = example(Clarification)
    assert isinstance(question, Clarification)
    message = core.clarification_messages(question, CONFIG)[0].message
    assert message.question == question.question and message.reason == question.reason
    assert [c.id for c in message.candidates] == [c.id for c in question.candidates]


def test_namespace_and_absolute_topic_names():
    config = Ros2Config(namespace="/robot7/hri", humans="/robot7/humans")
    assert config.own("command") == "/robot7/hri/command"
    assert config.own("/elsewhere") == "/elsewhere"
    assert config.human("persons", "tracked") == "/robot7/humans/persons/tracked"


def test_only_stop_passes_while_the_robot_is_busy():
    cmd = example(FusedCommand)
    assert isinstance(cmd, FusedCommand)
    stop = msgspec.structs.replace(cmd, intent="stop")
    assert core.passes_while_busy(cmd, busy=False)
    assert not core.passes_while_busy(cmd, busy=True)
    assert core.passes_while_busy(stop, busy=True)


# -- a ROS camera and text ---------------------------------------------------------------------------------------
def ros_camera_info(width: int, height: int) -> object:
    info = core.camera_info_message(
        core.CameraInfo(
            width=width, height=height, k=[500.0, 0, width / 2, 0, 500.0, height / 2, 0, 0, 1.0], frame_id="cam_opt"
        ),
        T,
    )
    return info


def ros_image(pixels: np.ndarray, encoding: str, stamp: float = T, pad: int = 0) -> object:
    height, width = pixels.shape[:2]
    rows = pixels.reshape(height, -1).view(np.uint8)
    padded = np.concatenate([rows, np.zeros((height, pad), np.uint8)], axis=1) if pad else rows
    return core.msg(
        core.IMAGE,
        header=core.header(stamp, "cam_opt"),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=padded.shape[1],
        data=np.ascontiguousarray(padded).reshape(-1),
    )


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    data = PHOTO.read_bytes()
    return decode_image(data, "jpeg", *jpeg_size(data)).copy()


def test_rgb8_image_with_row_padding_becomes_the_same_bgr_frame(photo: np.ndarray):
    camera = core.CameraBridge(CONFIG, "ros2/test")
    height, width = photo.shape[:2]
    camera.set_info(ros_camera_info(width, height))
    frame = camera.frame(ros_image(photo[:, :, ::-1], "rgb8", pad=6), now=T + 5)
    assert (frame.width, frame.height, frame.encoding, frame.cam) == (width, height, "bgr8", "ros0")
    assert np.array_equal(decode_image(frame.data, "bgr8", width, height), photo)
    assert frame.stamp == pytest.approx(T) and frame.camera_info is not None
    assert frame.camera_info.fx == 500.0 and frame.camera_info.frame_id == "cam_opt"


def test_mono8_and_unknown_encodings(photo: np.ndarray):
    camera = core.CameraBridge(CONFIG, "ros2/test")
    grey = photo[:, :, 1].copy()
    frame = camera.frame(ros_image(grey, "mono8"), now=T)
    img = decode_image(frame.data, "bgr8", frame.width, frame.height)
    assert np.array_equal(img[:, :, 0], grey) and np.array_equal(img[:, :, 2], grey)
    assert frame.camera_info is None  # no CameraInfo received
    with pytest.raises(InvalidSample):
        camera.frame(ros_image(grey, "bayer_rggb8"), now=T)
    small = core.CameraBridge(CONFIG, "ros2/test", max_pixels=grey.size - 1)
    with pytest.raises(InvalidSample, match="over the cap"):  # refused before any conversion
        small.frame(ros_image(grey, "mono8"), now=T)


def test_compressed_jpeg_passes_through_with_its_size():
    data = PHOTO.read_bytes()
    camera = core.CameraBridge(CONFIG, "ros2/test")
    message = core.msg(
        core.COMPRESSED_IMAGE,
        header=core.header(0.0),
        format="rgb8; jpeg compressed bgr8",
        data=np.frombuffer(data, np.uint8),
    )
    frame = camera.compressed_frame(message, now=T + 1, size=jpeg_size(data))
    assert frame.encoding == "jpeg" and frame.data == data and frame.stamp == T + 1  # stamp 0: now
    assert (frame.width, frame.height) == jpeg_size(data)


def test_aligned_depth_shares_the_colour_frames_seq(photo: np.ndarray):
    camera = core.CameraBridge(CONFIG, "ros2/test")
    height, width = photo.shape[:2]
    millimetres = np.full((height, width), 850, np.uint16)
    depth_msg = ros_image(millimetres, "16UC1")
    with pytest.raises(InvalidSample):  # depth means nothing without the intrinsics
        camera.depth(depth_msg, now=T)
    camera.set_info(ros_camera_info(width, height))
    depth = camera.depth(depth_msg, now=T)
    colour = camera.frame(ros_image(photo, "bgr8"), now=T)
    later = camera.frame(ros_image(photo, "bgr8", stamp=T + 0.1), now=T)
    assert depth.seq == colour.seq != later.seq
    assert depth.depth_scale == 0.001 and depth.encoding == "16UC1"
    assert np.frombuffer(depth.data, "<u2").reshape(height, width)[10, 10] == 850


def test_text_becomes_a_typed_transcript():
    transcript = core.text_transcript("  stop  ", now=T, source="ros2/test")
    assert transcript is not None
    assert (transcript.text, transcript.mic, transcript.end, transcript.final) == ("stop", "ros", T, True)
    assert core.text_transcript("   ", now=T, source="ros2/test") is None


def test_per_id_topics_of_people_no_camera_tracks_are_gone():
    tracked = core.Tracked()
    topics = [
        "/humans/persons/tracked",
        "/humans/persons/p_1/face_id",
        "/humans/persons/p_2/engagement_status",
        "/humans/faces/f_1/roi",
    ]
    outs = core.persons_messages(persons(person("p-1"), person("p-2")), CONFIG, core.Latch())
    for kind, ids in core.tracked_ids(outs, CONFIG).items():
        tracked.update(kind, "cam0", ids)
    assert tracked.gone("persons", topics, CONFIG) == []
    tracked.update("persons", "cam0", ["p_1"])
    assert tracked.gone("persons", topics, CONFIG) == ["/humans/persons/p_2/engagement_status"]
    tracked.update("persons", "cam1", ["p_2"])  # another camera still sees p_2
    assert tracked.gone("persons", topics, CONFIG) == []
    assert tracked.gone("faces", topics, CONFIG) == ["/humans/faces/f_1/roi"]  # no camera reported faces


def test_the_robots_state_from_ros_json_and_the_profile_to_ros():
    """docs/robot.md: a std_msgs/String of JSON -> RobotState (stamp: the JSON's, else now); anything else is refused
    with the contract's reasons; the profile goes out once as latched JSON, again only when it changes."""
    from common.robot import DEFAULT
    from common.schema import InvalidSample as Invalid

    state = core.robot_state('{"status": "failed", "reason": "couldn\'t reach it", "command": "c1"}', 5.0, "ros2/x")
    assert (state.status, state.reason, state.command, state.stamp, state.source) == (
        "failed",
        "couldn't reach it",
        "c1",
        5.0,
        "ros2/x",
    )
    assert core.robot_state('{"status": "idle", "stamp": 7.5}', 9.0, "ros2/x").stamp == 7.5
    for text, reason in [
        ("not json", "bad_value"),
        ("[1, 2]", "not_a_map"),
        ('{"status": "asleep"}', "bad_value"),
        ('{"status": "failed"}', "bad_value"),
        ('{"status": "idle", "holding": {"id": "x"}}', "missing_field"),
    ]:
        with pytest.raises(Invalid) as err:
            core.robot_state(text, 5.0, "ros2/x")
        assert err.value.reason == reason, (text, err.value)
    latch = core.Latch()
    (out,) = core.profile_messages(DEFAULT.sample(5.0, "fusion/x"), CONFIG, latch)
    assert out.topic == "/hri_fusion/robot_profile" and out.latched and '"name": "default"' in out.message.data
    assert core.profile_messages(DEFAULT.sample(6.0, "fusion/x"), CONFIG, latch) == []  # unchanged: not sent again


def test_the_camera_mount_goes_on_tf_static():
    """A level camera 1.2 m up (rpy [-pi/2, 0, -pi/2]): the optical z axis (forward) is the base's x, optical x (right)
    the base's -y, optical y (down) the base's -z."""
    from common.robot import parse_profile

    text = 'name = "r"\n[camera]\nframe_id = "cam0_optical"\nxyz = [0.1, 0, 1.2]\nrpy = [-1.5707963, 0, -1.5707963]\n'
    outs = core.profile_messages(parse_profile(text).sample(5.0, "fusion/x"), CONFIG, core.Latch())
    (tf,) = [o for o in outs if o.topic == "/tf_static"]
    assert tf.latched and tf.type == core.TF_MESSAGE
    (t,) = tf.message.transforms
    assert (t.header.frame_id, t.child_frame_id) == ("base_link", "cam0_optical")
    assert (t.transform.translation.x, t.transform.translation.z) == (0.1, 1.2)
    q = t.transform.rotation
    w, x, y, z = q.w, q.x, q.y, q.z
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    assert np.allclose(rotation @ [0, 0, 1], [1, 0, 0], atol=1e-6)  # optical forward = base forward
    assert np.allclose(rotation @ [1, 0, 0], [0, -1, 0], atol=1e-6)  # optical right = base -y (right)
    assert np.allclose(rotation @ [0, 1, 0], [0, 0, -1], atol=1e-6)  # optical down = base down
    from services.ros2.types import serialize

    assert serialize(tf.message, tf.type)  # CDR of the shipped definition

"""The real stack (router, vision, fusion, ros2) seen from a ROS 2 node over rmw_zenoh.

zenoh-ros2-sdk stands in for the ROS 2 node (it implements rmw_zenoh's keys, liveliness tokens and attachment in
Python, with the .msg definitions we ship: nothing is fetched). The node sends a real photo as a
sensor_msgs/Image with its CameraInfo; vision finds the candies in it and the node receives them as
vision_msgs/Detection2DArray; it types "pick up the red candy" on the text topic and receives the grounded
hri_fusion_msgs/FusedCommand; it receives people (samples we publish as the gesture service would) as REP-155
hri_msgs, and a latched id as a late joiner, as rmw_zenoh's transient-local subscription gets it.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Any

import msgspec
import numpy as np
import pytest

pytest.importorskip("rosbags")
sdk = pytest.importorskip("zenoh_ros2_sdk")

import zenoh  # noqa: E402
from zenoh import ext  # noqa: E402
from zenoh_ros2_sdk import message_registry  # noqa: E402
from zenoh_ros2_sdk.session import ZenohSession  # noqa: E402

from common.image import decode_image, png_size  # noqa: E402
from common.schema import Frame, FusedCommand  # noqa: E402
from services.ros2 import core, rmw  # noqa: E402
from services.ros2.types import MSG_ROOT, dds_type_name, deserialize, serialize, type_hash  # noqa: E402
from testkit.examples import examples  # noqa: E402
from testkit.harness import DATA, Client, ProcessGroup  # noqa: E402

pytestmark = pytest.mark.timeout(240)
TABLE = DATA / "demo" / "table.png"
FPS = 5.0


class Inbox:
    """Messages a ROS subscriber received, waited on by condition."""

    def __init__(self) -> None:
        self.items: list[Any] = []
        self._cond = threading.Condition()

    def __call__(self, message: Any) -> None:
        with self._cond:
            self.items.append(message)
            self._cond.notify_all()

    def wait_for(self, test: Any, timeout: float, what: str) -> Any:
        """The latest received message passing `test`, waiting up to `timeout` s for one."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                found = [m for m in self.items if test(m)]
                if found:
                    return found[-1]
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"no {what} within {timeout} s (received {len(self.items)} messages)")
                self._cond.wait(left)


@pytest.fixture(scope="module")
def stack() -> Iterator[ProcessGroup]:
    group = ProcessGroup()
    try:
        group.router()
        group.service("vision", "--backend", "color", "--labels", str(DATA / "demo" / "labels.json"))
        group.service("fusion")
        group.service("ros2")
        client = Client(group.endpoint)
        for name in ("vision", "fusion", "ros2"):
            client.wait_alive(name, timeout=90)
        client.close()
        yield group
    finally:
        print(group.logs())  # shown by pytest when a test of this module failed
        group.close()


@pytest.fixture(scope="module")
def ros(stack: ProcessGroup) -> Iterator[None]:
    """zenoh-ros2-sdk on the stack's router, reading only the shipped .msg files."""
    saved = message_registry._registry
    message_registry._registry = message_registry.MessageRegistry(messages_dir=str(MSG_ROOT))
    ZenohSession.get_instance("127.0.0.1", stack.port)
    try:
        yield
    finally:
        ZenohSession._instance.close()
        ZenohSession._instance = None
        message_registry._registry = saved


def subscriber(stack: ProcessGroup, topic: str, type_name: str, inbox: Inbox) -> Any:
    return sdk.ROS2Subscriber(topic, type_name, inbox, router_port=stack.port, node_name="test_listener")


def publisher(stack: ProcessGroup, topic: str, type_name: str) -> Any:
    return sdk.ROS2Publisher(topic, type_name, router_port=stack.port, node_name="test_robot")


def graph(client: Client) -> list[str]:
    """The rmw_zenoh graph's liveliness tokens on domain 0 (what ros2 node/topic list read)."""
    return [str(r.ok.key_expr) for r in client.session.liveliness().get("@ros2_lv/0/**", timeout=2) if r.ok]


def table_photo() -> np.ndarray:
    data = TABLE.read_bytes()
    return decode_image(data, "png", *png_size(data))


def send_camera(stack: ProcessGroup, stop: threading.Event) -> None:
    """A ROS camera driver: the photo as rgb8 Images with their CameraInfo, FPS times a second, stamped now."""
    photo = table_photo()
    height, width = photo.shape[:2]
    rgb = np.ascontiguousarray(photo[:, :, ::-1]).reshape(-1)
    images = publisher(stack, "/camera/color/image_raw", core.IMAGE)
    infos = publisher(stack, "/camera/color/camera_info", core.CAMERA_INFO)
    k = [600.0, 0.0, width / 2, 0.0, 600.0, height / 2, 0.0, 0.0, 1.0]
    calibration = core.CameraInfo(width=width, height=height, k=k, frame_id="camera_color_optical_frame")
    while not stop.is_set():
        now = time.time()
        info = core.camera_info_message(calibration, now)
        infos.publish(
            **{
                f: getattr(info, f)
                for f in (
                    "header",
                    "height",
                    "width",
                    "distortion_model",
                    "d",
                    "k",
                    "r",
                    "p",
                    "binning_x",
                    "binning_y",
                    "roi",
                )
            }
        )
        images.publish(
            header=core.header(now, "camera_color_optical_frame"),
            height=height,
            width=width,
            encoding="rgb8",
            is_bigendian=0,
            step=width * 3,
            data=rgb,
        )
        stop.wait(1.0 / FPS)
    images.close()
    infos.close()


def test_every_fixed_topic_is_on_the_ros_graph_with_its_type_before_anything_is_sent() -> None:
    """What `ros2 topic list/info` read (rmw_zenoh's liveliness tokens) shows the node's command, clarification,
    objects and tracked-people topics with their types as soon as it runs, before any command or sample."""
    group = ProcessGroup()
    client = None
    try:
        group.router()
        group.service("ros2")  # alone: no service to send it anything
        client = Client(group.endpoint)
        client.wait_alive("ros2", timeout=90)
        wanted = {
            (rmw.mangle(o.topic), dds_type_name(o.type), type_hash(o.type)) for o in core.node_topics(core.Ros2Config())
        }
        deadline = time.monotonic() + 30
        while True:
            tokens = [t.split("/") for t in graph(client)]
            published = {(t[9], t[10], t[11]) for t in tokens if len(t) > 11 and t[5] == "MP"}
            if wanted <= published or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        assert wanted <= published, f"not on the graph: {sorted(wanted - published)}"
        assert (
            "%hri_fusion%command",
            "hri_fusion_msgs::msg::dds_::FusedCommand_",
            type_hash(core.FUSED_COMMAND),
        ) in wanted
        assert client.stats("ros2")["other"].get("ros_published", 0) == 0  # nothing was sent
    finally:
        if client is not None:
            client.close()
        print(group.logs())
        group.close()


def test_a_ros_camera_and_text_drive_the_stack_and_ros_gets_objects_and_the_command(stack: ProcessGroup, ros: None):
    detections, commands = Inbox(), Inbox()
    subscriber(stack, "/hri_fusion/objects/detections_2d", core.DETECTIONS_2D, detections)
    subscriber(stack, "/hri_fusion/command", core.FUSED_COMMAND, commands)
    client = Client(stack.endpoint)
    frames = client.collect("hri/camera/ros0/frame")
    stack_commands = client.collect("hri/fusion/command")
    stop = threading.Event()
    camera = threading.Thread(target=send_camera, args=(stack, stop), daemon=True)
    try:
        camera.start()
        # the first Image may be handled before the first CameraInfo (two keys, no order between them): that frame
        # has no intrinsics, by design; the ones after it carry them
        _, frame = frames.wait(1, timeout=30, where=lambda k, f: f.camera_info is not None)[0]
        assert isinstance(frame, Frame) and frame.encoding == "bgr8" and frame.camera_info is not None
        assert np.array_equal(decode_image(frame.data, "bgr8", frame.width, frame.height), table_photo())
        assert frame.camera_info.frame_id == "camera_color_optical_frame"

        seen = detections.wait_for(lambda m: len(m.detections) >= 3, 60, "Detection2DArray with the candies")
        assert {d.results[0].hypothesis.class_id for d in seen.detections} == {"candy"}
        assert all(0 < d.bbox.center.position.x < frame.width for d in seen.detections)
        assert seen.header.frame_id == "ros0"

        text = publisher(stack, "/hri_fusion/text_command", core.STRING)
        client.wait_matched(["hri/speech/ros/transcript"])  # fusion listens
        text.publish(data="pick up the red candy")
        command = commands.wait_for(lambda m: m.intent == "pick_up", 60, "FusedCommand pick_up")
        assert command.has_target and command.target.label == "candy" and command.target.color == "red"
        assert command.target.cam == "ros0" and command.text == "pick up the red candy"
        _, on_stack = stack_commands.wait(1, timeout=10, where=lambda k, s: s.intent == "pick_up")[0]
        assert isinstance(on_stack, FusedCommand) and on_stack.id == command.id
        text.close()
    finally:
        stop.set()
        camera.join(5)
        client.close()


def test_people_reach_ros_as_rep155_and_a_late_joiner_gets_the_latched_ids(stack: ProcessGroup, ros: None):
    tracked = Inbox()
    subscriber(stack, "/humans/persons/tracked", core.IDS_LIST, tracked)
    client = Client(stack.endpoint)
    persons = next(e for e in examples() if type(e).__name__ == "Persons")
    person = persons.persons[0]
    try:
        client.wait_matched(["hri/gesture/cam0/persons"])
        deadline = time.monotonic() + 30
        while not tracked.items and time.monotonic() < deadline:  # until the ROS subscriber is matched too
            client.publish("hri/gesture/cam0/persons", persons)
            time.sleep(0.2)
        ids = tracked.wait_for(lambda m: len(m.ids) > 0, 10, "IdsList")
        assert list(ids.ids) == [core.ros_id(person.id)]

        # a late joiner, as rmw_zenoh's transient-local subscription: history from the publisher's cache
        key = rmw.topic_key(0, f"/humans/persons/{core.ros_id(person.id)}/face_id", core.STRING)
        late: list[str] = []
        got = threading.Event()

        def on_late(sample: zenoh.Sample) -> None:
            late.append(deserialize(sample.payload.to_bytes(), core.STRING).data)
            assert sample.attachment is not None
            rmw.parse_attachment(sample.attachment.to_bytes())  # rmw's layout
            got.set()

        history = ext.HistoryConfig(detect_late_publishers=True, max_samples=1)
        late_sub = ext.declare_advanced_subscriber(client.session, key, on_late, history=history)
        assert got.wait(15), "the latched face_id never reached the late joiner"
        assert late == [core.ros_id(person.face)]
        late_sub.undeclare()

        tokens = graph(client)
        assert any(t.endswith("/NN/%/%hri_fusion/hri_fusion") for t in tokens)  # ros2 node list
        assert any(
            "/MP/" in t and "/%hri_fusion%command/hri_fusion_msgs::msg::dds_::FusedCommand_/" in t for t in tokens
        )
        assert any("/MS/" in t and "/%camera%color%image_raw/sensor_msgs::msg::dds_::Image_/" in t for t in tokens)
        face_topic = f"/%humans%persons%{core.ros_id(person.id)}%face_id/"
        assert any(face_topic in t for t in tokens)

        # the person leaves: their per-id topics go from the graph (REP-155)
        client.publish("hri/gesture/cam0/persons", msgspec.structs.replace(persons, persons=[], stamp=time.time()))
        tracked.wait_for(lambda m: len(m.ids) == 0, 10, "an empty IdsList")
        deadline = time.monotonic() + 10
        while any(face_topic in t for t in graph(client)):
            assert time.monotonic() < deadline, "the face_id publisher of a person who left is still declared"
            time.sleep(0.1)
    finally:
        client.close()


def test_bridge_layout_speaks_raw_cdr_on_the_topic_name(stack: ProcessGroup):
    """--key-layout bridge: what zenoh-bridge-ros2dds carries between a DDS system and zenoh (the topic name as the
    key, raw CDR): a second ros2 instance in that layout, read and written here as the bridge would."""
    bridge = stack.service("ros2", "--key-layout", "bridge", "--instance", "bridge")
    client = Client(stack.endpoint)
    commands: list[Any] = []
    got = threading.Event()

    def on_command(sample: zenoh.Sample) -> None:
        assert sample.attachment is None  # the bridge layout has no rmw attachment
        commands.append(deserialize(sample.payload.to_bytes(), core.FUSED_COMMAND))
        got.set()

    sub = client.session.declare_subscriber("hri_fusion/command", on_command)
    transcripts = client.collect("hri/speech/ros/transcript")
    try:
        client.wait_alive("ros2", timeout=60)
        deadline = time.monotonic() + 60
        while not any(i == "bridge" for s, i in client.alive() if s == "ros2"):
            assert bridge.alive() and time.monotonic() < deadline, bridge.output()[-2000:]
            time.sleep(0.1)
        client.wait_matched(["hri_fusion/text_command"])
        text = core.msg(core.STRING, data="stop")
        client.session.put("hri_fusion/text_command", serialize(text, core.STRING))
        _, transcript = transcripts.wait(1, timeout=20)[0]
        assert transcript.text == "stop" and transcript.mic == "ros"
        assert got.wait(30), "no FusedCommand on the bridge key"
        assert any(c.intent == "stop" for c in commands)
        tokens = [str(r.ok.key_expr) for r in client.session.liveliness().get("@ros2_lv/**", timeout=2) if r.ok]
        nodes = [t for t in tokens if t.endswith("/NN/%/%hri_fusion/hri_fusion")]
        assert len(nodes) == 1  # the rmw_zenoh instance's; the bridge layout declares no graph tokens
    finally:
        sub.undeclare()
        client.close()
        bridge.terminate()


def test_bad_ros_messages_are_counted_and_dropped(stack: ProcessGroup):
    """Garbage on the camera and text keys, and an image over --max-pixels: counted, dropped, the service lives."""
    client = Client(stack.endpoint)
    try:
        image_key = rmw.topic_key(0, "/camera/color/image_raw", core.IMAGE)
        client.wait_matched([image_key])
        before = client.stats("ros2")["rejected"]
        client.put_raw(image_key, b"\x00\x01\x00\x00 not an image")
        client.put_raw(rmw.topic_key(0, "/hri_fusion/text_command", core.STRING), b"\xff")
        huge = core.msg(
            core.IMAGE,
            header=core.header(time.time()),
            height=5000,
            width=5000,
            encoding="mono8",
            is_bigendian=0,
            step=5000,
            data=np.zeros(16, np.uint8),  # the header alone is refused: nothing is allocated for it
        )
        client.put_raw(image_key, serialize(huge, core.IMAGE))
        deadline = time.monotonic() + 15
        while True:
            rejected = client.stats("ros2")["rejected"]
            if rejected.get("bad_cdr", 0) >= before.get("bad_cdr", 0) + 2 and rejected.get("oversized", 0) >= 1:
                break
            assert time.monotonic() < deadline, f"rejections not counted: {rejected}"
            time.sleep(0.2)
        assert any(s == "ros2" for s, _ in client.alive())
    finally:
        client.close()


def send_rgbd(stack: ProcessGroup, capture: dict[str, np.ndarray], stop: threading.Event) -> None:
    """A RealSense driver under ROS: colour, aligned depth (16UC1 mm) and CameraInfo, same stamps, 5 fps."""
    width, height = (int(v) for v in capture["image_size"])
    fx, fy, cx, cy = (float(v) for v in capture["intrinsics"])
    calibration = core.CameraInfo(width=width, height=height, k=[fx, 0, cx, 0, fy, cy, 0, 0, 1], frame_id="rs_optical")
    images = publisher(stack, "/camera/color/image_raw", core.IMAGE)
    depths = publisher(stack, "/camera/aligned_depth_to_color/image_raw", core.IMAGE)
    infos = publisher(stack, "/camera/color/camera_info", core.CAMERA_INFO)
    rgb = np.ascontiguousarray(capture["color"]).reshape(-1)
    depth = np.ascontiguousarray(capture["depth"].astype("<u2")).view(np.uint8)
    while not stop.is_set():
        now = time.time()
        info = core.camera_info_message(calibration, now)
        infos.publish(**{f: getattr(info, f) for f in info.__dataclass_fields__ if f != "__msgtype__"})
        stamp = core.header(now, "rs_optical")
        fields = dict(header=stamp, height=height, width=width, is_bigendian=0)
        depths.publish(**fields, encoding="16UC1", step=width * 2, data=depth)  # depth first, as a camera sends it
        images.publish(**fields, encoding="rgb8", step=width * 3, data=rgb)
        stop.wait(1.0 / FPS)
    for pub in (images, depths, infos):
        pub.close()


def test_a_ros_rgbd_camera_gives_ros_the_objects_in_metres(stack: ProcessGroup, ros: None):
    from testkit.shared import shared_path

    path = shared_path("data/rgbd/realsense_tabletop/realsense_frame.npz")  # skips, saying why, when absent
    with np.load(path) as npz:
        capture = {k: npz[k] for k in npz.files}
    in_3d = Inbox()
    subscriber(stack, "/hri_fusion/objects/detections_3d", core.DETECTIONS_3D, in_3d)
    stop = threading.Event()
    camera = threading.Thread(target=send_rgbd, args=(stack, capture, stop), daemon=True)
    try:
        camera.start()
        seen = in_3d.wait_for(lambda m: len(m.detections) > 0, 90, "Detection3DArray")
        assert seen.header.frame_id == "rs_optical"
        millimetres = capture["depth"][capture["depth"] > 0]
        nearest, farthest = np.percentile(millimetres, [1, 99]) / 1000.0
        for detection in seen.detections:
            z = detection.bbox.center.position.z
            assert nearest - 0.05 <= z <= farthest + 0.05, (detection.id, z)  # metres, within the scene's depth
            assert detection.bbox.size.x > 0 and detection.results[0].pose.pose.position.z == z
    finally:
        stop.set()
        camera.join(5)

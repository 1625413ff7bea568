"""Recordings the viewers decode (issue #36): every message of every channel decodes with `mcap` and the decoder
for its encoding; the Foxglove shapes say what the samples say; recordings made before still read and replay."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import cv2
import jsonschema  # type: ignore[import-untyped]
import msgspec
import numpy as np
import pytest
from mcap.reader import make_reader

from common.codec import decode, encode
from common.depth import depth_frame
from common.keys import Keys
from common.schema import (
    Bodies,
    Body,
    CameraInfo,
    DepthFrame,
    Frame,
    Person,
    Persons,
    Ray,
    Ray3D,
    Sample,
)
from hri.recording import SessionReader, SessionWriter, read_samples
from hri.viewers.foxglove_msgs import FoxgloveConverter, speaking_person
from testkit.examples import T, example_key, examples
from testkit.shared import shared_path

pytest.importorskip("foxglove", reason="foxglove-sdk (the foxglove extra) is not installed")
mcap_protobuf_decoder = pytest.importorskip("mcap_protobuf.decoder", reason="mcap-protobuf-support is not installed")

KEYS = Keys()
OLD_RECORDING = Path(__file__).parent / "data" / "recordings" / "before-viewers.mcap"
YCB_FX, YCB_FY, YCB_CX, YCB_CY = 1066.778, 1067.487, 312.9869, 241.3109  # shared/data/rgbd/README.md
YCB_DEPTH_SCALE = 0.0001  # 1 unit = 0.1 mm


def key_of(sample: Sample) -> str:
    """The key the stack publishes `sample` on."""
    return example_key(sample, KEYS)


def ycb_depth_units() -> np.ndarray:
    depth = cv2.imread(str(shared_path("data/rgbd/ycb_video/000002-depth.png")), cv2.IMREAD_UNCHANGED)
    assert depth is not None and depth.dtype == np.uint16
    return depth


def ycb_capture(cam: str = "cam0") -> tuple[Frame, DepthFrame]:
    """A real RGB-D capture (YCB-Video, 640x480): the colour PNG as sent, its 16-bit depth as a PNG DepthFrame."""
    folder = shared_path("data/rgbd/ycb_video")
    info = CameraInfo(
        width=640, height=480, k=[YCB_FX, 0, YCB_CX, 0, YCB_FY, YCB_CY, 0, 0, 1], frame_id=f"{cam}_optical"
    )
    colour = (folder / "000002-color.png").read_bytes()
    frame = Frame(
        stamp=T, source="camera/a", seq=7, cam=cam, width=640, height=480, encoding="png", data=colour,
        camera_info=info,
    )  # fmt: skip
    dframe = depth_frame(
        ycb_depth_units(), stamp=T, source="camera/a", seq=7, cam=cam, depth_scale=YCB_DEPTH_SCALE, camera_info=info,
        compression="png",
    )  # fmt: skip
    return frame, dframe


def session_samples() -> list[Sample]:
    """One of every contract type (testkit/examples.py) with a real RGB-D capture in place of the 2x2 images."""
    frame, depth = ycb_capture()
    kept = [s for s in examples() if not isinstance(s, (Frame, DepthFrame))]
    return [frame, depth] + kept


def write_session(path: Path, samples: list[Sample]) -> None:
    with open(path, "wb") as f:
        writer = SessionWriter(f, KEYS, metadata={"prefix": KEYS.prefix})
        for i, sample in enumerate(samples):
            writer.add(key_of(sample), encode(sample), int((T + 0.01 * i) * 1e9))
        writer.add("hri/custom/thing", b"\xc1 outside the contract", int((T + 1) * 1e9))
        writer.finish()


def decode_any(schema: Any, channel: Any, data: bytes, validators: dict[int, Any]) -> Any:
    """Decode one message with the decoder its channel's encoding calls for; raise if it does not decode."""
    if channel.message_encoding == "protobuf":
        decoder = mcap_protobuf_decoder.DecoderFactory().decoder_for("protobuf", schema)
        assert decoder is not None, f"no protobuf decoder for {schema.name}"
        if schema.name != "hri_fusion.RawSample":
            return decoder(data)
        data = decoder(data).data  # a raw channel: the payload as received, in a bytes field (issue #41)
    elif channel.message_encoding == "json":
        assert schema.encoding == "jsonschema"
        value = json.loads(data)
        validators.setdefault(schema.id, jsonschema.Draft202012Validator(json.loads(schema.data))).validate(value)
        return value
    else:
        assert channel.message_encoding == "msgpack"  # a raw channel recorded before issue #41
    kind = channel.metadata["schema"]
    if not kind:
        return data  # outside the contract: bytes as received
    return decode(data, getattr(__import__("common.schema", fromlist=[kind]), kind))


def decoded_channels(path: Path) -> dict[str, list[Any]]:
    out: dict[str, list[Any]] = {}
    validators: dict[int, Any] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            out.setdefault(channel.topic, []).append(decode_any(schema, channel, message.data, validators))
    return out


# ---------------------------------------------------------------------------
# The recording
# ---------------------------------------------------------------------------
def test_every_message_of_every_channel_decodes_with_its_encodings_decoder(tmp_path: Path) -> None:
    path = tmp_path / "session.mcap"
    samples = session_samples()
    write_session(path, samples)
    channels = decoded_channels(path)

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    encodings = {c.topic: c.message_encoding for c in summary.channels.values()}
    viewer = {t: e for t, e in encodings.items() if t.startswith("/")}
    # every contract key has a viewer channel of its own, in a shape Foxglove decodes
    for sample in samples:
        assert "/" + key_of(sample) in viewer, key_of(sample)
    assert set(viewer.values()) == {"protobuf", "json"}
    schemas = {summary.schemas[c.schema_id].name for c in summary.channels.values() if c.topic.startswith("/")}
    assert {
        "foxglove.CompressedImage", "foxglove.RawImage", "foxglove.RawAudio", "foxglove.ImageAnnotations",
        "foxglove.SceneUpdate", "foxglove.FrameTransform", "foxglove.Log", "Transcript", "FusedCommand",
        "Clarification", "Persons", "Faces",
    } <= schemas  # fmt: skip

    # the images are the camera's own bytes / the depth in its units
    frame, depth = samples[0], samples[1]
    assert isinstance(frame, Frame) and isinstance(depth, DepthFrame)
    (image,) = channels["/" + KEYS.frame("cam0")]
    assert image.format == "png" and image.data == frame.data and image.frame_id == "cam0_optical"
    (raw_depth,) = channels["/" + KEYS.depth("cam0")]
    units = np.frombuffer(raw_depth.data, np.uint16).reshape(480, 640)
    assert raw_depth.encoding == "16UC1" and raw_depth.step == 1280
    assert np.array_equal(units, ycb_depth_units())
    # the raw channels still hold the payloads exactly
    for sample in samples:
        assert channels[key_of(sample)] == [sample]
    assert channels["hri/custom/thing"] == [b"\xc1 outside the contract"]


def test_annotations_and_scene_say_what_the_samples_say(tmp_path: Path) -> None:
    path = tmp_path / "session.mcap"
    samples = session_samples()
    write_session(path, samples)
    channels = decoded_channels(path)
    detections = next(s for s in samples if type(s).__name__ == "Detections")

    (boxes,) = channels["/" + KEYS.objects("cam0") + "/annotations"]
    assert len(boxes.points) == len(detections.objects)  # type: ignore[attr-defined]
    for drawn, obj in zip(boxes.points, detections.objects):  # type: ignore[attr-defined]
        x, y, w, h = obj.bbox
        assert [(p.x, p.y) for p in drawn.points] == [(x, y), (x + w, y), (x + w, y + h), (x, y + h)]
    red = boxes.points[0].outline_color
    assert (red.r, red.g, red.b) == pytest.approx((0.9, 0.1, 0.1))  # the objects are red
    assert "candy" in boxes.texts[0].text and "0.90 m" in boxes.texts[1].text  # the placed cup says how far

    (scene,) = channels["/" + KEYS.objects("cam0") + "/scene"]
    (cube,) = [e for e in scene.entities if e.cubes]  # only the cup has a position
    assert cube.frame_id == "cam0_optical" and cube.id == "object/o2"
    p = cube.cubes[0].pose.position
    assert (p.x, p.y, p.z) == pytest.approx((0.1, -0.05, 0.9))
    assert (cube.cubes[0].size.x, cube.cubes[0].size.y, cube.cubes[0].size.z) == pytest.approx((0.08, 0.1, 0.06))

    (hand_scene,) = channels["/" + KEYS.hands("cam0") + "/scene"]
    (arrow,) = hand_scene.entities[0].arrows
    q = arrow.pose.orientation  # +x turned onto the ray's direction (0, 0.6, -0.8)
    turned = rotate([q.x, q.y, q.z, q.w], [1.0, 0.0, 0.0])
    assert turned == pytest.approx([0.0, 0.6, -0.8], abs=1e-6)

    (persons,) = channels["/" + KEYS.persons("cam0") + "/annotations"]
    assert persons.texts[0].text == "person-1 — speaking"  # speaking 0.7: the speaker is marked
    log = [m.message for m in channels["/hri/log"]]
    assert any('"pick up that cup"' in line for line in log)
    assert any(line.startswith("command ") for line in log) and any(line.startswith("question ") for line in log)
    (services,) = channels["/hri/services"]  # the service-state table: one row per service instance
    stats = next(s for s in samples if type(s).__name__ == "Stats")
    assert [(r["service"], r["instance"], r["received"]) for r in services["services"]] == [
        (stats.service, stats.instance, stats.received)  # type: ignore[attr-defined]
    ]
    (tf,) = {(m.parent_frame_id, m.child_frame_id) for m in channels["/hri/tf"]}
    assert tf == ("world", "cam0_optical")


def rotate(q: list[float], v: list[float]) -> list[float]:
    x, y, z, w = q
    m = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    return [float(c) for c in m @ np.asarray(v)]


def test_a_skeleton_is_lifted_into_metres_with_the_real_depth() -> None:
    frame, depth = ycb_capture()
    converter = FoxgloveConverter(KEYS)
    converter.convert(KEYS.depth("cam0"), depth)
    # a skeleton over the table: the depth under its points is the table's (about 0.8-1 m, README of the capture)
    body = Body(landmarks=[[200.0 + 7 * i, 150.0 + 6 * i] for i in range(33)], visibility=[0.9] * 33, person="p1")
    bodies = Bodies(stamp=T, source="gesture/a", seq=7, cam="cam0", width=640, height=480, bodies=[body])
    shown = {m.topic: m for m in converter.convert(KEYS.bodies("cam0"), bodies)}
    scene = mcap_protobuf_decoder.DecoderFactory().decoder_for("protobuf", schema_record("foxglove.SceneUpdate"))(
        shown["/" + KEYS.bodies("cam0") + "/scene"].data
    )
    (line,) = scene.entities[0].lines
    zs = [p.z for p in line.points]
    metres = ycb_depth_units() * YCB_DEPTH_SCALE
    # each end is the pixel's depth, back-projected with the intrinsics
    first = line.points[0]
    u, v = 200.0 + 7 * 11, 150.0 + 6 * 11  # BODY_CONNECTIONS starts with (11, 12)
    z = float(metres[int(round(v)), int(round(u))])
    assert first.z == pytest.approx(z) and first.x == pytest.approx((u - YCB_CX) * z / YCB_FX)
    assert 0.5 < min(zs) and max(zs) < 1.5


def schema_record(name: str) -> Any:
    from mcap.records import Schema

    from hri.viewers.foxglove_msgs import protobuf_schema

    s = protobuf_schema(name.removeprefix("foxglove."))
    return Schema(id=1, name=s.name, encoding=s.encoding, data=s.data)


def test_the_speaker_is_the_person_most_likely_speaking_if_likely_enough() -> None:
    def persons(*speaking: float | None) -> Persons:
        return Persons(
            stamp=T, source="gesture/a", seq=1, cam="cam0", width=640, height=480,
            persons=[Person(id=f"p{i}", bbox=[0, 0, 10, 10], score=0.9, speaking=s) for i, s in enumerate(speaking)],
        )  # fmt: skip

    assert speaking_person(persons(0.2, 0.8, None)) == "p1"
    assert speaking_person(persons(0.3, 0.4)) is None  # nobody likely speaking: nobody marked
    assert speaking_person(persons(None)) is None


def test_a_ray_without_depth_draws_no_scene_and_an_undecodable_depth_keeps_the_raw_sample(tmp_path: Path) -> None:
    converter = FoxgloveConverter(KEYS)
    flat = Ray(origin=[1.0, 2.0], direction=[1.0, 0.0])
    body = Body(landmarks=[[1.0, 1.0]] * 33, visibility=[0.9] * 33, left_ray=flat)
    bodies = Bodies(stamp=T, source="g/a", seq=1, cam="cam0", width=640, height=480, bodies=[body])
    topics = [m.topic for m in converter.convert(KEYS.bodies("cam0"), bodies)]
    assert topics == ["/" + KEYS.bodies("cam0"), "/" + KEYS.bodies("cam0") + "/annotations"]

    _, depth = ycb_capture()
    broken = msgspec.structs.replace(depth, data=depth.data[:100])  # a cut PNG: valid envelope, bad image
    path = tmp_path / "broken.mcap"
    with open(path, "wb") as f:
        writer = SessionWriter(f, KEYS)
        writer.add(KEYS.depth("cam0"), encode(broken), int(T * 1e9))
        writer.finish()
    assert writer.tally[KEYS.depth("cam0")].viewer_failed == 1
    assert [s for _, _, s in read_samples(path)] == [broken]


def test_with_a_3d_ray_the_hit_is_a_sphere_where_the_arrow_ends() -> None:
    converter = FoxgloveConverter(KEYS)
    r3 = Ray3D(
        origin=[0.0, 0.0, 1.0], direction=[0.0, 0.6, 0.8], method="forearm", frame_id="c_optical", hit=[0.0, 0.6, 1.8]
    )
    body = Body(
        landmarks=[[1.0, 1.0]] * 33, visibility=[0.9] * 33, right_ray=Ray(origin=[1, 2], direction=[0, 1], ray3d=r3)
    )
    bodies = Bodies(stamp=T, source="g/a", seq=1, cam="c", width=640, height=480, bodies=[body])
    shown = {m.topic: m for m in converter.convert(KEYS.bodies("c"), bodies)}
    scene = mcap_protobuf_decoder.DecoderFactory().decoder_for("protobuf", schema_record("foxglove.SceneUpdate"))(
        shown["/" + KEYS.bodies("c") + "/scene"].data
    )
    (entity,) = scene.entities
    arrow, sphere = entity.arrows[0], entity.spheres[0]
    assert arrow.shaft_length + arrow.head_length == pytest.approx(1.0)  # |hit - origin|
    assert (sphere.pose.position.y, sphere.pose.position.z) == pytest.approx((0.6, 1.8))


# ---------------------------------------------------------------------------
# Recordings made before the viewer channels
# ---------------------------------------------------------------------------
def bare_raw_messages(path: Path) -> list[tuple[str, bytes, int]]:
    """(topic, data, log time) of every message, read with the mcap library alone (not our reader)."""
    with open(path, "rb") as f:
        return [(ch.topic, m.data, m.log_time) for _, ch, m in make_reader(f).iter_messages(log_time_order=True)]


def test_a_recording_made_before_the_viewer_channels_still_reads_sample_for_sample() -> None:
    raw = bare_raw_messages(OLD_RECORDING)
    assert len(raw) == 14 and {"/" in t[:1] for t, _, _ in raw} == {False}  # 13 contract types + 1 outside
    reader = SessionReader(OLD_RECORDING)
    assert [(m.key, m.payload, m.log_ns) for m in reader.messages()] == raw  # byte for byte, in order
    reader.close()
    read = list(read_samples(OLD_RECORDING))
    contract = [(t, d) for t, d, _ in raw if t != "hri/custom/thing"]
    assert [k for k, _, _ in read] == [t for t, _ in contract]  # every contract sample still decodes...
    for (_, _, sample), (_, data) in zip(read, contract):  # ...as what its bytes say (today's contract)
        assert sample == decode(data, type(sample))
    assert [k for k, _, _ in read] == [key_of(s) for _, _, s in read]
    assert {t for _, t, _ in read} == {T}  # testkit/examples.py's stamp when the file was written
    assert len({type(s) for _, _, s in read}) == 13


def test_old_and_new_recordings_give_the_same_samples_and_payloads(tmp_path: Path) -> None:
    raw = bare_raw_messages(OLD_RECORDING)
    path = tmp_path / "new.mcap"
    with open(path, "wb") as f:  # the same bytes, as received by today's writer (viewer channels and all)
        writer = SessionWriter(f, KEYS)
        for topic, data, log_ns in raw:
            writer.add(topic, data, log_ns)
        writer.finish()
    assert any(t.startswith("/") for t, _, _ in bare_raw_messages(path))  # the viewer channels are there
    new, old = SessionReader(path), SessionReader(OLD_RECORDING)
    try:
        assert new.info.keys == old.info.keys
        assert not new.skipped_encodings  # the viewer channels are not "unreplayable channels"
        assert [(m.key, m.payload, m.log_ns, m.publish_ns) for m in new.messages()] == [
            (m.key, m.payload, m.log_ns, m.publish_ns) for m in old.messages()
        ]
    finally:
        new.close()
        old.close()


@pytest.mark.integration
def test_hri_replay_republishes_a_recording_made_before_the_viewer_channels_byte_for_byte(group: Any) -> None:
    from testkit.harness import Client

    reader = SessionReader(OLD_RECORDING)
    recorded = [(m.key, m.payload) for m in reader.messages()]
    reader.close()
    group.router()
    client = Client(group.endpoint)
    got: list[tuple[str, bytes]] = []
    try:
        sub = client.session.declare_subscriber("hri/**", lambda s: got.append((str(s.key_expr), s.payload.to_bytes())))
        res = group.hri("replay", str(OLD_RECORDING), "--speed", "0", timeout=60)
        assert res.returncode == 0, res.stderr
        deadline = time.monotonic() + 30
        while len(got) < len(recorded) and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)  # anything extra (a bug) has time to show up
        sub.undeclare()
        assert got == recorded  # every sample, in order, byte for byte
    finally:
        client.close()


def layout_topics(layout: dict[str, Any]) -> set[str]:
    panels = layout["configById"]
    image = panels["Image!hri-camera"]["imageMode"]
    return (
        {image["imageTopic"], *image["annotations"], *panels["3D!hri-scene"]["topics"]}
        | {panels["RosOut!hri-log"]["topicToRender"], panels["RawMessages!hri-command"]["topicPath"]}
        | {panels["Table!hri-services"]["topicPath"].split(".")[0]}
    )


def test_the_foxglove_layout_names_topics_a_recording_has(tmp_path: Path) -> None:
    path = tmp_path / "session.mcap"
    write_session(path, session_samples())
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    recorded = {c.topic for c in summary.channels.values()}
    layout = json.loads((Path(__file__).parents[1] / "docs" / "foxglove-layout.json").read_text())
    # the one exception: a gesture event's 3-D arrow exists only when the event's ray has depth (not in this set)
    assert layout_topics(layout) - recorded == {"/hri/gesture/cam0/event/scene"}


def test_a_viewer_behind_keeps_every_event_in_order_and_only_the_latest_of_each_stream() -> None:
    from hri.viewers.feed import MAX_BACKLOG, Inbox

    samples = {type(s).__name__: s for s in examples()}
    inbox = Inbox()
    frame, objects = samples["Frame"], samples["Detections"]
    outcomes = [
        inbox.put(("hri/camera/cam0/frame", frame, 1)),
        inbox.put(("hri/vision/cam0/objects", objects, 2)),
        inbox.put(("hri/speech/mic0/transcript", samples["Transcript"], 3)),
        inbox.put(("hri/camera/cam0/frame", frame, 4)),  # replaces the pending frame 1
        inbox.put(("hri/fusion/command", samples["FusedCommand"], 5)),
    ]
    assert outcomes == ["queued", "queued", "queued", "skipped", "queued"]
    inbox.close()
    order = []
    while (item := inbox.get()) is not None:
        order.append(item[2])
    assert order == [3, 5, 4, 2]  # the words and the command first, then the streams' latest, in their turn
    # a viewer slower than the stack: every stream is replaced between two gets; the busiest (the camera's frames,
    # replaced twice as often) is still served in its turn, not pushed back for ever (a Foxglove client got
    # annotations and no image for 90 s in a fresh-clone run of 29 Nov)
    busy, keys = Inbox(), ["hri/camera/cam0/frame", "hri/vision/cam0/objects", "hri/gesture/cam0/hands"]
    served: list[str] = []
    for n in range(30):
        for key in keys[::-1]:
            busy.put((key, objects, n))
        busy.put((keys[0], frame, n))
        item = busy.get()
        assert item is not None
        served.append(item[0])
    assert all(served.count(k) >= 9 for k in keys), {k: served.count(k) for k in keys}
    full = Inbox()
    for i in range(MAX_BACKLOG):
        full.put(("hri/speech/mic0/transcript", samples["Transcript"], i))
    assert full.put(("hri/fusion/command", samples["FusedCommand"], -1)) == "dropped"  # bounded, and says so

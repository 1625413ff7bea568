"""The ros2 service's pure core: the stack's samples <-> ROS 2 messages (no Zenoh here).

Outgoing, every stack sample becomes a list of `Outgoing` (a ROS topic, its type, the message, latched or not):
people as REP-155 / hri_msgs under /humans, objects as vision_msgs, the fused command and the clarification as
hri_fusion_msgs, the target as geometry_msgs/PoseStamped, the planner prompt as std_msgs/String. Incoming, a ROS
camera (Image or CompressedImage, CameraInfo, aligned depth) becomes Frame / DepthFrame, and a std_msgs/String
becomes a typed Transcript. docs/ros2.md has the topic table.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from common.image import DEFAULT_MAX_PIXELS
from common.schema import (
    Bodies,
    Body,
    CameraInfo,
    Clarification,
    DepthFrame,
    Detections,
    Faces,
    Frame,
    FusedCommand,
    ImageEncoding,
    InvalidSample,
    Persons,
    RobotProfile,
    RobotState,
    Speaker,
    Target,
    Transcript,
    make_transcript,
)
from services.ros2.config import Ros2Config
from services.ros2.types import message_class

STRING = "std_msgs/msg/String"
BOOL = "std_msgs/msg/Bool"
IDS_LIST = "hri_msgs/msg/IdsList"
SKELETON = "hri_msgs/msg/Skeleton2D"
ROI = "hri_msgs/msg/NormalizedRegionOfInterest2D"
LIVE_SPEECH = "hri_msgs/msg/LiveSpeech"
ENGAGEMENT = "hri_msgs/msg/EngagementLevel"
DETECTIONS_2D = "vision_msgs/msg/Detection2DArray"
DETECTIONS_3D = "vision_msgs/msg/Detection3DArray"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
FUSED_COMMAND = "hri_fusion_msgs/msg/FusedCommand"
CLARIFICATION = "hri_fusion_msgs/msg/Clarification"

# hri_msgs/Skeleton2D's 18 OpenPose-COCO points from MediaPipe Pose's 33 (the person's own left and right in
# both); NECK has no MediaPipe point: the middle of the shoulders.
NECK = -1
SKELETON_FROM_MEDIAPIPE = (0, NECK, 12, 14, 16, 11, 13, 15, 24, 26, 28, 23, 25, 27, 2, 5, 7, 8)
SHOULDERS = (11, 12)
TEXT_MIC = "ros"  # the mic id of typed commands from ROS: common/stack.py's ros2 node may publish them
SPEAKING_AT = 0.5  # Person.speaking at or above it: is_speaking true


@dataclass(frozen=True)
class Outgoing:
    topic: str  # the ROS topic, absolute
    type: str  # pkg/msg/Name
    message: Any
    latched: bool = False  # transient local: late joiners get the last one (REP-155 ids)


def msg(name: str, **fields: Any) -> Any:
    return message_class(name)(**fields)


def ros_time(stamp: float) -> Any:
    sec = math.floor(stamp)
    return msg("builtin_interfaces/msg/Time", sec=sec, nanosec=min(int(round((stamp - sec) * 1e9)), 999_999_999))


def unix_time(time: Any) -> float:
    return float(time.sec) + float(time.nanosec) * 1e-9


def header(stamp: float, frame_id: str = "") -> Any:
    return msg("std_msgs/msg/Header", stamp=ros_time(stamp), frame_id=frame_id)


def ids_list(stamp: float, ids: list[str]) -> Any:
    return msg(IDS_LIST, header=header(stamp), ids=ids)


def string(text: str) -> Any:
    return msg(STRING, data=text)


def point(xyz: list[float] | None) -> Any:
    x, y, z = xyz if xyz is not None else (0.0, 0.0, 0.0)
    return msg("geometry_msgs/msg/Point", x=x, y=y, z=z)


def vector3(xyz: list[float] | None) -> Any:
    x, y, z = xyz if xyz is not None else (0.0, 0.0, 0.0)
    return msg("geometry_msgs/msg/Vector3", x=x, y=y, z=z)


def pose(xyz: list[float] | None) -> Any:
    return msg(
        "geometry_msgs/msg/Pose",
        position=point(xyz),
        orientation=msg("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.0, w=1.0),
    )


def bbox_2d(box: list[float]) -> Any:
    x, y, w, h = box
    centre = msg("vision_msgs/msg/Pose2D", position=msg("vision_msgs/msg/Point2D", x=x + w / 2, y=y + h / 2), theta=0.0)
    return msg("vision_msgs/msg/BoundingBox2D", center=centre, size_x=w, size_y=h)


def ros_id(stack_id: str) -> str:
    """A stack id as a REP-155 id, usable as a ROS name token (letters, digits, '_', not starting with a digit):
    'person-1' -> 'person_1'. The tracked lists carry these, so a reader builds the per-id topics from them."""
    token = re.sub(r"[^A-Za-z0-9_]", "_", stack_id)
    return token if token[:1].isalpha() else f"id_{token}"


class Latch:
    """The last value sent on each latched topic: a latched topic is sent again only when its value changes."""

    def __init__(self) -> None:
        self._last: dict[str, str] = {}

    def changed(self, topic: str, value: str) -> bool:
        if self._last.get(topic) == value:
            return False
        self._last[topic] = value
        return True

    def forget(self, prefix: str) -> None:
        for topic in [t for t in self._last if t.startswith(prefix)]:
            del self._last[topic]


# -- people (REP-155) ------------------------------------------------------------------------------------------
class Tracked:
    """Who each camera tracks now, per kind (persons, bodies, faces, voices), as ROS ids: the per-id topics of an
    id no camera tracks any more are retired (REP-155: they vanish with the id)."""

    def __init__(self) -> None:
        self._ids: dict[tuple[str, str], set[str]] = {}

    def update(self, kind: str, cam: str, ids: list[str]) -> None:
        self._ids[(kind, cam)] = set(ids)

    def gone(self, kind: str, topics: list[str], config: Ros2Config) -> list[str]:
        """The per-id topics of `kind` among `topics` whose id no camera tracks."""
        here = set().union(*(ids for (k, _), ids in self._ids.items() if k == kind))
        root = config.human(kind) + "/"
        return [
            t
            for t in topics
            if t.startswith(root) and t.count("/", len(root)) >= 1 and t[len(root) :].split("/")[0] not in here
        ]


def tracked_ids(outs: list[Outgoing], config: Ros2Config) -> dict[str, list[str]]:
    """kind -> ids of the `tracked` lists among `outs` (what a persons/bodies/faces sample says is here)."""
    found = {}
    for out in outs:
        for kind in ("persons", "bodies", "faces", "voices"):
            if out.topic == config.human(kind, "tracked"):
                found[kind] = list(out.message.ids)
    return found


REP155_LEVELS = {"unknown": 0, "disengaged": 1, "engaging": 2, "engaged": 3, "disengaging": 4}  # EngagementLevel


def engagement_level(engaged: bool | None, level: str | None = None) -> int:
    """hri_msgs/EngagementLevel's number: the person's REP-155 level when the sender gives it (`Person.engagement`),
    else from `engaged` alone."""
    if level is not None:
        return REP155_LEVELS[level]
    if engaged is None:
        return 0  # UNKNOWN
    return 3 if engaged else 1  # ENGAGED, DISENGAGED


def persons_messages(sample: Persons, config: Ros2Config, latch: Latch) -> list[Outgoing]:
    """The tracked persons, their body/face/voice ids (latched, sent on change) and engagement; voices are the
    persons whose speaking is measured (a voice id is its person's id), bodies are persons with a skeleton (a body
    id is its person's id)."""
    out = [
        Outgoing(
            config.human("persons", "tracked"), IDS_LIST, ids_list(sample.stamp, [ros_id(p.id) for p in sample.persons])
        )
    ]
    voices = [p for p in sample.persons if p.speaking is not None]
    out.append(
        Outgoing(config.human("voices", "tracked"), IDS_LIST, ids_list(sample.stamp, [ros_id(p.id) for p in voices]))
    )
    for person in sample.persons:
        pid = ros_id(person.id)
        links = {"body_id": pid if person.has_body else "", "face_id": ros_id(person.face) if person.face else ""}
        links["voice_id"] = pid if person.speaking is not None else ""
        for link, value in links.items():
            topic = config.human("persons", pid, link)
            if latch.changed(topic, value):
                out.append(Outgoing(topic, STRING, string(value), latched=True))
        level = msg(ENGAGEMENT, header=header(sample.stamp), level=engagement_level(person.engaged, person.engagement))
        out.append(Outgoing(config.human("persons", pid, "engagement_status"), ENGAGEMENT, level))
    for person in voices:
        speaking = msg(BOOL, data=bool(person.speaking is not None and person.speaking >= SPEAKING_AT))
        out.append(Outgoing(config.human("voices", ros_id(person.id), "is_speaking"), BOOL, speaking))
    return out


def skeleton_points(body: Body, width: int, height: int) -> list[Any]:
    """The 18 normalised OpenPose-COCO points of a MediaPipe skeleton, visibility as confidence."""
    points = []
    for index in SKELETON_FROM_MEDIAPIPE:
        if index == NECK:
            (x, y), c = (
                np.mean([body.landmarks[i] for i in SHOULDERS], axis=0),
                min(body.visibility[i] for i in SHOULDERS),
            )
        else:
            (x, y), c = body.landmarks[index], body.visibility[index]
        points.append(
            msg(
                "hri_msgs/msg/NormalizedPointOfInterest2D",
                x=float(np.clip(x / width, 0.0, 1.0)),
                y=float(np.clip(y / height, 0.0, 1.0)),
                c=float(c),
            )
        )
    return points


def bodies_messages(sample: Bodies, config: Ros2Config) -> list[Outgoing]:
    """The tracked bodies (a skeleton of a known person; its body id is the person's id) and their skeletons."""
    known = [b for b in sample.bodies if b.person is not None]
    ids = [ros_id(b.person) for b in known if b.person is not None]
    out = [Outgoing(config.human("bodies", "tracked"), IDS_LIST, ids_list(sample.stamp, ids))]
    for body, body_id in zip(known, ids):
        skeleton = msg(
            SKELETON,
            header=header(sample.stamp),
            skeleton=skeleton_points(body, sample.width, sample.height),
        )
        out.append(Outgoing(config.human("bodies", body_id, "skeleton2d"), SKELETON, skeleton))
    return out


def faces_messages(sample: Faces, config: Ros2Config) -> list[Outgoing]:
    """The tracked faces and each one's region of interest, normalised to the image."""
    out = [
        Outgoing(
            config.human("faces", "tracked"), IDS_LIST, ids_list(sample.stamp, [ros_id(f.id) for f in sample.faces])
        )
    ]
    for face in sample.faces:
        x, y, w, h = face.bbox
        roi = msg(
            ROI,
            header=header(sample.stamp),
            xmin=float(np.clip(x / sample.width, 0, 1)),
            ymin=float(np.clip(y / sample.height, 0, 1)),
            xmax=float(np.clip((x + w) / sample.width, 0, 1)),
            ymax=float(np.clip((y + h) / sample.height, 0, 1)),
            c=face.score,
        )
        out.append(Outgoing(config.human("faces", ros_id(face.id), "roi"), ROI, roi))
    return out


# -- objects -----------------------------------------------------------------------------------------------------
def hypothesis(label: str, score: float, xyz: list[float] | None) -> Any:
    return msg(
        "vision_msgs/msg/ObjectHypothesisWithPose",
        hypothesis=msg("vision_msgs/msg/ObjectHypothesis", class_id=label, score=score),
        pose=msg("geometry_msgs/msg/PoseWithCovariance", pose=pose(xyz), covariance=np.zeros(36)),
    )


def detections_messages(sample: Detections, config: Ros2Config) -> list[Outgoing]:
    """Every object as a vision_msgs Detection2D (pixels; one hypothesis: the label as class_id, the detection
    score); those with a position (depth) also as a Detection3D in metres in the camera's optical frame."""
    frame_id = sample.frame_id or sample.cam
    stamp = header(sample.stamp, sample.cam)
    in_2d = [
        msg(
            "vision_msgs/msg/Detection2D",
            header=stamp,
            results=[hypothesis(o.label, o.score, None)],
            bbox=bbox_2d(o.bbox),
            id=o.id,
        )
        for o in sample.objects
    ]
    out = [
        Outgoing(config.own("objects/detections_2d"), DETECTIONS_2D, msg(DETECTIONS_2D, header=stamp, detections=in_2d))
    ]
    placed = [o for o in sample.objects if o.position is not None]
    if placed:
        stamp_3d = header(sample.stamp, frame_id)
        in_3d = [
            msg(
                "vision_msgs/msg/Detection3D",
                header=stamp_3d,
                results=[hypothesis(o.label, o.score, o.position)],
                bbox=msg("vision_msgs/msg/BoundingBox3D", center=pose(o.position), size=vector3(o.extent)),
                id=o.id,
            )
            for o in placed
        ]
        detections_3d = msg(DETECTIONS_3D, header=stamp_3d, detections=in_3d)
        out.append(Outgoing(config.own("objects/detections_3d"), DETECTIONS_3D, detections_3d))
    return out


def camera_info_message(info: CameraInfo, stamp: float) -> Any:
    fx, cx, fy, cy = info.fx, info.cx, info.fy, info.cy
    return msg(
        CAMERA_INFO,
        header=header(stamp, info.frame_id),
        height=info.height,
        width=info.width,
        distortion_model="plumb_bob" if info.distortion_model == "none" else info.distortion_model,
        d=np.array(info.distortion if info.distortion_model != "none" else [0.0] * 5, dtype=np.float64),
        k=np.array(info.k, dtype=np.float64),
        r=np.array([1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]),
        p=np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1.0, 0]),
        binning_x=0,
        binning_y=0,
        roi=msg("sensor_msgs/msg/RegionOfInterest", x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )


def camera_info_messages(sample: Frame, config: Ros2Config, latch: Latch) -> list[Outgoing]:
    """The stack camera's intrinsics, latched, sent when they change (a frame carries them every time)."""
    info = sample.camera_info
    if info is None or not latch.changed(f"camera_info/{sample.cam}", repr(info)):
        return []
    return [
        Outgoing(config.own(f"{sample.cam}/camera_info"), CAMERA_INFO, camera_info_message(info, sample.stamp), True)
    ]


# -- commands ----------------------------------------------------------------------------------------------------
def target_message(target: Target) -> Any:
    return msg(
        "hri_fusion_msgs/msg/Target",
        id=target.id,
        label=target.label,
        color=target.color or "",
        score=target.score,
        cam=target.cam,
        bbox=bbox_2d(target.bbox),
        has_position=target.position is not None,
        position=point(target.position),
        extent=vector3(target.extent),
        frame_id=target.frame_id or "",
    )


EMPTY_TARGET = Target(id="-", label="-", bbox=[0, 0, 0, 0], center=[0, 0], score=0.0, cam="-")


def speaker_message(speaker: Speaker | None) -> Any:
    if speaker is None:
        return msg(
            "hri_fusion_msgs/msg/Speaker", person_id="", confidence=0.0, method="unknown", addressed=0, reason=""
        )
    addressed = 0 if speaker.addressed is None else (1 if speaker.addressed else 2)
    return msg(
        "hri_fusion_msgs/msg/Speaker",
        person_id=ros_id(speaker.person) if speaker.person else "",
        confidence=speaker.confidence,
        method=speaker.method,
        addressed=addressed,
        reason=speaker.reason,
    )


def command_message(cmd: FusedCommand) -> Any:
    target, location, motion = cmd.target, cmd.location, cmd.motion
    return msg(
        FUSED_COMMAND,
        header=header(cmd.stamp, (target.frame_id or "") if target is not None else ""),
        id=cmd.id,
        intent=cmd.intent,
        text=cmd.text or "",
        has_target=target is not None,
        target=target_message(target if target is not None else EMPTY_TARGET),
        has_location=location is not None,
        location_cam=location.cam if location is not None else "",
        location_px=point([location.x, location.y, 0.0] if location is not None else None),
        location_has_position=location is not None and location.position is not None,
        location_position=point(location.position if location is not None else None),
        location_frame_id=(location.frame_id or "") if location is not None else "",
        place=cmd.place or "",
        gesture=cmd.gesture or "",
        motion_direction=(motion.direction or "") if motion is not None else "",
        motion_distance=_or_nan(motion.distance if motion is not None else None),
        motion_angle=_or_nan(motion.angle if motion is not None else None),
        confidence=cmd.confidence,
        weight_speech=cmd.weights.speech,
        weight_vision=cmd.weights.vision,
        weight_gesture=cmd.weights.gesture,
        explanation=cmd.explanation,
        prompt=cmd.prompt,
        speaker=speaker_message(cmd.speaker),
    )


def _or_nan(value: float | None) -> float:
    return math.nan if value is None else float(value)


def live_speech(stamp: float, text: str, confidence: float) -> Any:
    return msg(LIVE_SPEECH, header=header(stamp), incremental="", final=text, confidence=confidence, locale="")


def voice_speech(stamp: float, text: str | None, speaker: Speaker | None, config: Ros2Config) -> list[Outgoing]:
    """What a known speaker said, on their voice's speech topic (REP-155: /humans/voices/<id>/speech)."""
    if not text or speaker is None or speaker.person is None:
        return []
    topic = config.human("voices", ros_id(speaker.person), "speech")
    return [Outgoing(topic, LIVE_SPEECH, live_speech(stamp, text, speaker.confidence))]


def fused_command_messages(cmd: FusedCommand, config: Ros2Config) -> list[Outgoing]:
    """The command, the target's pose (with depth) in the camera's optical frame, the planner prompt, and the
    speaker's words on their voice."""
    out = [Outgoing(config.own("command"), FUSED_COMMAND, command_message(cmd))]
    target = cmd.target
    if target is not None and target.position is not None:
        stamped = msg(POSE_STAMPED, header=header(cmd.stamp, target.frame_id or target.cam), pose=pose(target.position))
        out.append(Outgoing(config.own("target_pose"), POSE_STAMPED, stamped))
    out.append(Outgoing(config.own("planner_prompt"), STRING, string(cmd.prompt)))
    return out + voice_speech(cmd.stamp, cmd.text, cmd.speaker, config)


def clarification_messages(question: Clarification, config: Ros2Config) -> list[Outgoing]:
    message = msg(
        CLARIFICATION,
        header=header(question.stamp),
        id=question.id,
        text=question.text or "",
        reason=question.reason,
        question=question.question,
        candidates=[target_message(t) for t in question.candidates],
        speaker=speaker_message(question.speaker),
    )
    out = [Outgoing(config.own("clarification"), CLARIFICATION, message)]
    return out + voice_speech(question.stamp, question.text, question.speaker, config)


# -- incoming: a ROS camera and text ----------------------------------------------------------------------------
def stack_camera_info(info: Any, cam: str) -> CameraInfo | None:
    """The stack's CameraInfo from a sensor_msgs/CameraInfo; None when it carries no calibration (K all 0)."""
    k = [float(v) for v in info.k]
    if k[0] <= 0.0 or k[4] <= 0.0:
        return None
    d = [float(v) for v in info.d]
    model = info.distortion_model if any(d) else "none"
    return CameraInfo(
        width=int(info.width),
        height=int(info.height),
        k=k,
        distortion_model=model or "none",
        distortion=d if model != "none" else [],
        frame_id=info.header.frame_id or f"{cam}_optical",
    )


# sensor_msgs/Image encodings the stack's Frame takes, and how to make bgr8 rows of them
COLOUR_CHANNELS = {"bgr8": 3, "rgb8": 3, "bgra8": 4, "rgba8": 4, "mono8": 1}


def bgr8_rows(image: Any) -> bytes:
    """A sensor_msgs/Image of a COLOUR_CHANNELS encoding as tightly packed bgr8 rows."""
    channels = COLOUR_CHANNELS.get(image.encoding)
    if channels is None:
        raise InvalidSample("bad_value", f"encoding {image.encoding!r}: not one of {', '.join(COLOUR_CHANNELS)}")
    width, height, step = int(image.width), int(image.height), int(image.step)
    if step < width * channels or len(image.data) < step * height:
        raise InvalidSample("bad_value", f"{width}x{height} {image.encoding}: step {step}, {len(image.data)} bytes")
    rows = np.asarray(image.data, dtype=np.uint8)[: step * height].reshape(height, step)
    pixels = rows[:, : width * channels].reshape(height, width, channels)
    if image.encoding == "mono8":
        pixels = np.repeat(pixels, 3, axis=2)
    elif image.encoding.startswith("rgb"):
        pixels = pixels[:, :, 2::-1]
    else:
        pixels = pixels[:, :, :3]
    return np.ascontiguousarray(pixels).tobytes()


@dataclass
class CameraBridge:
    """A ROS camera as the stack's camera: seq numbers per capture (colour and depth of one stamp share one), the
    latest calibration, and the stamp of each message (header stamp; 0 means "now")."""

    config: Ros2Config
    source: str
    max_pixels: int = DEFAULT_MAX_PIXELS  # --max-pixels: a larger image is refused before it is converted
    info: CameraInfo | None = None
    next_seq: int = 0
    seq_by_stamp: dict[float, int] = field(default_factory=dict)

    def seq_of(self, stamp: float) -> int:
        seq = self.seq_by_stamp.get(stamp)
        if seq is None:
            seq = self.seq_by_stamp[stamp] = self.next_seq
            self.next_seq += 1
            for old in sorted(self.seq_by_stamp)[:-16]:  # colour and depth of one capture come close together
                del self.seq_by_stamp[old]
        return seq

    def set_info(self, info: Any) -> None:
        self.info = stack_camera_info(info, self.config.cam)

    def info_for(self, width: int, height: int) -> CameraInfo | None:
        info = self.info
        return info if info is not None and (info.width, info.height) == (width, height) else None

    def check_pixels(self, width: int, height: int) -> None:
        if width * height > self.max_pixels:
            raise InvalidSample("oversized", f"image of {width}x{height} is over the cap of {self.max_pixels} pixels")

    def frame(self, image: Any, now: float) -> Frame:
        width, height = int(image.width), int(image.height)
        self.check_pixels(width, height)
        return self.stack_frame(image, now, (width, height), "bgr8", bgr8_rows(image))

    def stack_frame(self, image: Any, now: float, size: tuple[int, int], encoding: ImageEncoding, data: bytes) -> Frame:
        """The stack's Frame of a ROS image (raw or compressed), stamped with its header's time (else `now`)."""
        stamp = unix_time(image.header.stamp) or now
        return Frame(
            stamp=stamp,
            source=self.source,
            seq=self.seq_of(stamp),
            cam=self.config.cam,
            width=size[0],
            height=size[1],
            encoding=encoding,
            data=data,
            camera_info=self.info_for(*size),
        )

    def compressed_frame(self, image: Any, now: float, size: tuple[int, int]) -> Frame:
        """`size`: (width, height) read from the compressed header by the shell (common/image.py)."""
        fmt = image.format.lower()
        encoding: ImageEncoding
        if "png" in fmt:
            encoding = "png"
        elif "jpeg" in fmt or "jpg" in fmt:
            encoding = "jpeg"
        else:
            raise InvalidSample("bad_value", f"format {image.format!r}: jpeg or png only")
        self.check_pixels(*size)
        return self.stack_frame(image, now, size, encoding, bytes(image.data))

    def depth(self, image: Any, now: float) -> DepthFrame:
        """Aligned depth: 16UC1 in millimetres (REP-118) or 32FC1 in metres; needs the camera's calibration."""
        width, height = int(image.width), int(image.height)
        self.check_pixels(width, height)
        info = self.info_for(width, height)
        if info is None:
            raise InvalidSample("bad_value", f"depth {width}x{height} without a CameraInfo of that size")
        if image.encoding not in ("16UC1", "32FC1", "mono16"):
            raise InvalidSample("bad_value", f"depth encoding {image.encoding!r}: 16UC1 or 32FC1 only")
        float_depth = image.encoding == "32FC1"
        unit = np.dtype(np.float32 if float_depth else np.uint16).newbyteorder(">" if image.is_bigendian else "<")
        item = unit.itemsize
        if int(image.step) < width * item or len(image.data) < int(image.step) * height:
            raise InvalidSample("bad_value", f"depth {width}x{height}: step {image.step}, {len(image.data)} bytes")
        rows = np.asarray(image.data, dtype=np.uint8)[: int(image.step) * height].reshape(height, int(image.step))
        values = rows[:, : width * item].copy().view(unit).reshape(height, width)
        stamp = unix_time(image.header.stamp) or now
        return DepthFrame(
            stamp=stamp,
            source=self.source,
            seq=self.seq_of(stamp),
            cam=self.config.cam,
            width=width,
            height=height,
            encoding="32FC1" if float_depth else "16UC1",
            depth_scale=1.0 if float_depth else 0.001,
            camera_info=info,
            data=values.astype(unit.newbyteorder("<")).tobytes(),
        )


def text_transcript(text: str, now: float, source: str) -> Transcript | None:
    """A typed command from the ROS side, as `hri say` makes it; None for blank text."""
    if not text.strip():
        return None
    return make_transcript(text.strip(), mic=TEXT_MIC, end=now, confidence=1.0, source=source)


def robot_state(text: str, now: float, source: str) -> RobotState:
    """The robot's state from the JSON of a std_msgs/String (docs/robot.md): `status` (idle, busy, done, failed),
    optional `command`, `intent`, `holding` ({label, id, color}), `reason`, and `stamp` (seconds; absent: now)."""
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise InvalidSample("bad_value", f"robot state is not JSON: {exc}") from None
    if not isinstance(data, dict):
        raise InvalidSample("not_a_map", f"robot state: expected a JSON object, got {type(data).__name__}")
    return RobotState.from_dict({"stamp": now, **data, "source": source, "v": 1})


def quaternion(rpy: list[float]) -> Any:
    """Roll, pitch, yaw (radians, fixed axes x, y, z: REP-103) as a geometry_msgs/Quaternion."""
    (cr, sr), (cp, sp), (cy, sy) = ((math.cos(a / 2), math.sin(a / 2)) for a in rpy)
    return msg(
        "geometry_msgs/msg/Quaternion",
        x=sr * cp * cy - cr * sp * sy,
        y=cr * sp * cy + sr * cp * sy,
        z=cr * cp * sy - sr * sp * cy,
        w=cr * cp * cy + sr * sp * sy,
    )


def camera_mount_message(sample: RobotProfile) -> Any:
    """The profile's camera mount as tf2 transforms (one: the camera's optical frame in its parent)."""
    mount = sample.camera
    if mount is None:
        return msg(TF_MESSAGE, transforms=[])
    transform = msg("geometry_msgs/msg/Transform", translation=vector3(mount.xyz), rotation=quaternion(mount.rpy))
    stamped = msg(
        "geometry_msgs/msg/TransformStamped",
        header=header(sample.stamp, mount.parent),
        child_frame_id=mount.frame_id,
        transform=transform,
    )
    return msg(TF_MESSAGE, transforms=[stamped])


def profile_messages(sample: RobotProfile, config: Ros2Config, latch: Latch) -> list[Outgoing]:
    """The robot's profile as JSON on a latched std_msgs/String, and where its camera sits on the static transform
    tree (/tf_static, latched, as a static_transform_publisher would); sent when the profile changes."""
    text = json.dumps({k: v for k, v in sample.to_dict().items() if k not in ("v", "stamp")}, sort_keys=True)
    if not latch.changed("robot_profile", text):
        return []
    out = [Outgoing(config.own("robot_profile"), STRING, string(text), latched=True)]
    if sample.camera is not None:
        out.append(Outgoing("/tf_static", TF_MESSAGE, camera_mount_message(sample), latched=True))
    return out


def passes_while_busy(cmd: FusedCommand, busy: bool) -> bool:
    """While the robot says it is busy, only `stop` reaches it (a new task would be ignored or interrupt)."""
    return not busy or cmd.intent == "stop"


# -- the stack's own images and speech, for a rosbag2 export ------------------------------------------------------
def image_messages(sample: Frame, config: Ros2Config) -> list[Outgoing]:
    """A colour frame as sensor_msgs/Image (bgr8) or CompressedImage (jpeg/png), in the camera's optical frame."""
    frame_id = sample.camera_info.frame_id if sample.camera_info is not None else sample.cam
    stamp = header(sample.stamp, frame_id)
    if sample.encoding == "bgr8":
        image = msg(
            IMAGE,
            header=stamp,
            height=sample.height,
            width=sample.width,
            encoding="bgr8",
            is_bigendian=0,
            step=sample.width * 3,
            data=np.frombuffer(sample.data, np.uint8),
        )
        return [Outgoing(config.own(f"{sample.cam}/image_raw"), IMAGE, image)]
    compressed = msg(COMPRESSED_IMAGE, header=stamp, format=sample.encoding, data=np.frombuffer(sample.data, np.uint8))
    return [Outgoing(config.own(f"{sample.cam}/image_raw/compressed"), COMPRESSED_IMAGE, compressed)]


def depth_messages(sample: DepthFrame, values: np.ndarray, config: Ros2Config) -> list[Outgoing]:
    """Aligned depth as sensor_msgs/Image: 16UC1 in millimetres when the scale allows it exactly, else 32FC1
    metres (REP-118). `values`: the decoded depth image in the sample's units."""
    metres = values.astype(np.float64) * sample.depth_scale
    if sample.encoding == "16UC1" and sample.depth_scale == 0.001:
        encoding, data, step = "16UC1", values.astype("<u2"), sample.width * 2
    else:
        encoding, data, step = "32FC1", metres.astype("<f4"), sample.width * 4
    image = msg(
        IMAGE,
        header=header(sample.stamp, sample.camera_info.frame_id),
        height=sample.height,
        width=sample.width,
        encoding=encoding,
        is_bigendian=0,
        step=step,
        data=np.frombuffer(data.tobytes(), np.uint8),
    )
    return [Outgoing(config.own(f"{sample.cam}/depth/image_raw"), IMAGE, image)]


def transcript_messages(sample: Transcript, config: Ros2Config) -> list[Outgoing]:
    """What a microphone heard (speaker unknown until fusion attributes it) as hri_msgs/LiveSpeech."""
    speech = msg(
        LIVE_SPEECH,
        header=header(sample.stamp, sample.mic),
        incremental="" if sample.final else sample.text,
        final=sample.text if sample.final else "",
        confidence=sample.confidence,
        locale="",
    )
    return [Outgoing(config.own(f"speech/{ros_id(sample.mic)}"), LIVE_SPEECH, speech)]

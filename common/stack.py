"""The stack, declared once: every topic of the wire and every node that reads or publishes it.

A *topic* is a key pattern under the prefix with the one schema published there. A *node* is a process of the
stack (`python -m services.<name>`): the topics it reads, each with its queue policy, and the topics it
publishes. A *client* is something outside the stack that publishes or reads (a remote microphone, `hri say`,
`hri replay`, a planner). Derived from this file, never written again: the key table (common/keys.py), the
access-control roles (common/security.py), the services `hri up`, the demo and docker-compose.yml start, the
subscriptions each service makes (`Service.subscribe_input`), the modalities fusion waits for.

Adding a node: one `Node(...)` entry in NODES and one package `services/<name>/` whose `main` builds its
`Service` from `node("<name>")`.

Contract layer: the schema and the standard library only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from common.schema import (
    AudioChunk,
    Bodies,
    Clarification,
    DepthFrame,
    Detections,
    Faces,
    Frame,
    FusedCommand,
    GestureEvent,
    Hands,
    Persons,
    RobotProfile,
    RobotState,
    Sample,
    SpeechDecoding,
    Spoken,
    Stats,
    Transcript,
)

QueuePolicy = Literal["latest", "fifo"]


@dataclass(frozen=True)
class Topic:
    name: str  # how nodes refer to it
    pattern: str  # below the prefix; {placeholders} are one key chunk each
    schema: type[Sample]
    description: str = ""
    image: bool = False  # an encoded image: its header is checked against --max-pixels before it is decoded

    def placeholders(self) -> list[str]:
        """The names of the pattern's {placeholders}, in order (e.g. ['cam'])."""
        return [chunk[1:-1] for chunk in self.pattern.split("/") if chunk.startswith("{")]

    def wildcard(self) -> str:
        """The pattern with every placeholder as '*': what a subscriber to all of it declares."""
        return "/".join("*" if chunk.startswith("{") else chunk for chunk in self.pattern.split("/"))


# The one table of what is published where.
TOPICS: tuple[Topic, ...] = (
    Topic("frame", "camera/{cam}/frame", Frame, "colour images", image=True),
    Topic("depth", "camera/{cam}/depth", DepthFrame, "depth images aligned to the colour ones"),
    Topic("audio", "audio/{mic}/pcm", AudioChunk, "microphone audio"),
    Topic("objects", "vision/{cam}/objects", Detections, "detected objects"),
    Topic("hands", "gesture/{cam}/hands", Hands, "hands and pointing rays"),
    Topic("event", "gesture/{cam}/event", GestureEvent, "gesture starts and ends"),
    Topic("bodies", "gesture/{cam}/bodies", Bodies, "body poses"),
    Topic("faces", "gesture/{cam}/faces", Faces, "faces: mouth opening and head orientation"),
    Topic("persons", "gesture/{cam}/persons", Persons, "people in view with stable ids"),
    Topic("transcript", "speech/{mic}/transcript", Transcript, "recognised utterances"),
    Topic("decoding", "speech/{mic}/decoding", SpeechDecoding, "speech is decoding an utterance: video eases"),
    Topic("command", "fusion/command", FusedCommand, "grounded commands"),
    Topic("clarification", "fusion/clarification", Clarification, "questions back to the person"),
    Topic("spoken", "voice/{speaker}/spoken", Spoken, "what the robot's voice says and when"),
    Topic("voice_audio", "voice/{speaker}/pcm", AudioChunk, "the robot's voice as audio, for a speaker and echo"),
    Topic("stats", "stats/{service}/{instance}", Stats, "every node's counters (answered on query)"),
    Topic("robot_profile", "robot/profile", RobotProfile, "what the robot can do (also answered on query)"),
    Topic("robot_state", "robot/state", RobotState, "what the robot is doing, from the robot"),
)


@dataclass(frozen=True)
class Input:
    topic: str  # a name in TOPICS
    policy: QueuePolicy = "fifo"  # latest: one slot per key, newest wins (frames); fifo: lossless up to maxlen
    maxlen: int = 1000
    monotonic: bool = False  # stamps must not go back (a camera or microphone stream)
    joined: bool = False  # fusion's join waits for the publisher's watermark on this input
    modality: bool = True  # its publisher is a modality fusion weighs (the robot's own state is not)


@dataclass(frozen=True)
class Container:
    """How docker-compose.yml runs a node (`python -m hri.compose` writes the file from NODES).

    `flags` is compose text: `${VAR:-default}` is substituted by compose. With `flags_env` (the default) the
    variable HRI_<NAME>_ARGS replaces the flags as a whole; a node with knobs of its own (the camera's
    HRI_CAMERA_SOURCE) sets it False and writes them into `flags`.
    """

    flags: str = ""
    flags_env: bool = True
    note: str = ""  # a comment above its command in docker-compose.yml (why these defaults)
    mounts: tuple[str, ...] = ()  # volumes besides HRI_DATA at /data, compose syntax


# Niceness of the services that read frames: weight 110 against 1024 for a nice-0 process (Linux CFS), so a
# speech decode or a fusion decision gets the cores at once; the frame services take what is left and skip.
FRAME_NICE = 10
# Speech asks for more than a nice-0 process (weight 3121 vs 1024) where the system allows it (root or
# CAP_SYS_NICE; else it runs at 0): a decode is short (under a CPU-second) and every word waits for it.
SPEECH_NICE = -5


@dataclass(frozen=True)
class Node:
    name: str
    description: str
    inputs: tuple[Input, ...] = ()
    outputs: tuple[str, ...] = ()  # topic names
    reads_images: bool = False  # takes --max-pixels (rejects oversized frames before decoding); must be True
    # when an input is an image topic
    container: Container = Container()  # docker-compose.yml: no flags, HRI_<NAME>_ARGS adds some
    # default --nice: its CPU priority (> 0 lower, < 0 higher where allowed). Frame services skip stale frames
    # when they fall behind; speech and fusion cannot skip, so on a small machine frame work yields (issue #34)
    nice: int = 0
    opt_in: bool = False  # off by default: `hri up --<name>` starts it, docker compose under the profile <name>
    fixed_keys: tuple[str, ...] = ()  # exact keys (below the prefix) it publishes besides its outputs' patterns

    @property
    def module(self) -> str:
        return module_of(self.name)

    @property
    def args_variable(self) -> str:
        """The environment variable whose value replaces the node's flags in docker-compose.yml."""
        return f"HRI_{self.name.upper()}_ARGS"

    def input(self, topic: str) -> Input:
        for i in self.inputs:
            if i.topic == topic:
                return i
        raise KeyError(
            f"{self.name} declares no input {topic!r}: declare it in {self.name}'s Node in common/stack.py "
            f"(it reads {', '.join(self.input_names()) or 'nothing'})"
        )

    def input_names(self) -> list[str]:
        return [i.topic for i in self.inputs]


@dataclass(frozen=True)
class Client:
    """Not a process of the stack, but someone with a role on the wire (access control)."""

    name: str
    description: str
    outputs: tuple[str, ...] = ()
    reads_everything: bool = False
    fixed_keys: tuple[str, ...] = field(default=())  # exact keys it may publish (below the prefix)
    user: str | None = None  # the user `hri secure init` creates for it (None: the role only, given with --user)


# The stack, in start order after the router.
NODES: tuple[Node, ...] = (
    Node(
        "camera",
        "frames (and depth) from a webcam, RealSense, video, folder or photo",
        outputs=("frame", "depth"),
        container=Container(
            "--source ${HRI_CAMERA_SOURCE:-/data/demo/table.png} --fps 5 --loop",
            flags_env=False,
            note="The demo's table of candies (one red, two green, …), 5 fps; HRI_CAMERA_SOURCE=/data/images/tabletop\n"
            "cycles the other shipped photos, a video file or folder under HRI_DATA works too.",
        ),
    ),
    Node(
        "vision",
        "objects with class, colour and position",
        inputs=(
            Input("depth", "latest", monotonic=True),  # the camera sends depth just before colour
            Input("frame", "latest", monotonic=True),
            Input("decoding", "fifo", maxlen=10),  # speech first (issue #42): served before the frames
        ),
        outputs=("objects",),
        reads_images=True,
        nice=FRAME_NICE,
        container=Container(
            "--backend color --labels /data/demo/labels.json",
            note='Colour segmentation, objects named "candy" as in the demo scene. '
            "HRI_VISION_ARGS replaces the flags,\n"
            'e.g. "--backend onnx --model /models/yolox_nano.onnx" with the model\'s folder in HRI_MODELS.',
            mounts=("${HRI_MODELS:-./data}:/models:ro",),
        ),
    ),
    Node(
        "gesture",
        "hands, bodies, pointing rays and gesture events",
        inputs=(
            Input("frame", "latest", monotonic=True),
            Input("depth", "fifo", maxlen=4),
            Input("decoding", "fifo", maxlen=10),  # speech first (issue #42): served before the frames
        ),
        outputs=("hands", "bodies", "event", "faces", "persons"),
        reads_images=True,
        nice=FRAME_NICE,
    ),
    Node(
        "speech",
        "voice activity -> Whisper -> transcripts with times and confidence",
        inputs=(
            Input("audio", "fifo", maxlen=2000, monotonic=True),
            # the robot's own voice: when it speaks (masked) and what it played (the echo to cancel; docs/voice.md)
            Input("spoken", "fifo", maxlen=100),
            Input("voice_audio", "fifo", maxlen=2000, monotonic=True),
        ),
        outputs=("transcript", "decoding"),
        nice=SPEECH_NICE,
        container=Container(
            "--input zenoh",
            note="Default: AudioChunks over zenoh from a microphone elsewhere (a container has no sound card).\n"
            'HRI_SPEECH_ARGS="--input wav --wav /data/<folder> --wait-for fusion,vision" '
            "transcribes WAV files instead.",
        ),
    ),
    Node(
        "fusion",
        "joins the modalities on source time, grounds the command, asks when unsure",
        inputs=(
            Input("transcript", "fifo", maxlen=200),
            Input("objects", "fifo", maxlen=300, joined=True),
            Input("hands", "fifo", maxlen=600, joined=True),
            Input("event", "fifo", maxlen=200, joined=True),
            Input("bodies", "fifo", maxlen=50),  # which way the speaker faces
            Input("faces", "fifo", maxlen=600),  # mouths over time: who is speaking (issue #33)
            Input("persons", "fifo", maxlen=300),  # people in view with stable ids
            Input("robot_state", "fifo", maxlen=50, modality=False),  # the robot's own state (docs/robot.md)
            Input("spoken", "fifo", maxlen=100, modality=False),  # a question said aloud: its answer window (voice.md)
        ),
        outputs=("command", "clarification", "robot_profile"),
    ),
    Node(
        "ros2",
        "ROS 2 over rmw_zenoh: people (REP-155), objects, commands out; a ROS camera and text in",
        inputs=(
            Input("persons", "latest"),  # REP-155 topics are states: the newest per camera is what counts
            Input("bodies", "latest"),
            Input("faces", "latest"),
            Input("objects", "latest"),
            Input("command", "fifo", maxlen=100),
            Input("clarification", "fifo", maxlen=100),
            Input("spoken", "fifo", maxlen=100),  # what the robot's voice says, as text (~/robot_speech)
            Input("frame", "latest"),  # for the camera's intrinsics (sensor_msgs/CameraInfo), on change
            Input("robot_profile", "latest"),  # the robot's profile from fusion, latched on ROS (docs/robot.md)
        ),
        outputs=("frame", "depth", "robot_state"),  # a ROS 2 camera as the stack's camera; the robot's state
        reads_images=True,
        container=Container(
            note="ROS 2 (rmw_zenoh) beside the stack: `docker compose --profile ros2 up -d`; ROS nodes with\n"
            'RMW_IMPLEMENTATION=rmw_zenoh_cpp connect to this router (docs/ros2.md); HRI_ROS2_ARGS="--domain-id 3".',
        ),
        opt_in=True,
        # typed commands from a ROS std_msgs/String topic, as `hri say` sends them (not a speech modality)
        fixed_keys=("speech/ros/transcript",),
    ),
    Node(
        "voice",
        "speaks fusion's questions and refusals (piper, offline) to a WAV, a sound device or the wire",
        inputs=(Input("clarification", "fifo", maxlen=100), Input("command", "fifo", maxlen=100)),
        outputs=("spoken", "voice_audio"),
        container=Container(
            note="The robot's voice: `docker compose --profile voice up -d`; its audio goes out as AudioChunks on\n"
            'hri/voice/robot/pcm (a container has no sound card); HRI_VOICE_ARGS="--confirm" also confirms commands.',
        ),
        opt_in=True,
    ),
)
CLIENTS: tuple[Client, ...] = (
    Client("mic", "a microphone elsewhere sending AudioChunks", outputs=("audio",), user="mic"),
    Client("keyboard", "hri say (typed commands)", fixed_keys=("speech/kbd/transcript",)),
    Client("robot", "the robot's own controller, saying what it is doing", outputs=("robot_state",)),
    Client(
        "replay",
        "hri replay: puts recorded samples back",
        outputs=tuple(t for n in NODES if n.name != "fusion" for t in n.outputs) + ("audio",),
    ),
    Client(
        "reader", "hri echo / list / stats / record, a planner listening to commands", reads_everything=True, user="cli"
    ),
)


# The functions below read NODES and TOPICS when called (not the NODE/TOPIC dicts built at import), so what is
# derived from them follows the declaration, also where a test adds an entry.


def module_of(name: str) -> str:
    """The module a node runs as: `python -m services.<name>`."""
    return f"services.{name}"


def node(name: str) -> Node:
    for n in NODES:
        if n.name == name:
            return n
    raise KeyError(f"no node {name!r} in the stack (common/stack.py NODES): {', '.join(n.name for n in NODES)}")


def topic(name: str) -> Topic:
    for t in TOPICS:
        if t.name == name:
            return t
    raise KeyError(f"no topic {name!r} in the stack (common/stack.py TOPICS): {', '.join(t.name for t in TOPICS)}")


def publishers_of(topic: str) -> list[str]:
    """The nodes that publish `topic`."""
    return [n.name for n in NODES if topic in n.outputs]


def check_stack() -> None:
    """Every name refers to a declared topic, and a node reading images says so; raises ValueError naming the
    first entry that does not."""
    topics = {t.name: t for t in TOPICS}
    for declared in TOPICS:
        if declared.image and declared.schema is not Frame:
            raise ValueError(f"topic {declared.name}: an image topic's schema is Frame (its header is checked)")
    for n in NODES:
        for t in [i.topic for i in n.inputs] + list(n.outputs):
            if t not in topics:
                raise ValueError(f"node {n.name}: unknown topic {t!r}; topics: {', '.join(topics)}")
        images = [i.topic for i in n.inputs if topics[i.topic].image]
        if images and not n.reads_images:
            raise ValueError(f"node {n.name} reads the image topic(s) {images}: declare it with reads_images=True")
    for c in CLIENTS:
        for t in c.outputs:
            if t not in topics:
                raise ValueError(f"client {c.name}: unknown topic {t!r}")


check_stack()

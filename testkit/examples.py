"""The contract's example samples: one valid instance of every schema, small and hand-written (the codec tests
round-trip and break them; testkit/payloads.py makes the benchmarks' realistic samples from them)."""

import common.stack as stack
from common.keys import Keys
from common.schema import (
    AudioChunk,
    Bodies,
    Body,
    CameraInfo,
    CameraMount,
    Clarification,
    ColorShare,
    DepthFrame,
    DetectedObject,
    Detections,
    Face,
    Faces,
    Frame,
    FusedCommand,
    GestureEvent,
    Hand,
    Hands,
    HeldObject,
    ImageQuality,
    Location,
    Loudness,
    Motion,
    Person,
    Persons,
    Ray,
    Ray3D,
    RobotProfile,
    RobotState,
    Sample,
    Speaker,
    SpeechDecoding,
    Spoken,
    Stats,
    Target,
    Transcript,
    Weights,
    Word,
)

T = 1_790_000_000.0
LANDMARKS = [[100.0 + i, 200.0 - i] for i in range(21)]
RAY = Ray(origin=[120.0, 180.0], direction=[0.6, -0.8], confidence=0.9)
TARGET = Target(id="o3", label="cup", color="red", bbox=[10, 20, 30, 40], center=[25, 40], score=0.8, cam="cam0")
SPEAKER = Speaker(person="person-1", confidence=0.8, method="mouth_motion", addressed=True, reason="mouth moved")
INFO_2X2 = CameraInfo(width=2, height=2, k=[600.0, 0.0, 1.0, 0.0, 600.0, 1.0, 0.0, 0.0, 1.0], frame_id="cam0_optical")


def examples():
    return [
        Frame(
            stamp=T,
            source="camera/a",
            seq=7,
            cam="cam0",
            width=2,
            height=2,
            encoding="bgr8",
            data=bytes(12),
            camera_info=INFO_2X2,
        ),
        AudioChunk(stamp=T, source="mic/a", mic="mic0", rate=16000, channels=1, format="s16le", data=bytes(640)),
        Detections(
            stamp=T,
            source="vision/a",
            seq=7,
            cam="cam0",
            width=640,
            height=480,
            objects=[
                DetectedObject(id="o1", label="candy", color="red", score=0.9, bbox=[1, 2, 3, 4], center=[2.5, 4.0]),
                DetectedObject(
                    id="o2",
                    label="cup",
                    color="red",
                    score=0.8,
                    bbox=[5, 6, 7, 8],
                    center=[8.5, 10.0],
                    lab=[38.0, 45.0, 30.0],
                    colors=[ColorShare(name="red", p=0.7), ColorShare(name="brown", p=0.2)],
                    position=[0.1, -0.05, 0.9],
                    extent=[0.08, 0.1, 0.06],
                    depth_support=0.8,
                ),
            ],
            quality=ImageQuality(brightness=0.5, contrast=0.4, sharpness=0.9),
            frame_id="cam0_optical",
        ),
        Hands(
            stamp=T,
            source="gesture/a",
            seq=7,
            cam="cam0",
            width=640,
            height=480,
            hands=[
                Hand(
                    hand="right",
                    score=0.97,
                    landmarks=LANDMARKS,
                    gesture="point",
                    ray=Ray(
                        origin=[120.0, 180.0],
                        direction=[0.6, -0.8],
                        confidence=0.9,
                        source="hand",
                        ray3d=Ray3D(
                            origin=[0.0, -0.4, 1.5],
                            direction=[0.0, 0.6, -0.8],
                            method="eye_fingertip",
                            frame_id="cam0_optical",
                        ),
                    ),
                )
            ],
        ),
        GestureEvent(
            stamp=T,
            source="gesture/a",
            cam="cam0",
            width=640,
            height=480,
            gesture="point",
            phase="start",
            start=T - 0.2,
            end=T,
            score=0.9,
            hand="right",
            ray=RAY,
        ),
        Transcript(
            stamp=T,
            source="speech/a",
            mic="mic0",
            start=T - 1.2,
            end=T,
            text="pick up that cup",
            confidence=0.8,
            words=[Word(word="pick", start=T - 1.2, end=T - 1.0, confidence=0.9)],
            final=True,
            backend="pocketsphinx",
            loudness=Loudness(start=T - 1.3, step=0.02, db=[-62, -35, -24, -120]),
        ),
        FusedCommand(
            stamp=T,
            source="fusion/a",
            id="c1",
            intent="pick_up",
            text="pick up that cup",
            target=TARGET,
            location=Location(x=10, y=20, cam="cam0"),
            gesture="point",
            confidence=0.7,
            weights=Weights(speech=0.4, vision=0.3, gesture=0.3),
            inputs={"speech": T, "vision": T - 0.1, "gesture": None},
            explanation="red cup, pointed at",
            prompt="Command: pick up ...",
            motion=Motion(direction="forward", distance=0.5, angle=0.0),
            speaker=SPEAKER,
        ),
        Clarification(
            stamp=T,
            source="fusion/a",
            id="q1",
            text="pick up the cup",
            reason="ambiguous",
            question="Which cup: the red one on the left or the blue one on the right?",
            candidates=[TARGET, TARGET],
            speaker=SPEAKER,
        ),
        Stats(
            stamp=T,
            source="vision/a",
            service="vision",
            instance="a",
            uptime=3.0,
            received=10,
            published=9,
            skipped=1,
            rejected={"not_msgpack": 2},
            other={"undecodable": 1},
        ),
        Bodies(
            stamp=T,
            source="gesture/a",
            seq=7,
            cam="cam0",
            width=640,
            height=480,
            bodies=[
                Body(
                    landmarks=[[300.0 + i, 100.0 + 8 * i] for i in range(33)],
                    visibility=[0.9] * 33,
                    right_ray=Ray(origin=[200.0, 250.0], direction=[-0.6, 0.8], confidence=0.8, source="body"),
                    person="person-1",
                )
            ],
        ),
        Faces(
            stamp=T,
            source="gesture/a",
            seq=7,
            cam="cam0",
            width=640,
            height=480,
            faces=[
                Face(
                    id="face-1",
                    person="person-1",
                    bbox=[280.0, 60.0, 80.0, 90.0],
                    score=0.95,
                    mouth_open=0.12,
                    yaw=-5.0,
                    pitch=2.0,
                    looking_at_camera=True,
                )
            ],
        ),
        Persons(
            stamp=T,
            source="gesture/a",
            seq=7,
            cam="cam0",
            width=640,
            height=480,
            persons=[
                Person(
                    id="person-1",
                    bbox=[240.0, 50.0, 180.0, 420.0],
                    score=0.9,
                    face="face-1",
                    has_body=True,
                    hands=["right"],
                    position=[0.1, 0.0, 1.8],
                    frame_id="cam0_optical",
                    speaking=0.7,
                    engaged=True,
                    engagement="engaged",
                )
            ],
        ),
        Spoken(
            stamp=T,
            source="voice/a",
            id="question-q1",
            text="Which cup: the red one on the left or the blue one on the right?",
            kind="question",
            answers="q1",
            start=T,
            end=T + 3.2,
            speaker="robot",
            voice="piper:joe",
        ),
        RobotProfile(
            stamp=T,
            source="fusion/a",
            name="tabletop-arm",
            never_grasp={"furniture": ["chair", "couch"]},
            max_weight_kg=1.0,
            max_size_m=0.3,
            weights_kg={"cup": 0.3, "laptop": 2.0},
            carries=False,
            navigates=False,
            speaks=True,
            while_busy="queue",
            camera=CameraMount(
                parent="base_link", frame_id="cam0_optical", xyz=[0.0, -0.3, 0.6], rpy=[-2.2, 0.0, -1.57]
            ),
        ),
        RobotState(
            stamp=T,
            source="robot/a",
            status="busy",
            command="cmd-1f68d3158ccbc7f3",
            intent="bring",
            holding=HeldObject(label="cup", id="o3", color="red"),
        ),
        SpeechDecoding(stamp=T, source="speech/a", mic="mic0", decoding=True),
        DepthFrame(
            stamp=T,
            source="camera/a",
            seq=7,
            cam="cam0",
            width=2,
            height=2,
            encoding="16UC1",
            depth_scale=0.001,
            camera_info=INFO_2X2,
            data=bytes(8),
        ),
    ]


def example_key(sample: Sample, keys: Keys | None = None) -> str:
    """The key the stack publishes `sample` on: the first topic of common/stack.py whose schema is the sample's
    type (the microphone's audio before the robot's voice), its placeholders filled from the sample's fields."""
    topic = next(t for t in stack.TOPICS if t.schema is type(sample))
    chunks = {name: str(getattr(sample, name)) for name in topic.placeholders()}
    return (keys or Keys()).key(topic.name, **chunks)

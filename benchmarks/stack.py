"""The whole stack as users start it (`hri up`), on a real clip at 30 fps with its audio, for a minute or more.

What runs: `hri up` (router, camera, vision with YOLOX-Nano ONNX, gesture, speech, fusion) with
- the camera on a real talking-person clip (../shared/data/talking, 25 fps), looped and paced at `--fps` (30);
- speech playing, in real time (`--realtime`), the clip's own audio looped for the run's length, with spoken
  COMMAND sentences (piper's neural voice, testkit/synth.py; espeak-ng if piper is missing) put in at known times
  between the clip's sentences: the clip's people talk but give no command, so every command the stack emits
  beyond the spoken ones is one "nobody gave" — except, on an intent clip (../shared/data/intent), a gesture
  command inside one of the clip's labelled deliberate gestures (intent.json; `labelled_gestures`), which was given.

What it reports, over the measured window (from the moment every service is live):
- per service: CPU share of the machine (/proc/<pid>/stat utime+stime of the service and its children, divided
  by wall time x cores), frames/samples received, published and skipped as stale (the services' own Stats),
  and the lag of each output from its source stamp to its arrival here (same host, same clock: p50/p99, and
  p50 of the first and last third of the run, to see whether it grows);
- speech: last word -> command latency (arrival of the FusedCommand minus the end of the last recognised word
  of its transcript, both on this host's clock) for every spoken command, while video flows;
- fusion: every command emitted, the spoken ones and the rest.

**Scenes** (issue #42: the stack's cost grows with what the scene holds): `--scene NAME` (repeatable; default:
every scene of SCENES, the development set only — never the held-back clips) picks real material from ../shared:
a clean talking head, two speakers side by side, people talking with their hands, and a slideshow of the people,
pointing and home photos (several people, many objects; each photo held `SLIDE_SECONDS`, fitted into 640x480 in a
temporary folder). A clip without its own audio gets a talking clip's audio under the commands. After the runs,
one line per scene against the goal of issue #42 (`GOAL`: the stack <= 1.8 of 2 cores, gesture >= 20 Hz with lag
p99 <= 120 ms, vision >= 10 Hz with p99 <= 200 ms, faces >= 10 Hz, persons >= 5 Hz, no lag growing, last word ->
command p50 <= 450 ms, no command nobody gave), naming each figure that misses it and the service behind it.
Measured on a shared machine the figures say nothing of the goal: the load average before and after each run is
printed beside them. `--clip PATH` runs that clip (with the .wav beside it) as the one scene instead.

`--compare` runs the stack twice in one invocation, first with the knobs of issue #34 turned off (the "before":
`BEFORE_ARGS`), then as it ships, and prints both side by side so the ratio is meaningful on a shared machine.
`--speech-alone` adds a third run with no camera, vision or gesture: the same audio, speech's latency with no video
flowing (the control: what video costs speech on this machine, now).

Usage: python benchmarks/stack.py [--seconds 60] [--scene NAME ...] [--clip PATH] [--commands 5] [--compare]
                                  [--speech-alone] [--rounds N] [--variant LABEL=FLAGS] [--size 640x480]
                                  [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from common.codec import decode
from common.keys import Keys
from common.schema import Bodies, Detections, Faces, FusedCommand, Hands, Persons, Sample, Transcript
from services.speech.audio import RATE, read_wav
from testkit.harness import Client, free_port
from testkit.synth import PIPER_VOICE, SynthError, read_wav_int16, synthesize, write_wav_int16

# this checkout (not testkit's ROOT: run as `python benchmarks/stack.py`, testkit may come from an installed copy);
# `hri up` runs here, so the services are this checkout's
ROOT = Path(__file__).resolve().parent.parent
SHARED = Path(
    os.environ.get("HRI_SHARED")
    or next((p for p in (ROOT.parent / "shared", ROOT.parent.parent / "shared") if p.is_dir()), ROOT.parent / "shared")
)  # beside the checkout, or beside its worktrees' folder
DEFAULT_MODEL = SHARED / "models" / "yolox_nano.onnx"
SERVICES = ("camera", "vision", "gesture", "speech", "fusion")
# Commands that need no object in view (the clip shows a man talking, no table): fusion grounds them alone.
COMMAND_SENTENCES = ("turn left", "stop", "come here", "go forward one meter", "turn right", "look at me")
# the outputs whose lag is measured: key below the prefix -> (schema, label)
OUTPUTS: dict[str, tuple[type[Sample], str]] = {
    "vision/*/objects": (Detections, "vision objects"),
    "gesture/*/hands": (Hands, "gesture hands"),
    "gesture/*/bodies": (Bodies, "gesture bodies"),
    "gesture/*/faces": (Faces, "gesture faces"),
    "gesture/*/persons": (Persons, "gesture persons"),
    "speech/*/transcript": (Transcript, "speech transcript"),
    "fusion/command": (FusedCommand, "fusion command"),
}
# The "before" of issue #34 (flags that turn its knobs off), for --compare: every service at normal priority and
# OpenCV's pools at its own size (every core); the rest of the changes (fusion, gestures) have no switch.
BEFORE_ARGS: list[str] = [
    "--vision-arg=--nice=0",
    "--gesture-arg=--nice=0",
    "--speech-arg=--nice=0",
    *(f"--{name}-arg=--cv-threads=0" for name in ("camera", "vision", "gesture")),
]


@dataclass(frozen=True)
class Scene:
    """Real material the camera plays, and the audio under the spoken commands (paths below ../shared)."""

    name: str
    what: str
    audio: str  # a 16 kHz WAV of people talking (the clip's own when it has one)
    video: str | None = None
    photos: tuple[str, ...] = ()  # a slideshow instead of a video


TALKING = "data/talking/real_single_vr1_cfr25"
SCENES: tuple[Scene, ...] = (
    Scene(
        "talking head", "one man talking to the camera (docs/benchmarks.md so far)", f"{TALKING}.wav", f"{TALKING}.mp4"
    ),
    Scene(
        "two speakers",
        "two people side by side taking turns",
        "data/talking/comp_turns_bbaf2n_lbbc2a.wav",
        "data/talking/comp_turns_bbaf2n_lbbc2a.mp4",
    ),
    Scene("talking hands", "a man talking with his hands", f"{TALKING}.wav", "data/intent/cat4_tango_speaker7.mp4"),
    Scene(
        "waving and signs",
        "a webcam: swipes, waves, thumbs up",
        f"{TALKING}.wav",
        "data/intent/cat2_webcam_swipe_wave_thumbs.mp4",
    ),
    Scene(
        "photos: people and objects",
        "several people, a living room of 10 objects, a kitchen, a table of cubes, a pointer",
        f"{TALKING}.wav",
        photos=(
            "data/people_multi/coco_val2014_000000000241.jpg",
            "data/people_multi/intel_headpose_pair_f000.png",
            "data/scenes/airbnb2_plant4.jpg",
            "data/people_multi/room_pointer_bystander_0219_t1.png",
            "data/pointing/nico_table_f01_red_cube.jpg",
            "data/people_multi/coco_val2014_000000000338.jpg",
            "data/people/four_15a73593-b13e-4a1b-99bb-51775cfdfc42.jpg",
            "data/pointing/room_woman_0126_t2_right_arm_to_image_right.png",
        ),
    ),
)
SLIDE_SECONDS = 3.0  # each photo of a slideshow is held this long (people sit still; the camera does not move)


def slideshow(photos: list[Path], folder: Path, fps: float, size: tuple[int, int] = (640, 480)) -> Path:
    """A folder the camera plays in name order: each photo fitted into `size` (padded black), written once beside
    it and linked SLIDE_SECONDS x fps times (temporary: nothing derived from ../shared is kept)."""
    import cv2

    stills = folder.with_name(folder.name + "_stills")
    folder.mkdir(parents=True, exist_ok=True)
    stills.mkdir(parents=True, exist_ok=True)
    held = max(1, round(SLIDE_SECONDS * fps))
    for k, photo in enumerate(photos):
        img = cv2.imread(str(photo))
        if img is None:
            raise RuntimeError(f"cannot read {photo}")
        scale = min(size[0] / img.shape[1], size[1] / img.shape[0])
        fitted = (round(img.shape[1] * scale), round(img.shape[0] * scale))
        small = cv2.resize(img, fitted, interpolation=cv2.INTER_AREA)
        canvas = np.zeros((size[1], size[0], 3), np.uint8)
        y0, x0 = (size[1] - small.shape[0]) // 2, (size[0] - small.shape[1]) // 2
        canvas[y0 : y0 + small.shape[0], x0 : x0 + small.shape[1]] = small
        still = stills / f"photo{k:02d}.png"
        cv2.imwrite(str(still), canvas)
        for n in range(held):
            (folder / f"{k:02d}_{n:04d}.png").symlink_to(still)
    return folder


def scene_source(scene: Scene, tmp: Path, fps: float) -> Path:
    """What the camera plays for `scene`: its video, or its photos as a slideshow folder under `tmp`."""
    if scene.video is not None:
        return SHARED / scene.video
    name = re.sub(r"\W+", "_", scene.name)
    return slideshow([SHARED / p for p in scene.photos], tmp / f"slides_{name}", fps)


def missing_material(scene: Scene) -> list[str]:
    return [
        p for p in (scene.audio, *([scene.video] if scene.video else []), *scene.photos) if not (SHARED / p).exists()
    ]


@dataclass
class Spoken:
    text: str
    at: float  # seconds into the WAV where the sentence's speech starts
    end: float  # ... and ends (last sample above 1 % of its peak)


@dataclass
class Audio:
    path: Path
    seconds: float
    spoken: list[Spoken]


def _speech_span(samples: np.ndarray) -> tuple[float, float]:
    loud = np.flatnonzero(np.abs(samples.astype(np.float64)) > 0.01 * max(1.0, float(np.max(np.abs(samples)))))
    return (loud[0] / RATE, loud[-1] / RATE) if loud.size else (0.0, 0.0)


def _say(text: str, out: Path) -> np.ndarray:
    try:
        synthesize(text, out, voice=PIPER_VOICE, lead_silence=0.6, trail_silence=0.6)
    except SynthError:  # no piper: espeak-ng's formant voice
        synthesize(text, out, voice="en-us", lead_silence=0.6, trail_silence=0.6)
    return read_wav_int16(out)


def build_audio(clip_wav: Path, seconds: float, commands: int, folder: Path) -> Audio:
    """The clip's own audio looped over `seconds` and 15 s more (the services' start-up), with `commands` spoken
    command sentences put in, spread over the first `seconds` (each after a whole pass of the clip's audio, so no
    command overlaps the clip's talk)."""
    talk = read_wav(clip_wav)
    assert talk.rate == RATE, f"{clip_wav}: expected a {RATE} Hz WAV"
    clip = np.asarray(talk.samples, dtype=np.int16).reshape(-1)
    every = seconds / (commands + 1)
    parts: list[np.ndarray] = []
    spoken: list[Spoken] = []
    length, next_command = 0, every
    while length < (seconds + 15) * RATE:
        if len(spoken) < commands and length >= next_command * RATE:
            text = COMMAND_SENTENCES[len(spoken) % len(COMMAND_SENTENCES)]
            said = _say(text, folder / f"command{len(spoken)}.wav")
            start, end = _speech_span(said)
            spoken.append(Spoken(text, length / RATE + start, length / RATE + end))
            parts.append(said)
            length += len(said)
            next_command += every
            continue
        parts.append(clip)
        length += len(clip)
    out = folder / "stack_audio.wav"
    write_wav_int16(out, np.concatenate(parts))
    return Audio(out, length / RATE, spoken)


# ---- per-process CPU from /proc ---------------------------------------------------------------------------------


def _proc_stat(pid: int) -> tuple[int, float] | None:
    """(parent pid, utime + stime in seconds) of a live process, None if it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2 :].split()  # after "pid (comm) "
    ticks = os.sysconf("SC_CLK_TCK")
    return int(fields[1]), (int(fields[11]) + int(fields[12])) / ticks


def _cmdline(pid: int) -> list[str]:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
    except OSError:
        return []


def _all_parents() -> dict[int, int]:
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            stat = _proc_stat(int(entry.name))
            if stat is not None:
                parents[int(entry.name)] = stat[0]
    return parents


def service_pids(root_pid: int) -> dict[str, int]:
    """The pid of each stack process below `root_pid` (`hri up`), by name ("router" or a service)."""
    parents = _all_parents()
    children: dict[int, list[int]] = {}
    for pid, ppid in parents.items():
        children.setdefault(ppid, []).append(pid)
    found: dict[str, int] = {}
    todo = list(children.get(root_pid, []))
    while todo:
        pid = todo.pop()
        argv = _cmdline(pid)
        if "-m" in argv and argv.index("-m") + 1 < len(argv):
            module = argv[argv.index("-m") + 1]
            name = "router" if module == "hri.cli" and "router" in argv else module.removeprefix("services.")
            found.setdefault(name, pid)
        todo += children.get(pid, [])
    return found


def cpu_seconds(pid: int) -> float:
    """CPU seconds of `pid` and of its live descendants."""
    parents = _all_parents()
    total, todo = 0.0, [pid]
    while todo:
        p = todo.pop()
        stat = _proc_stat(p)
        total += stat[1] if stat else 0.0
        todo += [c for c, pp in parents.items() if pp == p]
    return total


# ---- what arrives -----------------------------------------------------------------------------------------------


@dataclass
class Arrival:
    at: float  # wall time of arrival
    stamp: float
    sample: Any


@dataclass
class Recorder:
    keys: Keys
    start: float = 0.0
    arrivals: dict[str, list[Arrival]] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def listen(self, client: Client) -> None:
        for pattern, (schema, label) in OUTPUTS.items():
            self.arrivals[label] = []
            client._subs.append(
                client.session.declare_subscriber(f"{self.keys.prefix}/{pattern}", self._handler(schema, label))
            )

    def _handler(self, schema: type[Sample], label: str) -> Callable[[Any], None]:
        return lambda raw: self._on(raw, schema, label)

    def _on(self, raw: Any, schema: type[Sample], label: str) -> None:
        now = time.time()
        try:
            sample = decode(raw.payload.to_bytes(), schema)
        except Exception:  # a bad sample is the services' business; here it is simply not measured
            return
        with self.lock:
            if now >= self.start > 0:
                self.arrivals[label].append(Arrival(now, sample.stamp, sample))

    def count(self, label: str) -> int:
        with self.lock:
            return len(self.arrivals[label])


def _percentile(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


def lag_figures(arrivals: list[Arrival], seconds: float) -> dict[str, Any]:
    """Count, rate and lag (arrival - source stamp, ms) of one output; p50 of the first and last third."""
    lags = [(a.at - a.stamp) * 1000.0 for a in arrivals]
    thirds = [
        [lags[i] for i, a in enumerate(arrivals) if int(3 * (a.at - arrivals[0].at) / seconds) == k] for k in (0, 2)
    ]
    return {
        "count": len(arrivals),
        "rate_hz": len(arrivals) / seconds,
        "lag_p50_ms": _percentile(lags, 50),
        "lag_p99_ms": _percentile(lags, 99),
        "lag_p50_first_third_ms": _percentile(thirds[0], 50) if arrivals else None,
        "lag_p50_last_third_ms": _percentile(thirds[1], 50) if arrivals else None,
    }


LABEL_TOLERANCE_S = 0.5  # intent.json's times are by eye, about +-0.3 s; a wave's call comes at its end


def labelled_gestures(clip: Path) -> tuple[list[tuple[float, float, str]], float, int]:
    """An intent clip's labelled deliberate gestures (../shared/data/intent/intent.json): (start, end, intent) for
    each event of a clip that expects that intent, a wave for come_here/greet, a palm or stop for stop; with the
    clip's frame rate and frame count. ([], 0, 0): not an intent clip."""
    import cv2

    labels = clip.parent / "intent.json"
    if clip.parent.name != "intent" or not labels.exists():
        return [], 0.0, 0
    meta = next((c for c in json.loads(labels.read_text())["clips"] if c["file"] == clip.name), None)
    if meta is None:
        return [], 0.0, 0
    expected = {i for e in meta["expect"] for i in e.split(" ")[0].split("|")}
    words = {"come_here": ("wave",), "greet": ("wave",), "stop": ("palm", "stop")}
    given = [
        (float(start), float(end), intent)
        for start, end, text in meta["events"]
        for intent in sorted(expected)
        if any(w in text.lower() for w in words.get(intent, ()))
    ]
    cap = cv2.VideoCapture(str(clip))
    fps, frames = float(cap.get(cv2.CAP_PROP_FPS) or 0.0), int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
    cap.release()
    return given, fps, frames


def clip_time(stamp: float | None, seqs: dict[float, int], fps: float, frames: int) -> float | None:
    """Source time in the (looped) clip of the frame stamped `stamp`: its seq (from the gesture stage's per-frame
    samples) modulo the clip's frames, over its frame rate. None when unknown."""
    if stamp is None or not seqs or fps <= 0 or frames <= 0:
        return None
    nearest = min(seqs, key=lambda s: abs(s - stamp))
    return (seqs[nearest] % frames) / fps if abs(nearest - stamp) < 0.1 else None


def gesture_given(intent: str, at: float | None, labelled: list[tuple[float, float, str]]) -> bool:
    """Was a gesture command of `intent` at clip time `at` given: inside a labelled deliberate gesture of that intent
    (+- LABEL_TOLERANCE_S)?"""
    return at is not None and any(
        meant == intent and start - LABEL_TOLERANCE_S <= at <= end + LABEL_TOLERANCE_S for start, end, meant in labelled
    )


def command_figures(recorder: Recorder, audio: Audio, clip: Path | None = None) -> dict[str, Any]:
    """Every command emitted; for the spoken ones, last recognised word -> command arrival. On an intent clip, a
    gesture command inside one of its labelled deliberate gestures was given (`labelled_gestures`); any other
    command without speech is one nobody gave."""
    transcripts = {a.sample.stamp: a for a in recorder.arrivals["speech transcript"]}
    labelled, fps, frames = labelled_gestures(clip) if clip is not None else ([], 0.0, 0)
    seqs = {a.sample.stamp: a.sample.seq for a in recorder.arrivals["gesture hands"]} if labelled else {}
    commands: list[dict[str, Any]] = []
    latencies: list[float] = []
    heard_after: list[float] = []
    for a in recorder.arrivals["fusion command"]:
        cmd: FusedCommand = a.sample
        heard = transcripts.get(cmd.inputs.get("speech") or -1.0)
        entry: dict[str, Any] = {"intent": cmd.intent, "text": cmd.text, "gesture": cmd.gesture}
        if cmd.gesture and not cmd.text and labelled:
            entry["clip_s"] = clip_time(cmd.inputs.get("gesture"), seqs, fps, frames)
            entry["given"] = gesture_given(cmd.intent, entry["clip_s"], labelled)
        if heard is not None:
            tr: Transcript = heard.sample
            last_word = tr.words[-1].end if tr.words else tr.end
            entry["last_word_to_command_ms"] = (a.at - last_word) * 1000.0
            entry["last_word_to_transcript_ms"] = (heard.at - last_word) * 1000.0
            latencies.append(entry["last_word_to_command_ms"])
            heard_after.append(entry["last_word_to_transcript_ms"])
        commands.append(entry)
    return {
        "spoken": [s.text for s in audio.spoken],
        "emitted": commands,
        "emitted_without_speech": sum(1 for c in commands if not c["text"] and not c.get("given")),
        "gestures_given": sum(1 for c in commands if c.get("given")),
        "last_word_to_command_p50_ms": _percentile(latencies, 50),
        "last_word_to_command_max_ms": max(latencies) if latencies else None,
        # where the time goes: speech (the end-of-utterance silence, then decoding) and fusion (its window)
        "last_word_to_transcript_p50_ms": _percentile(heard_after, 50),
        "transcript_to_command_p50_ms": _percentile([c - h for c, h in zip(latencies, heard_after)], 50),
    }


# ---- one run ----------------------------------------------------------------------------------------------------


@dataclass
class RunConfig:
    clip: Path
    model: Path
    audio: Audio
    seconds: float
    fps: float
    extra: list[str]  # more `hri up` flags (e.g. the "before" knobs)
    label: str
    size: str | None = None  # camera --size WxH
    scene: str = ""


def up_argv(cfg: RunConfig, endpoint: str, prefix: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "hri.cli",
        "up",
        "--prefix",
        prefix,
        "--listen",
        endpoint,
        "--camera",
        str(cfg.clip),
        "--fps",
        f"{cfg.fps:g}",
        "--loop",
        "--vision-backend",
        "onnx",
        "--model",
        str(cfg.model),
        "--speech-input",
        "wav",
        "--wav",
        str(cfg.audio.path),
        "--speech-arg=--realtime",
        *([f"--camera-arg=--size={cfg.size}"] if cfg.size else []),
        *cfg.extra,
    ]


def _stats(client: Client, service: str) -> dict[str, Any]:
    try:
        return client.stats(service, timeout=5.0)
    except AssertionError:
        return {}


def started(extra: list[str]) -> set[str]:
    """The services a run starts (`--no-NAME` among its flags leaves one out)."""
    return {s for s in SERVICES if f"--no-{s}" not in extra}


def _wait_live(client: Client, up: subprocess.Popen, timeout: float, expected: set[str]) -> None:
    deadline = time.monotonic() + timeout
    while {s for s, _ in client.alive()} < expected:
        if up.poll() is not None:
            raise RuntimeError(f"hri up exited with code {up.returncode} before the stack came up")
        if time.monotonic() > deadline:
            raise RuntimeError(f"the stack was not live after {timeout:.0f} s")
        time.sleep(0.5)


def _progress(recorder: Recorder, elapsed: float, seconds: float) -> None:
    counts = ", ".join(f"{label} {recorder.count(label)}" for _, label in OUTPUTS.values())
    print(f"  {elapsed:5.0f}/{seconds:.0f} s  {counts}", flush=True)


@dataclass
class Window:
    wall: float
    cpu: dict[str, float]
    stats: dict[str, dict[str, Any]]


def _window(client: Client, pids: dict[str, int]) -> Window:
    return Window(
        time.time(),
        {name: cpu_seconds(pid) for name, pid in pids.items()},
        {name: _stats(client, name) for name in SERVICES if name in pids},
    )


def service_figures(first: Window, last: Window, cores: int) -> dict[str, Any]:
    wall = last.wall - first.wall
    out: dict[str, Any] = {}
    for name in first.cpu:
        out[name] = {"cpu_share_of_machine": (last.cpu.get(name, 0.0) - first.cpu[name]) / (wall * cores)}
        a, b = first.stats.get(name, {}), last.stats.get(name, {})
        for counter in ("received", "published", "skipped"):
            if counter in a and counter in b:
                out[name][counter] = b[counter] - a[counter]
        clocks = {k: v for k, v in b.get("other", {}).items() if k.startswith(("clock_offset_ms:", "delay_ms:"))}
        if clocks:
            out[name]["clocks"] = clocks  # fusion's view of each source: clock offset, or delay by design
    out["total_cpu_cores"] = sum(v["cpu_share_of_machine"] for v in out.values()) * cores
    return out


def run_stack(cfg: RunConfig) -> dict[str, Any]:
    load_before = os.getloadavg()[0]  # before this run's stack starts (a run before it still counts in it)
    port, prefix = free_port(), f"bench{os.getpid()}"
    endpoint = f"tcp/127.0.0.1:{port}"
    name = re.sub(r"[^\w.-]+", "_", cfg.label)  # a label may hold a '/' ("faces 15/s")
    log = open(Path(tempfile.gettempdir()) / f"hri-stack-bench-{prefix}-{name}.log", "w")  # noqa: SIM115
    up = subprocess.Popen(
        up_argv(cfg, endpoint, prefix), cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
    )
    print(f"[{cfg.label}] hri up (pid {up.pid}); services' log in {log.name}", flush=True)
    client: Client | None = None
    try:
        deadline = time.monotonic() + 30
        while client is None:
            try:
                client = Client(endpoint, prefix=prefix)
            except Exception:
                if time.monotonic() > deadline or up.poll() is not None:
                    raise
                time.sleep(0.3)
        _wait_live(client, up, timeout=180, expected=started(cfg.extra))
        recorder = Recorder(Keys(prefix))
        recorder.listen(client)
        pids = service_pids(up.pid)
        first = _window(client, pids)
        recorder.start = first.wall
        while time.time() - first.wall < cfg.seconds:
            time.sleep(min(5.0, cfg.seconds - (time.time() - first.wall)) or 0.1)
            _progress(recorder, time.time() - first.wall, cfg.seconds)
        last = _window(client, pids)
        recorder.start = float("inf")  # nothing more counts
        seconds = last.wall - first.wall
        return {
            "label": cfg.label,
            "scene": cfg.scene,
            "load_average": [round(load_before, 2), round(os.getloadavg()[0], 2)],  # 1-min, before and after
            "extra_flags": cfg.extra,
            "seconds": seconds,
            "services": service_figures(first, last, os.cpu_count() or 1),
            "outputs": {label: lag_figures(arr, seconds) for label, arr in recorder.arrivals.items()},
            "commands": command_figures(recorder, cfg.audio, cfg.clip),
        }
    finally:
        if client is not None:
            client.close()
        up.terminate()  # hri up stops its services in reverse order
        try:
            up.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(up.pid, 9)
            up.wait(5)
        log.close()


# ---- the goal of issue #42 --------------------------------------------------------------------------------------

GOAL = {
    "stack_cores_of_2": 1.8,  # scaled to the machine's cores: 90 % of them
    "gesture_hz": 20.0,
    "gesture_p99_ms": 120.0,
    "vision_hz": 10.0,
    "vision_p99_ms": 200.0,
    "faces_hz": 10.0,
    "persons_hz": 5.0,
    "last_word_to_command_p50_ms": 450.0,
}
GROWS = (1.5, 20.0)  # a lag grows when its last third's p50 is over 1.5x the first third's + 20 ms


def _service_note(result: dict[str, Any], service: str) -> str:
    s = result["services"].get(service, {})
    if not s:
        return f"{service} not measured"
    return f"{service} {100 * s['cpu_share_of_machine']:.0f} % of the machine, {s.get('skipped', '-')} frames skipped"


def _cpu_per_frame(result: dict[str, Any], service: str, rate_hz: float, goal_hz: float, cores: int) -> str:
    """'; 46 ms of CPU a frame: 20 Hz needs 0.92 cores, it had 0.60' (why a rate is missed), or ''."""
    share = result["services"].get(service, {}).get("cpu_share_of_machine")
    if share is None or rate_hz <= 0:
        return ""
    had = share * cores
    per_frame = had / rate_hz
    need = per_frame * goal_hz
    return f"; {1000 * per_frame:.0f} ms of CPU a frame: {goal_hz:g} Hz needs {need:.2f} cores, it had {had:.2f}"


def _rate_and_tail(
    result: dict[str, Any], label: str, service: str, hz: str, p99: str | None, cores: int = 2
) -> list[str]:
    if service not in result["services"]:
        return []  # not run (the speech-alone variant): nothing to judge
    o = result["outputs"].get(label)
    if not o or not o["count"]:
        return [f"{label}: nothing arrived ({_service_note(result, service)})"]
    out = []
    if o["rate_hz"] < GOAL[hz]:
        why = _cpu_per_frame(result, service, o["rate_hz"], GOAL[hz], cores) if label == "gesture hands" else ""
        out.append(f"{label} {o['rate_hz']:.1f} Hz < {GOAL[hz]:g} ({_service_note(result, service)}{why})")
    if p99 is not None and (o["lag_p99_ms"] or 0.0) > GOAL[p99]:
        out.append(f"{label} lag p99 {o['lag_p99_ms']:.0f} ms > {GOAL[p99]:g} ({_service_note(result, service)})")
    first, last = o["lag_p50_first_third_ms"], o["lag_p50_last_third_ms"]
    if first is not None and last is not None and last > GROWS[0] * first + GROWS[1]:
        out.append(
            f"{label} lag grows: p50 {first:.0f} -> {last:.0f} ms over the run ({_service_note(result, service)})"
        )
    return out


def _speech_why(cmds: dict[str, Any]) -> str:
    """Where a spoken command's time goes: speech's part (the end-of-utterance silence it keeps, then decoding) and
    fusion's (its window closes `window_after` after words that look at something, then it waits for the video
    services to pass it)."""
    heard, fused = cmds.get("last_word_to_transcript_p50_ms"), cmds.get("transcript_to_command_p50_ms")
    if heard is None or fused is None:
        return ""
    from services.fusion.core import Config as FusionConfig
    from services.speech.vad import VadConfig

    silence, after = 1000 * VadConfig.min_silence, 1000 * FusionConfig().window_after
    return (
        f"; speech: the transcript p50 {heard:.0f} ms after the last word ({silence:.0f} ms of it the "
        f"end-of-utterance silence it keeps, the rest decoding and queueing); fusion: p50 {fused:.0f} ms from the "
        f"transcript to the command (a window ends {after:.0f} ms after words that look at something, then fusion "
        "waits for vision and gesture samples past it)"
    )


def goal_misses(result: dict[str, Any], cores: int) -> list[str]:
    """Each figure of one run that misses issue #42's goal, with the service behind it; [] when it is met.
    Pure: the run's figures in, sentences out."""
    misses = []
    stack_cores = result["services"]["total_cpu_cores"]
    allowed = GOAL["stack_cores_of_2"] * cores / 2
    if stack_cores > allowed:
        busiest = max(SERVICES, key=lambda n: result["services"].get(n, {}).get("cpu_share_of_machine", 0.0))
        misses.append(
            f"stack {stack_cores:.2f} of {cores} cores > {allowed:g} (the most: {_service_note(result, busiest)})"
        )
    misses += _rate_and_tail(result, "gesture hands", "gesture", "gesture_hz", "gesture_p99_ms", cores)
    misses += _rate_and_tail(result, "vision objects", "vision", "vision_hz", "vision_p99_ms")
    misses += _rate_and_tail(result, "gesture faces", "gesture", "faces_hz", None)
    misses += _rate_and_tail(result, "gesture persons", "gesture", "persons_hz", None)
    cmds = result["commands"]
    p50 = cmds["last_word_to_command_p50_ms"]
    if p50 is None:
        misses.append("no spoken command came through (speech or fusion: see the services' log)")
    elif p50 > GOAL["last_word_to_command_p50_ms"]:
        misses.append(
            f"last word -> command p50 {p50:.0f} ms > {GOAL['last_word_to_command_p50_ms']:g} "
            f"({_service_note(result, 'speech')}{_speech_why(cmds)})"
        )
    if cmds["emitted_without_speech"]:
        misses.append(f"{cmds['emitted_without_speech']} command(s) nobody gave")
    return misses


def goal_row(r: dict[str, Any]) -> str:
    """One run's figures of the goal, in print_goal's columns."""
    o = r["outputs"]

    def hz(label: str) -> str:
        return f"{o[label]['rate_hz']:.1f}" if label in o else "-"

    def tail(label: str) -> str:
        return f"{hz(label)}/{_ms(o[label]['lag_p99_ms'])}" if label in o else "-"

    cmds = r["commands"]
    load = "/".join(f"{v:.1f}" for v in r.get("load_average", []))
    return (
        f"{r['label'][:34]:34s} {load:>9s} {r['services']['total_cpu_cores']:5.2f} {tail('gesture hands'):>13s} "
        f"{tail('vision objects'):>14s} {hz('gesture faces'):>5s} {hz('gesture persons'):>5s} "
        f"{_ms(cmds['last_word_to_command_p50_ms']):>7s} {cmds['emitted_without_speech']:>7d}"
    )


def print_goal(results: list[dict[str, Any]], cores: int) -> None:
    """One line per run against the goal, then what misses it."""
    print(f"\n== against issue #42's goal ({cores} cores; figures from a loaded machine say nothing of it)")
    print(
        f"{'run':34s} {'load':>9s} {'cores':>5s} {'hands Hz/p99':>13s} {'vision Hz/p99':>14s} "
        f"{'faces':>5s} {'pers.':>5s} {'lw->cmd':>7s} {'unasked':>7s}"
    )
    for r in results:
        print(goal_row(r))
        misses = goal_misses(r, cores)
        for m in misses:
            print(f"    misses: {m}")
        if not misses:
            loaded = r.get("load_average", [0.0])[0] > 0.5 * cores
            print("    meets the goal" + (" (on a loaded machine: measure again on a quiet one)" if loaded else ""))


# ---- report -----------------------------------------------------------------------------------------------------


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.0f}"


def print_run(result: dict[str, Any], cores: int) -> None:
    print(f"\n== {result['label']} ({result['seconds']:.0f} s, flags {' '.join(result['extra_flags']) or 'none'})")
    services = result["services"]
    print(f"{'service':8s} {'CPU % of machine':>16s} {'received':>9s} {'published':>9s} {'skipped':>8s}")
    for name in ("router", *SERVICES):
        s = services.get(name)
        if s:
            print(
                f"{name:8s} {100 * s['cpu_share_of_machine']:16.1f} {s.get('received', '-'):>9} "
                f"{s.get('published', '-'):>9} {s.get('skipped', '-'):>8}"
            )
    print(f"whole stack: {services['total_cpu_cores']:.2f} of {cores} cores")
    print(f"fusion's clocks: {services.get('fusion', {}).get('clocks', {})}")
    print(f"{'output':18s} {'count':>6s} {'Hz':>6s} {'p50 ms':>7s} {'p99 ms':>7s} {'p50 1st/3rd third':>18s}")
    for label, o in result["outputs"].items():
        print(
            f"{label:18s} {o['count']:6d} {o['rate_hz']:6.1f} {_ms(o['lag_p50_ms']):>7s} {_ms(o['lag_p99_ms']):>7s} "
            f"{_ms(o['lag_p50_first_third_ms']):>8s}/{_ms(o['lag_p50_last_third_ms'])}"
        )
    cmds = result["commands"]
    print(f"spoken commands: {len(cmds['spoken'])} ({', '.join(cmds['spoken'])})")
    for c in cmds["emitted"]:
        lat = c.get("last_word_to_command_ms")
        given = ""
        if "given" in c:
            at = "?" if c["clip_s"] is None else f"{c['clip_s']:.2f} s"
            given = f" at clip {at}: {'given (labelled)' if c['given'] else 'nobody gave'}"
        print(
            f"  emitted {c['intent']:10s} text={c['text']!r} gesture={c['gesture']} last word->command {_ms(lat)} ms"
            + given
        )
    print(
        f"last word -> command p50 {_ms(cmds['last_word_to_command_p50_ms'])} ms, max "
        f"{_ms(cmds['last_word_to_command_max_ms'])} ms; commands nobody gave: {cmds['emitted_without_speech']}; "
        f"gesture commands inside the clip's labelled gestures: {cmds.get('gestures_given', 0)}"
    )


def variant(text: str) -> tuple[str, list[str]]:
    """'LABEL=FLAG FLAG ...' (--variant) -> (label, `hri up` flags)."""
    label, sep, flags = text.partition("=")
    if not sep or not label.strip():
        raise argparse.ArgumentTypeError(f"--variant wants LABEL=FLAGS, got {text!r}")
    return label.strip(), flags.split()


def planned_runs(
    compare: bool, speech_alone: bool, rounds: int, variants: list[tuple[str, list[str]]] | None = None
) -> list[tuple[str, list[str]]]:
    """The runs, alternated round by round (before, the variants, as shipped, speech alone, then again) so that a
    machine whose load drifts does not favour whichever ran first."""
    one: list[tuple[str, list[str]]] = [("before", BEFORE_ARGS)] if compare else []
    one += variants or []
    one.append(("as shipped", []))
    if speech_alone:  # the control: the same audio with no video flowing, on the same machine
        one.append(("speech alone", [f"--no-{s}" for s in ("camera", "vision", "gesture")]))
    if rounds == 1:
        return one
    return [(f"{label} #{r + 1}", flags) for r in range(rounds) for label, flags in one]


def chosen_scenes(names: list[str], clip: Path | None) -> list[Scene]:
    """The scenes asked for (`--scene`, all of SCENES by default), or the one `--clip` (with its .wav)."""
    if clip is not None:
        return [Scene(clip.stem, str(clip), str(clip.with_suffix(".wav")), str(clip))]
    if not names:
        return list(SCENES)
    known = {sc.name: sc for sc in SCENES}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise SystemExit(f"unknown scene(s) {unknown}; the scenes: {', '.join(known)}")
    return [known[n] for n in names]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0, help="measured window per run (default 60)")
    ap.add_argument(
        "--scene",
        action="append",
        default=[],
        metavar="NAME",
        help=f"a scene to run, repeatable (default: all): {'; '.join(sc.name for sc in SCENES)}",
    )
    ap.add_argument("--clip", type=Path, default=None, help="run this video (with a .wav beside it) as the scene")
    ap.add_argument("--model", type=Path, default=DEFAULT_MODEL, help="ONNX detector for vision")
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--size", default="640x480", help="camera --size (frames fitted inside); '' for the clip's own")
    ap.add_argument("--commands", type=int, default=5, help="spoken commands put into the audio")
    ap.add_argument("--compare", action="store_true", help="run the 'before' knobs first, then as shipped")
    ap.add_argument(
        "--speech-alone", action="store_true", help="also run router, speech and fusion alone (the control)"
    )
    ap.add_argument("--rounds", type=int, default=1, help="repeat the set of runs, alternating (default 1)")
    ap.add_argument("--up-arg", action="append", default=[], metavar="ARG", help="one more `hri up` flag")
    ap.add_argument(
        "--variant",
        action="append",
        type=variant,
        default=[],
        metavar="LABEL=FLAGS",
        help="one more run before 'as shipped' with these `hri up` flags (space-separated), repeatable: e.g. "
        "'faces every frame=--gesture-arg=--faces-max-rate=0'",
    )
    ap.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = ap.parse_args()
    scenes = chosen_scenes(args.scene, args.clip)
    absent = {sc.name: missing_material(sc) for sc in scenes if missing_material(sc)}
    if not args.model.exists() or absent:
        print(f"skipped: needs {args.model} and the scenes' material under {SHARED} (set HRI_SHARED): {absent}")
        return
    cores = os.cpu_count() or 1
    print(f"machine: {cores} cores; load average {os.getloadavg()}", flush=True)
    results = []
    with tempfile.TemporaryDirectory(prefix="hri-stack-bench-") as tmp:
        audios: dict[str, Audio] = {}
        for scene in scenes:
            if scene.audio not in audios:
                folder = Path(tmp) / f"audio{len(audios)}"
                folder.mkdir()
                audios[scene.audio] = build_audio(SHARED / scene.audio, args.seconds, args.commands, folder)
            audio = audios[scene.audio]
            source = scene_source(scene, Path(tmp), args.fps)
            print(f"scene {scene.name!r} ({scene.what}): {source}", flush=True)
            print(f"audio: {audio.seconds:.0f} s; commands at {[round(s.at, 1) for s in audio.spoken]} s", flush=True)
            for label, flags in planned_runs(args.compare, args.speech_alone, args.rounds, args.variant):
                cfg = RunConfig(
                    source,
                    args.model,
                    audio,
                    args.seconds,
                    args.fps,
                    [*flags, *args.up_arg],
                    f"{scene.name}: {label}" if len(scenes) > 1 else label,
                    args.size or None,
                    scene.name,
                )
                results.append(run_stack(cfg))
    for result in results:
        print_run(result, cores)
    print_goal(results, cores)
    report = {"machine": {"cores": cores, "loadavg_after": os.getloadavg()}, "runs": [asdict_safe(r) for r in results]}
    if args.json:
        args.json.write_text(json.dumps(report, indent=1))
        print(f"figures written to {args.json}")


def asdict_safe(result: dict[str, Any]) -> dict[str, Any]:
    return json.loads(json.dumps(result, default=lambda o: asdict(o) if hasattr(o, "__dataclass_fields__") else str(o)))


if __name__ == "__main__":
    main()

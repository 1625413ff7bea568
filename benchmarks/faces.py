"""Who is speaking (issue #33): the face stage's cost beside bare MediaPipe Face Mesh, attribution's added latency,
and how many utterances of the real talking clips are attributed right / unknown / wrong.

1. Cost per frame on the frames of every clip of ../shared/data/talking (decoded once, before timing; a fresh
   graph per clip, video mode, as the gesture service runs it): bare `FaceMesh.process` on the RGB image vs the
   face stage (`FaceStage.process`: the same call, plus landmarks to pixels, tracking, mouth and head angles).
   CPU time of the process (all its threads: MediaPipe's graph runs in its own), so that the load of other
   processes on a shared machine weighs less than in wall time. Runs alternate clip by clip, median of each.
   Target: face stage >= 0.9x the bare frames/s.
2. Attribution's added latency from the last word to the command: fusion in process deciding the same utterances
   (a command said in each labelled speech interval, over a scene of two cups) with the clip's faces buffered vs
   without faces; the time of the `tick` that publishes the command, p50/p99 of each, and of `attribute` alone.
   Goal: under 50 ms added at p50.
3. Accuracy on all 11 clips, utterances as the speech service finds them (Silero VAD over the clip's WAV, as
   `hri-speech` segments it) and as labelled (talking.json): right / unknown / wrong against the labelled speaker
   of the speech the utterance overlaps most; "wrong" includes attributing to a person who was silent.

Usage: python benchmarks/faces.py [--repeats 5] [--no-speed] [--no-accuracy]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from common.schema import Faces  # noqa: E402
from services.fusion.core import Config, FusionCore  # noqa: E402
from services.fusion.speaker import attribute  # noqa: E402
from services.gesture.faces import MESH_MIN_CONFIDENCE, FaceConfig, FaceStage  # noqa: E402
from testkit.frames import read_frames  # noqa: E402
from testkit.scenarios import say, scene  # noqa: E402
from testkit.scenarios.suite import TWO_CUPS  # noqa: E402
from testkit.shared import shared_dir  # noqa: E402
from testkit.talking import T0, TALKING, Utterance, extract, person_of_face, talking_json, transcript_of, utterances  # noqa: E402


def bare_run(clips: list[list[np.ndarray]], max_faces: int) -> float:
    from mediapipe.python.solutions import face_mesh

    n, spent = 0, 0.0
    for frames in clips:
        mesh = face_mesh.FaceMesh(
            static_image_mode=False,
            max_num_faces=max_faces,
            refine_landmarks=False,
            min_detection_confidence=MESH_MIN_CONFIDENCE,
            min_tracking_confidence=MESH_MIN_CONFIDENCE,
        )
        t = time.process_time()
        for img in frames:
            mesh.process(cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
        spent += time.process_time() - t
        n += len(frames)
        mesh.close()
    return spent / n


def stage_run(clips: list[list[np.ndarray]], cfg: FaceConfig) -> float:
    n, spent = 0, 0.0
    for frames in clips:
        stage = FaceStage(cfg)
        t = time.process_time()
        for i, img in enumerate(frames):
            stage.process(img, 1.0 + i / 25.0)
        spent += time.process_time() - t
        n += len(frames)
        stage.close()
    return spent / n


def speed(names: list[str], repeats: int) -> None:
    """Bare and face stage alternate clip by clip (the machine's load hits both alike); per-run medians."""
    clips = [read_frames(shared_dir() / TALKING / name, 10**6) for name in names]
    cfg = FaceConfig()
    frames = sum(len(c) for c in clips)
    bare: list[float] = []
    ours: list[float] = []
    for _ in range(repeats):
        b = o = 0.0
        for frames_of_clip in clips:
            b += bare_run([frames_of_clip], cfg.max_faces) * len(frames_of_clip)
            o += stage_run([frames_of_clip], cfg) * len(frames_of_clip)
        bare.append(b / frames)
        ours.append(o / frames)
    b, o = statistics.median(bare), statistics.median(ours)
    ratios = ", ".join(f"{x / y:.2f}" for x, y in zip(bare, ours))
    print(f"1. cost per frame, {frames} frames of {len(clips)} clips, {repeats} runs alternating clip by clip (median)")
    print(f"   bare FaceMesh.process       {b * 1000:6.2f} ms CPU/frame  {1 / b:6.1f} frames/CPU-s")
    print(
        f"   face stage (FaceStage)      {o * 1000:6.2f} ms CPU/frame  {1 / o:6.1f} frames/CPU-s  = {b / o:.2f}x bare"
    )
    print(f"   per run: {ratios}x")


@dataclass
class Case:
    clip: dict
    faces: list[Faces]
    utterance: Utterance


def fusion_latency(cases: list[Case]) -> None:
    """Per utterance: the tick that decides it, with its clip's faces buffered and without."""
    with_faces: list[float] = []
    without: list[float] = []
    alone: list[float] = []
    for case in cases:
        u = case.utterance
        for feed_faces, sink in ((True, with_faces), (False, without)):
            core = FusionCore(Config(), "fusion/bench")
            core.on_liveliness("vision", "bench", True)
            wall = 1000.0
            if feed_faces:
                for f in case.faces:
                    core.on_faces("hri/gesture/cam0/faces", f, wall)
            for step in scene(TWO_CUPS, 0.0, case.clip["duration_s"], 0.2):
                key, det = step.build(T0)
                core.on_detections(key, det, wall)  # type: ignore[arg-type]
            key, t = say(u.start, u.end, "pick up the red cup").build(T0)
            core.on_transcript(key, t, wall)  # type: ignore[arg-type]
            start = time.perf_counter()
            out = core.tick(wall + 10.0)  # the window is due: this tick decides and builds the command
            sink.append(time.perf_counter() - start)
            assert len(out) == 1
        t = transcript_of(u)
        start = time.perf_counter()
        attribute(t, [f for f in case.faces if t.start - 1.1 <= f.stamp <= t.end + 1.1])
        alone.append(time.perf_counter() - start)

    def pct(xs: list[float]) -> str:
        xs = sorted(xs)
        p99 = xs[min(len(xs) - 1, int(0.99 * len(xs)))]
        return f"p50 {statistics.median(xs) * 1000:6.2f} ms  p99 {p99 * 1000:6.2f} ms"

    added = [a - b for a, b in zip(with_faces, without)]
    print(f"2. fusion's decision of {len(cases)} utterances (in process), last word -> command")
    print(f"   without faces               {pct(without)}")
    print(f"   with the clip's faces       {pct(with_faces)}")
    print(f"   added by attribution        {pct(added)}   (goal p50 < 50 ms)")
    print(f"   attribute() alone           {pct(alone)}")


def vad_utterances(wav: Path) -> list[tuple[float, float]]:
    """(start, end) s of every utterance the speech service's VAD finds in `wav` (speech_start..speech_end)."""
    from services.speech.audio import read_wav
    from services.speech.vad import RATE, make_segmenter

    audio = read_wav(wav)
    samples = audio.samples.astype(np.float32)
    if audio.rate != RATE:
        raise SystemExit(f"{wav}: {audio.rate} Hz, expected {RATE}")
    seg = make_segmenter()
    found = seg.feed(samples) + seg.flush()
    return [(u.speech_start / RATE, u.speech_end / RATE) for u in found]


def verdict(speaker_label: str | None, truth: str | None) -> str:
    if speaker_label is None:
        return "unknown"
    return "right" if speaker_label == truth else "wrong"


def accuracy(meta: list[dict], faces: dict[str, list[Faces]]) -> None:
    print("3. accuracy on every utterance of the 11 clips (right / unknown / wrong)")
    totals: dict[str, Counter] = {"labelled": Counter(), "vad": Counter()}
    for clip in meta:
        samples = faces[clip["clip"]]
        mapping = person_of_face(clip, samples)
        labelled = [(u.start, u.end) for u in utterances(clip)]
        vad = vad_utterances(shared_dir() / TALKING / clip["wav"])
        for kind, spans in (("labelled", labelled), ("vad", vad)):
            row = []
            for start, end in spans:
                truth = best_overlap(clip, start, end)
                t = transcript_of(Utterance(clip["clip"], start, end, truth or "", "x"))
                sp = attribute(t, samples)
                v = verdict(mapping.get(sp.person) if sp.person else None, truth)
                totals[kind][v] += 1
                row.append(f"{start:.2f}-{end:.2f} {truth}->{mapping.get(sp.person or '', '?')} {v}")
            print(f"   {kind:8} {clip['clip']:36} " + "; ".join(row))
    for kind, c in totals.items():
        print(f"   {kind:8} total {sum(c.values())}: right {c['right']}, unknown {c['unknown']}, wrong {c['wrong']}")


def best_overlap(clip: dict, start: float, end: float) -> str | None:
    best, label = 0.0, None
    for s in clip["speech"]:
        overlap = min(end, s["end"]) - max(start, s["start"])
        if overlap > best:
            best, label = overlap, s["speaker"]
    return label


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-speed", action="store_true")
    ap.add_argument("--no-accuracy", action="store_true")
    args = ap.parse_args()
    if not (shared_dir() / TALKING / "talking.json").exists():
        raise SystemExit(f"{shared_dir() / TALKING} not found: set HRI_SHARED to the shared/ folder")
    meta = talking_json()["clips"]
    names = [c["clip"] for c in meta]
    if not args.no_speed:
        speed(names, args.repeats)
    faces = {name: extract(shared_dir() / TALKING / name) for name in names}
    cases = [Case(c, faces[c["clip"]], u) for c in meta for u in utterances(c)]
    fusion_latency(cases)
    if not args.no_accuracy:
        accuracy(meta, faces)


if __name__ == "__main__":
    main()

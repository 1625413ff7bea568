"""The talking clips of ../shared/data/talking/ (real people speaking, `talking.json` says who speaks when) run
through the face stage: each clip's `Faces` samples in source time (the frame index over the clip's fps), and
the labelled speech intervals as utterances.

`python -m testkit.talking --write` recomputes the face series of all clips into tests/data/talking_faces.json
(numbers derived by our face stage: mouth opening, head angles, boxes; no pixels), so the attribution tests run
without ../shared/; tests/test_speaker.py checks the cache against a fresh run of the face stage when the clips
are there.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path

import msgspec
import numpy as np

from common.schema import Faces, Transcript, Word
from testkit.shared import ROOT, shared_dir

CACHE = ROOT / "tests" / "data" / "talking_faces.json"
TALKING = "data/talking"
T0 = 1000.0  # source time of each clip's first frame and audio sample (stamps must be > 0)


@dataclass(frozen=True)
class Utterance:
    """One labelled speech interval of a clip: who said it (the clip's P0, P1…; P0 is leftmost)."""

    clip: str
    start: float
    end: float
    speaker: str
    text: str


def talking_json(root: Path | None = None) -> dict:
    base = (root or shared_dir()) / TALKING
    return json.loads((base / "talking.json").read_text())


def utterances(clip: dict) -> list[Utterance]:
    return [
        Utterance(clip["clip"], s["start"], s["end"], s["speaker"], s.get("transcript", "")) for s in clip["speech"]
    ]


def transcript_of(u: Utterance, source: str = "test/speech") -> Transcript:
    """A Transcript spanning the labelled interval, in the clip's source time (no word times: labels have none)."""
    return Transcript(
        stamp=T0 + u.end,
        source=source,
        mic="default",
        start=T0 + u.start,
        end=T0 + u.end,
        text=u.text or "(speech)",
        confidence=0.9,
        words=list[Word](),
        final=True,
        backend="label",
    )


def extract(video: Path, source: str = "test/gesture") -> list[Faces]:
    """Run the face stage over every frame of `video` (stamps: T0 + frame index / the file's fps)."""
    import cv2

    from services.gesture.faces import FaceConfig, FaceStage

    cap = cv2.VideoCapture(str(video))
    fps = cap.get(cv2.CAP_PROP_FPS) or 25.0
    stage = FaceStage(FaceConfig())
    out: list[Faces] = []
    try:
        seq = 0
        while True:
            ok, img = cap.read()
            if not ok:
                break
            stamp = round(T0 + seq / fps, 4)
            faces = stage.process(img, stamp)
            h, w = img.shape[:2]
            out.append(Faces(stamp=stamp, source=source, seq=seq, cam="cam0", width=w, height=h, faces=faces))
            seq += 1
    finally:
        stage.close()
        cap.release()
    return out


def person_of_face(clip: dict, faces: list[Faces]) -> dict[str, str]:
    """Face track id -> the clip's person label (P0, P1, …), by the label's face box centre nearest the track's."""
    people = [(p["id"], p["face_boxes"][0]["box"][0] + p["face_boxes"][0]["box"][2] / 2) for p in clip["people"]]
    mapping: dict[str, str] = {}
    for sample in faces:
        for f in sample.faces:
            if f.id not in mapping:
                cx = f.bbox[0] + f.bbox[2] / 2
                mapping[f.id] = min(people, key=lambda p: abs(p[1] - cx))[0]
    return mapping


FACE_FIELDS = ("id", "bbox", "mouth_open", "yaw", "pitch", "looking_at_camera", "score")


def _compact(samples: list[Faces]) -> dict:
    """One row per frame: [stamp, seq, [[face fields in FACE_FIELDS order], ...]] (the cache stays small)."""
    first = samples[0]
    return {
        "width": first.width,
        "height": first.height,
        "frames": [[s.stamp, s.seq, [[getattr(f, k) for k in FACE_FIELDS] for f in s.faces]] for s in samples],
    }


def _expand(clip: dict, source: str = "test/gesture") -> list[Faces]:
    return [
        msgspec.convert(
            {
                "stamp": stamp,
                "source": source,
                "seq": seq,
                "cam": "cam0",
                "width": clip["width"],
                "height": clip["height"],
                "faces": [dict(zip(FACE_FIELDS, row)) for row in rows],
            },
            Faces,
        )
        for stamp, seq, rows in clip["frames"]
    ]


def load_cache(path: Path = CACHE) -> dict[str, list[Faces]]:
    raw = json.loads(path.read_text())
    return {name: _expand(clip) for name, clip in raw["clips"].items()}


def write_cache(path: Path = CACHE) -> None:
    meta = talking_json()
    clips = {c["clip"]: _compact(extract(shared_dir() / TALKING / c["clip"])) for c in meta["clips"]}
    doc = {
        "about": "Faces (mouth opening, head angles, boxes) of every frame of ../shared/data/talking/* computed by "
        "services/gesture/faces.py; regenerate with `python -m testkit.talking --write`",
        "clips": clips,
    }
    path.write_text(json.dumps(doc, separators=(",", ":")) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--write", action="store_true", help=f"recompute {CACHE.relative_to(ROOT)}")
    args = parser.parse_args()
    if args.write:
        write_cache()
        print(f"wrote {CACHE} ({CACHE.stat().st_size} bytes)")


if __name__ == "__main__":
    main()


def spoken_commands(clip: dict, commands: list[str], out: Path) -> Path:
    """A 16 kHz WAV as long as `clip` with `commands[i]` said by the piper voice in the clip's i-th labelled
    speech interval (stretched to fill it), silence elsewhere. The mouths and the timing stay the real clip's;
    only the words are synthetic (GRID's sentences are not commands, so fusion would publish nothing for them)."""
    from testkit.synth import PIPER_VOICE, RATE, read_wav_int16, synthesize, write_wav_int16

    track = np.zeros(int(round(clip["duration_s"] * RATE)), dtype=np.int16)
    for u, text in zip(utterances(clip), commands):
        natural = _voiced(read_wav_int16(synthesize(text, out, voice=PIPER_VOICE, lead_silence=0, trail_silence=0)))
        speed = 150.0 * len(natural) / RATE / (u.end - u.start)  # piper's pace scaled to fill the interval
        voiced = _voiced(
            read_wav_int16(
                synthesize(text, out, voice=PIPER_VOICE, speed=int(round(speed)), lead_silence=0, trail_silence=0)
            )
        )
        start = int(round(u.start * RATE))
        voiced = voiced[: len(track) - start]
        track[start : start + len(voiced)] = voiced
    write_wav_int16(out, track)
    return out


def _voiced(samples: np.ndarray) -> np.ndarray:
    """`samples` without the silence before the first and after the last loud 10 ms."""
    frames = len(samples) // 160
    loud = [i for i in range(frames) if np.abs(samples[i * 160 : (i + 1) * 160]).max() > 500]
    return samples[loud[0] * 160 : (loud[-1] + 1) * 160] if loud else samples

"""Who is speaking and to whom (issue #40): speaker and addressee on the real talking clips, with the sound and
without it, development and held-back clips apart; engagement on the photos of several people.

1. Speaker, on every utterance of the 11 clips of ../shared/data/talking, twice: as labelled (talking.json, 15)
   and as the speech service's VAD finds them in each clip's WAV (Silero, as `hri-speech` segments it, 16). The
   faces come from the face stage run on each video (Face Mesh, as the gesture service runs it); the loudness
   from the WAV through the speech service's own function (services/speech/loudness.py; for the VAD's utterances
   over the audio the VAD cut, padding included, as the service publishes it). Each utterance: right / unknown /
   wrong against the labelled speaker of the speech it overlaps most, and "silent" when the person named moved
   their lips without the audio (the dub clips) — never acceptable. With the sound (`Transcript.loudness`) and
   without it (timing of mouth motion alone, as before issue #40).
2. Addressee: every utterance whose speaker is found, `Speaker.addressed` against the label (every face of these
   clips looks at the camera: all addressed).
3. Engagement on ../shared/data/people_multi: each face the face stage finds, held as a 2 s still, engaged or not
   against the label (turned away vs looking at the camera).
4. attribute()'s time per utterance with and without the sound (p50; the machine is shared, see the docs).

The held-back clips (BRIEF: talking/comp_dub_brbk7n_lbax4n_audioR, comp_turns_lbax4n_sbwe5n, real_single_vr5) are
counted apart; no setting was chosen on them.

Usage: python benchmarks/speaker.py [--cached]   (--cached: the recorded face series, tests/data/talking_faces.json)
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
import wave
from collections import Counter
from pathlib import Path

import msgspec
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from common.engagement import engaged_over  # noqa: E402
from common.schema import Faces, Loudness, Transcript  # noqa: E402
from services.fusion.speaker import attribute  # noqa: E402
from services.speech.audio import pcm_to_mono  # noqa: E402
from services.speech.loudness import loudness_of  # noqa: E402
from testkit.shared import shared_dir  # noqa: E402
from testkit.talking import T0, TALKING, Utterance, extract, load_cache, person_of_face, talking_json, transcript_of  # noqa: E402

HELD_BACK = {"comp_dub_brbk7n_lbax4n_audioR.mp4", "comp_turns_lbax4n_sbwe5n.mp4", "real_single_vr5.mp4"}


def wav_audio(path: Path) -> tuple[np.ndarray, int]:
    with wave.open(str(path)) as w:
        return pcm_to_mono(w.readframes(w.getnframes()), w.getnchannels()), w.getframerate()


def vad_utterances(audio: np.ndarray, rate: int) -> list[tuple[float, float, Loudness]]:
    """(start, end, loudness) of each utterance the speech service's VAD finds, in the clips' source time."""
    from services.speech.vad import RATE, make_segmenter

    if rate != RATE:
        raise SystemExit(f"{rate} Hz, expected {RATE}")
    seg = make_segmenter()
    found = seg.feed(audio.astype(np.float32)) + seg.flush()
    return [
        (u.speech_start / RATE, u.speech_end / RATE, loudness_of(u.audio, RATE, T0 + u.audio_start / RATE))
        for u in found
    ]


def best_overlap(clip: dict, start: float, end: float) -> str | None:
    best, label = 0.0, None
    for s in clip["speech"]:
        overlap = min(end, s["end"]) - max(start, s["start"])
        if overlap > best:
            best, label = overlap, s["speaker"]
    return label


def verdict(named: str | None, truth: str | None, silent: set[str]) -> str:
    if named is None:
        return "unknown"
    if named in silent:
        return "silent"
    return "right" if named == truth else "wrong"


def spans_of(clip: dict, audio: np.ndarray, rate: int) -> dict[str, list[tuple[float, float, Loudness]]]:
    whole = loudness_of(audio, rate, T0)
    return {
        "labelled": [(s["start"], s["end"], whole) for s in clip["speech"]],
        "vad": vad_utterances(audio, rate),
    }


def speaker_and_addressee(meta: list[dict], faces: dict[str, list[Faces]]) -> list[float]:
    """Sections 1 and 2; returns attribute()'s times with the sound (s) for section 4."""
    tally: dict[tuple[str, str, str], Counter] = {}
    times: list[float] = []
    print("1. speaker, 2. addressee: per utterance  truth -> named with the sound [without] (addressed)")
    for clip in meta:
        samples = faces[clip["clip"]]
        mapping = person_of_face(clip, samples)
        silent = {m["person"] for m in clip.get("mouthing_without_audio", [])}
        split = "held back" if clip["clip"] in HELD_BACK else "dev"
        audio, rate = wav_audio(shared_dir() / TALKING / clip["wav"])
        for kind, spans in spans_of(clip, audio, rate).items():
            row = []
            for start, end, loud in spans:
                truth = best_overlap(clip, start, end)
                blind: Transcript = transcript_of(Utterance(clip["clip"], start, end, truth or "", "x"))
                heard = msgspec.structs.replace(blind, loudness=loud)
                t = time.perf_counter()
                with_sound = attribute(heard, samples)
                times.append(time.perf_counter() - t)
                without = attribute(blind, samples)
                for mode, sp in (("sound", with_sound), ("timing", without)):
                    named = mapping.get(sp.person) if sp.person else None
                    c = tally.setdefault((kind, split, mode), Counter())
                    c[verdict(named, truth, silent)] += 1
                    if mode == "sound" and sp.person is not None:
                        c["addressed" if sp.addressed else "not addressed"] += 1
                named_now = mapping.get(with_sound.person or "", "?")
                named_before = mapping.get(without.person or "", "?")
                row.append(f"{start:.2f}-{end:.2f} {truth}->{named_now} [{named_before}] ({with_sound.addressed})")
            print(f"   {kind:8} {split:9} {clip['clip']:36} " + "; ".join(row))
    print("   totals (right / unknown / wrong / silent person named; addressed of those named, all should be):")
    for (kind, split, mode), c in sorted(tally.items()):
        n = sum(c[k] for k in ("right", "unknown", "wrong", "silent"))
        addressed = f"  addressed {c['addressed']}/{c['addressed'] + c['not addressed']}" if mode == "sound" else ""
        print(
            f"   {kind:8} {split:9} {mode:6} {n:2} utterances: right {c['right']}, unknown {c['unknown']}, "
            f"wrong {c['wrong']}, silent {c['silent']}{addressed}"
        )
    return times


def engagement_on_photos() -> None:
    import cv2

    from services.gesture.faces import FaceConfig, FaceStage

    folder = shared_dir() / "data/people_multi"
    labels = json.loads((folder / "people_multi.json").read_text())
    right = total = 0
    rows = []
    for image in labels["images"]:
        img = cv2.imread(str(folder / image["file"]))
        if img is None:
            continue
        stage = FaceStage(FaceConfig(), video=False)
        found = stage.process(img, 1.0)
        stage.close()
        for f in found:
            cx = f.bbox[0] + f.bbox[2] / 2
            person = next(
                (
                    p
                    for p in image["people"]
                    if p["head_box"] and abs(cx - p["head_box"][0] - p["head_box"][2] / 2) < p["head_box"][2] / 2
                ),
                None,
            )
            if person is None:
                continue
            h, w = img.shape[:2]
            still = [
                Faces(stamp=1.0 + k * 0.1, source="bench", seq=k, cam="cam0", width=w, height=h, faces=[f])
                for k in range(21)
            ]
            e = engaged_over(still, f.id, 1.0, 3.0)
            label = person["faces_camera"]
            looking = label.startswith("yes") and ("eyes on the camera" in label or "frontal" in label)
            expected = True if looking else False if label.startswith("no") else None
            ok = expected is None or e.engaged == expected
            if expected is not None:
                total += 1
                right += ok
            rows.append(f"   {image['file']:36} {person['id']} engaged {e.engaged!s:5} label '{label[:40]}' {e.reason}")
    print("3. engagement on people_multi (each face found, held 2 s)")
    print("\n".join(rows))
    print(f"   right on {right} of {total} faces with a clear label (turned away / looking at the camera)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cached", action="store_true", help="the recorded face series instead of running Face Mesh")
    args = ap.parse_args()
    if not (shared_dir() / TALKING / "talking.json").exists():
        raise SystemExit(f"{shared_dir() / TALKING} not found: set HRI_SHARED to the shared/ folder")
    meta = talking_json()["clips"]
    if args.cached:
        faces = load_cache()
    else:
        faces = {c["clip"]: extract(shared_dir() / TALKING / c["clip"]) for c in meta}
    times = speaker_and_addressee(meta, faces)
    engagement_on_photos()
    print(f"4. attribute() with the sound: p50 {statistics.median(times) * 1000:.2f} ms over {len(times)} utterances")


if __name__ == "__main__":
    main()

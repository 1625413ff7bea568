"""Commands from gestures nobody meant, and spoken commands lost to them (issue #40), on real clips and photos.

Each clip of ../shared/data/intent/ (intent.json) and ../shared/data/talking/ (talking.json) goes through the gesture
core and fusion's core as the services run them (testkit/intent.py), once per frame subset (all frames; every 2nd
from 0 and from 1; 70 % drawn with fixed seeds: the frames a loaded service happens to process), with a spoken
command ("turn left") placed over each labelled stretch of hand movement (intent clips) or speech (talking clips).
Each photo of the photo sets (people/, people_multi/, pointing/) is shown for `PHOTO_S` s at 10 frames/s.

Figures (source time throughout):
- false gesture commands: on clips where nothing is meant (talk, negative, point; the talking clips), every
  stop / come_here; on the deliberate clips, a command of the other kind; per minute of those clips;
- stop latency: the first stop within the labelled stop event minus the event's end (negative: before it ended);
- deliberate missed: a deliberate clip (expect stop or come_here) without that command;
- utterances dropped: placed commands with neither a command nor a question (one placed over a labelled stop is
  meant to be cancelled and is counted apart);
- repeatability: the clips whose gesture commands differ between frame subsets.
Dev and held-back clips (the split of the round's brief) are reported apart.

    .venv/bin/python benchmarks/intent.py                       # this checkout, subsets all and every2+0
    .venv/bin/python benchmarks/intent.py --subsets all,every2+0,every2+1,random70/1,random70/2 --photos
    .venv/bin/python benchmarks/intent.py --before main         # the same run on a worktree of `main` first
    .venv/bin/python benchmarks/intent.py --split held_back      # the held-back clips (measure them only at the end)
Speed: MediaPipe on every frame; about 1-2 min per subset on the loaded 2-core machine.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parent.parent
HELD_BACK = (
    "cat2_kard_two_hand_wave",
    "cat4_tango_speaker8",
    "cat4_tango_un_podium_speech",
    "extra_asl_thanks",
    "comp_dub_brbk7n_lbax4n_audioR",
    "comp_turns_lbax4n_sbwe5n",
    "real_single_vr5",
    "intel_walking_trio_f034",
    "room_pointer_bystander_0219_t21",
    "lowcam_man_image7_right_arm_to_floor",
    "room_woman_0219_t6_left_arm_to_image_right",
)
PHOTO_SETS = ("people", "people_multi", "pointing")
PHOTO_S, PHOTO_FPS = 1.5, 10.0
PLACED = "turn left"
MAX_FRAMES = 700
UTTERANCE_MAX_S = 1.5


def _testkit(code: Path) -> ModuleType:
    """testkit/intent.py of THIS checkout, run against the services of `code` (a checkout of another ref)."""
    sys.path.insert(0, str(code))
    spec = importlib.util.spec_from_file_location("intent_kit", ROOT / "testkit" / "intent.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # (its dataclasses look their module up)
    spec.loader.exec_module(module)
    return module


@dataclass
class ClipResult:
    clip: str
    held_back: bool
    kind: str
    expect: list[str]
    minutes: float
    commands: dict[str, list[tuple[str, float]]] = field(default_factory=dict)  # subset -> (intent, t)
    placed: int = 0
    dropped: dict[str, int] = field(default_factory=dict)  # subset -> placed commands without an answer
    cancelled: dict[str, int] = field(default_factory=dict)  # subset -> placed over a labelled stop, no answer
    stop_event: tuple[float, float] | None = None


def _placed(kit: ModuleType, clip, events: list) -> tuple[list, set[int]]:
    """The commands placed over the clip's labelled movement or speech; the indices of those over a labelled stop."""
    spans = [(s, e) for s, e, _ in clip.utterances] or [(s, e) for s, e, what in events if e - s >= 0.5]
    stops = {i for i, (s, e) in enumerate(spans) if any("stop" in w and s <= ee and ss <= e for ss, ee, w in events)}
    return [kit.transcript(s, min(e, s + UTTERANCE_MAX_S), PLACED) for s, e in spans], stops


def _answered(kit: ModuleType, outputs: list, t) -> bool:
    return any(abs(o.stamp - t.stamp) < 1e-6 and getattr(o, "text", "x") is not None for o in outputs)


def run_clip(kit: ModuleType, settings, shared: Path, clip, events: list, subsets: list[str]) -> ClipResult:
    images, fps = kit.clip_frames(shared / "data" / clip.folder / clip.file, MAX_FRAMES)
    fps = fps if fps > 1 else clip.fps
    held = any(h in clip.file for h in HELD_BACK)
    stop_events: list[tuple[float, float] | None] = [(s, e) for s, e, what in events if "stop" in what]
    result = ClipResult(
        clip.file, held, clip.kind, list(clip.expect), len(images) / fps / 60.0, stop_event=(stop_events or [None])[-1]
    )
    placed, over_stop = _placed(kit, clip, events)
    result.placed = len(placed)
    for kind in subsets:
        samples = kit.gesture_samples(settings, images, fps, kit.subset(len(images), kind))
        outputs = kit.run_fusion(samples, placed)
        result.commands[kind] = kit.gesture_commands(outputs)
        lost = [i for i, t in enumerate(placed) if not _answered(kit, outputs, t)]
        result.dropped[kind] = len([i for i in lost if i not in over_stop])
        result.cancelled[kind] = len([i for i in lost if i in over_stop])
        print(f"  {clip.file} [{kind}]: {result.commands[kind]} dropped {result.dropped[kind]}", file=sys.stderr)
    return result


def run_photos(kit: ModuleType, settings, shared: Path) -> dict[str, dict[str, int]]:
    """Per photo set (people/ by its class prefix): photos, and the stops and calls they gave."""
    import cv2

    out: dict[str, dict[str, int]] = {}
    for folder in PHOTO_SETS:
        for path in sorted((shared / "data" / folder).glob("*.*")):
            if path.suffix.lower() not in (".jpg", ".jpeg", ".png") or any(h in path.name for h in HELD_BACK):
                continue
            img = cv2.imread(str(path))
            if img is None:
                continue
            name = f"{folder}/{path.name.split('_')[0]}" if folder == "people" else folder
            frames = [img] * round(PHOTO_S * PHOTO_FPS)
            commands = kit.gesture_commands(kit.run_fusion(kit.gesture_samples(settings, frames, PHOTO_FPS)))
            row = out.setdefault(name, {"photos": 0, "stop": 0, "come_here": 0})
            row["photos"] += 1
            for intent, _ in commands:
                row[intent] += 1
    return out


def _intents(commands: list[tuple[str, float]]) -> list[str]:
    return [i for i, _ in commands]


def _false(r: ClipResult, commands: list[tuple[str, float]]) -> int:
    meant = {alt for e in r.expect for alt in e.split("|")}
    optional = r.clip.startswith("cat2_webcam")  # "come_here (the waves), or nothing"
    return sum(1 for i in _intents(commands) if i not in meant and not (optional and i == "come_here"))


def _missed(r: ClipResult, commands: list[tuple[str, float]]) -> int:
    return sum(1 for e in r.expect if not set(e.split("|")) & set(_intents(commands)))


def _latency(r: ClipResult, commands: list[tuple[str, float]]) -> float | None:
    if r.stop_event is None:
        return None
    s, e = r.stop_event
    given = [t for i, t in commands if i == "stop" and s <= t <= e + 1.0]
    return round(given[0] - e, 3) if given else None


def summary(results: list[ClipResult], held_back: bool) -> dict:
    rows = [r for r in results if r.held_back == held_back]
    subsets = list(rows[0].commands) if rows else []
    natural = [r for r in rows if not r.expect]
    minutes = sum(r.minutes for r in natural)
    out: dict = {"clips": len(rows), "natural_minutes": round(minutes, 2), "subsets": {}}
    for kind in subsets:
        false = sum(_false(r, r.commands[kind]) for r in rows)
        out["subsets"][kind] = {
            "false_commands": false,
            "false_per_minute": round(false / minutes, 2) if minutes else None,
            "deliberate_missed": sum(_missed(r, r.commands[kind]) for r in rows),
            "deliberate": sum(len(r.expect) for r in rows),
            "stop_latency_s": {r.clip: _latency(r, r.commands[kind]) for r in rows if r.stop_event},
            "placed": sum(r.placed for r in rows),
            "dropped": sum(r.dropped[kind] for r in rows),
            "cancelled_by_labelled_stop": sum(r.cancelled[kind] for r in rows),
        }
    out["differ_between_subsets"] = [r.clip for r in rows if len({tuple(_intents(c)) for c in r.commands.values()}) > 1]
    return out


def measure(code: Path, shared: Path, subsets: list[str], photos: bool, split: str) -> dict:
    kit = _testkit(code)
    from services.gesture.core import GestureSettings  # of `code` (first on the path)

    settings = GestureSettings()
    labels = _labels(shared)
    results = []
    for clip in kit.load_clips(shared):
        held = any(h in clip.file for h in HELD_BACK)
        if split == "none" or (held and split == "dev") or (not held and split == "held_back"):
            continue
        results.append(run_clip(kit, settings, shared, clip, labels.get(clip.file, []), subsets))
    report = {
        "dev": summary(results, False) if split in ("dev", "both") else None,
        "held_back": summary(results, True) if split in ("held_back", "both") else None,
        "clips": [asdict(r) for r in results],
    }
    if photos:
        report["photos"] = run_photos(kit, settings, shared)
    return report


def _labels(shared: Path) -> dict[str, list]:
    path = shared / "data" / "intent" / "intent.json"
    if not path.exists():
        return {}
    return {c["file"]: [tuple(e) for e in c["events"]] for c in json.loads(path.read_text())["clips"]}


def _before(ref: str, argv: list[str]) -> dict:
    """This benchmark on a temporary worktree of `ref` (its services, this checkout's testkit/intent.py)."""
    with tempfile.TemporaryDirectory(prefix="intent-before-") as tmp:
        tree = Path(tmp) / "tree"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), ref], check=True)
        try:
            out = Path(tmp) / "before.json"
            cmd = [sys.executable, str(Path(__file__).resolve()), "--code", str(tree), "--json", str(out), *argv]
            subprocess.run(cmd, check=True)
            return json.loads(out.read_text())
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=True)


def _print(title: str, report: dict) -> Iterator[str]:
    for split in ("dev", "held_back"):
        s = report.get(split)
        if not s:
            continue
        yield f"{title} — {split}: {s['clips']} clips, {s['natural_minutes']} min of natural behaviour"
        for kind, f in s["subsets"].items():
            yield (
                f"  [{kind}] false commands {f['false_commands']} ({f['false_per_minute']}/min), deliberate missed "
                f"{f['deliberate_missed']}/{f['deliberate']}, utterances dropped {f['dropped']}/{f['placed']} "
                f"(+{f['cancelled_by_labelled_stop']} cancelled over a labelled stop), "
                f"stop latency {f['stop_latency_s']}"
            )
        yield f"  differ between subsets: {s['differ_between_subsets'] or 'none'}"
    for name, row in (report.get("photos") or {}).items():
        yield f"  photos {name}: {row}"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    parser.add_argument("--subsets", default="all,every2+0", help="comma-separated: all, every2+0, random70/1, ...")
    parser.add_argument("--photos", action="store_true", help="also the photo sets (people, people_multi, pointing)")
    parser.add_argument(
        "--split",
        choices=("dev", "held_back", "both", "none"),
        default="dev",
        help="which clips (held back: only at the end; none: the photos alone)",
    )
    parser.add_argument("--before", metavar="REF", help="first the same run on a worktree of REF (e.g. main)")
    parser.add_argument("--code", type=Path, default=ROOT, help=argparse.SUPPRESS)
    parser.add_argument("--json", type=Path, help="write the report as JSON here")
    args = parser.parse_args(argv)
    subsets = args.subsets.split(",")
    passed = ["--shared", str(args.shared), "--subsets", args.subsets]
    passed += ["--photos"] * args.photos + ["--split", args.split]
    before = _before(args.before, passed) if args.before else None
    report = measure(args.code, args.shared, subsets, args.photos, args.split)
    if args.json:
        args.json.write_text(json.dumps({"after": report, "before": before}, indent=1) + "\n")
    if before is not None:
        print("\n".join(_print(f"before ({args.before})", before.get("after", before))))
    print("\n".join(_print("after" if before is not None else "this checkout", report)))


if __name__ == "__main__":
    main()

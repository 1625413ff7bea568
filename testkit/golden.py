"""The golden net under fusion: every in-process fusion run's outputs, written out in full and compared byte for byte.

Two files under tests/data/golden/:
- `fusion_synthetic.txt`: the scenario suite (testkit/scenarios/suite.py) and the seeded degraded sweep
  (testkit/scenarios/sweep.py), each with adaptive and with fixed weights. Needs nothing but the project.
- `fusion_real.txt`: the scenes made from real photos (YOLOX-Nano detections, testkit/scenarios/real.py) and the real
  indoor scenes (../shared/data/scenes/, through vision's own pipeline). Needs ../shared/ (the model and the photos).
  The detector's boxes and scores are rounded (to half pixels and hundredths, testkit/golden_detections.py) before
  anything else sees them: onnxruntime's last digits differ between CPUs, the rounded figures do not.

Every published sample (command, question, its explanation, weights, prompt, ids, stamps) is one line of canonical
JSON under its run's header. A refactor must leave both files unchanged; a change of behaviour re-blesses them on
purpose and the diff shows what changed:

    .venv/bin/python -m testkit.golden --bless          # rewrite the files (the real one only with ../shared/)
    .venv/bin/python -m testkit.golden --diff           # print what differs from the committed files

tests/test_golden.py fails on any difference and names the first run that differs and the figure in it.
HRI_ORT_THREADS=1 and HRI_ORT_GRAPH_OPT=off run the detector with other onnxruntime settings: the file stays the same.
"""

from __future__ import annotations

import argparse
import difflib
import json
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterator

if TYPE_CHECKING:
    from testkit.golden_detections import GoldenDetector, OrtSettings

ROOT = Path(__file__).resolve().parent.parent
GOLDEN_DIR = ROOT / "tests" / "data" / "golden"
SYNTHETIC = GOLDEN_DIR / "fusion_synthetic.txt"
REAL = GOLDEN_DIR / "fusion_real.txt"
SWEEP_SEED = 1
SWEEP_TRIALS = 40  # per kind: benchmarks/fusion_eval.py's default
WEIGHTS = ("adaptive", "fixed")


def shared_dir() -> Path:
    return Path(os.environ.get("HRI_SHARED") or ROOT.parent / "shared")


def yolox_model() -> Path:
    return Path(os.environ.get("HRI_YOLOX_MODEL") or shared_dir() / "models" / "yolox_nano.onnx")


def _line(sample: Any) -> str:
    return f"  {type(sample).__name__} " + json.dumps(sample.to_dict(), sort_keys=True, ensure_ascii=False)


def _runs(title: str, scenarios: list[Any]) -> Iterator[str]:
    from services.fusion.core import Config
    from testkit.scenarios import run_in_process

    for mode in WEIGHTS:
        for i, sc in enumerate(scenarios):
            yield f"# {title} [{mode}] {i}: {sc.name}"
            outputs = run_in_process(sc, Config(weights=mode, **sc.config))
            yield from (_line(o) for o in outputs)


def synthetic_lines() -> Iterator[str]:
    from testkit.scenarios.suite import SCENARIOS
    from testkit.scenarios.sweep import degraded_sweep

    yield from _runs("suite", SCENARIOS)
    yield from _runs("sweep", degraded_sweep(SWEEP_SEED, SWEEP_TRIALS))


def real_detectors(ort: OrtSettings | None = None) -> tuple[GoldenDetector, GoldenDetector]:
    """(the real photos' detector, the indoor scenes' detector): rounding, under `ort` (default: from the env)."""
    from testkit.golden_detections import GoldenDetector, OrtSettings
    from testkit.scenarios.real import MIN_SCORE, NMS_IOU

    model, ort = yolox_model(), ort or OrtSettings.from_env()
    return GoldenDetector(model, MIN_SCORE, NMS_IOU, ort), GoldenDetector(model, ort=ort)


def real_lines(detectors: tuple[GoldenDetector, GoldenDetector] | None = None) -> Iterator[str]:
    """The real-photo runs, from the detectors' rounded boxes and scores (`real_detectors()` by default)."""
    from testkit.scenarios.indoor import load_lines, scenario, vision_pipeline
    from testkit.scenarios.real import real_scenarios, yolox_detector

    shared, model = shared_dir(), yolox_model()
    photos_detector, indoor_detector = detectors or real_detectors()

    def photo(name: str) -> Path:
        photos_detector.photo = name
        return ROOT / name[5:] if name.startswith("repo:") else shared / name

    yield from _runs("real photos", real_scenarios(yolox_detector(model, photos_detector), photo))
    folder = shared / "data" / "scenes"
    see = vision_pipeline(model, indoor_detector)
    indoor = []
    for line in load_lines(folder):
        indoor_detector.photo = f"{folder.name}/{line.photo}"
        indoor.append(scenario(line, see(folder / line.photo)))
    yield from _runs("indoor scenes", indoor)


def real_available() -> str:
    """'' when the real scenes can run, else why not."""
    folder = shared_dir() / "data" / "scenes"
    if not yolox_model().is_file():
        return f"no YOLOX-Nano model at {yolox_model()} (set HRI_SHARED or HRI_YOLOX_MODEL)"
    if not (folder / "scenes.json").is_file():
        return f"no {folder / 'scenes.json'} (set HRI_SHARED)"
    return ""


def render(lines: Callable[[], Iterator[str]]) -> str:
    return "\n".join(lines()) + "\n"


def _leaves(value: Any, path: str = "") -> Iterator[tuple[str, Any]]:
    """(path, value) of every figure and string of a decoded sample, in order: `target.bbox[0]`."""
    if isinstance(value, dict):
        for key in sorted(value):
            yield from _leaves(value[key], f"{path}.{key}" if path else key)
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from _leaves(item, f"{path}[{i}]")
    else:
        yield path, value


def differing_figure(expected: str, actual: str) -> str:
    """Which field of two sample lines differs first, with both values ('' when not two samples of one kind)."""
    kind_a, _, json_a = expected.strip().partition(" ")
    kind_b, _, json_b = actual.strip().partition(" ")
    try:
        a, b = dict(_leaves(json.loads(json_a))), dict(_leaves(json.loads(json_b)))
    except ValueError:
        return ""
    if kind_a != kind_b:
        return f"a {kind_b} where the file has a {kind_a}"
    for path in list(a) + [p for p in b if p not in a]:
        if a.get(path, "<absent>") != b.get(path, "<absent>"):
            return f"{kind_a} {path}: {a.get(path, '<absent>')!r} in the file, {b.get(path, '<absent>')!r} now"
    return ""


def first_difference(expected: str, actual: str) -> str:
    """The first differing line with the run it belongs to, the figure that differs, and a short unified diff."""
    exp, act = expected.splitlines(), actual.splitlines()
    header = ""
    for i, (a, b) in enumerate(zip(exp, act)):
        if a.startswith("# "):
            header = a
        if a != b:
            diff = list(difflib.unified_diff(exp[max(0, i - 2) : i + 6], act[max(0, i - 2) : i + 6], lineterm=""))
            figure = differing_figure(a, b)
            return (
                f"first difference at line {i + 1}, in run {header!r}"
                + (f": {figure}" if figure else "")
                + ":\n"
                + "\n".join(diff[:40])
            )
    if len(exp) != len(act):
        return f"the files agree on {min(len(exp), len(act))} lines, then one has {abs(len(exp) - len(act))} more"
    return ""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--bless", action="store_true", help="rewrite the golden files from the code as it is")
    what.add_argument("--diff", action="store_true", help="print the first difference of each file")
    args = parser.parse_args(argv)
    jobs: list[tuple[Path, Callable[[], Iterator[str]]]] = [(SYNTHETIC, synthetic_lines)]
    why_not = real_available()
    if why_not:
        print(f"golden: {REAL.name} left as it is: {why_not}", file=sys.stderr)
    else:
        from testkit.golden_detections import OrtSettings

        jobs.append((REAL, real_lines))
        print(f"golden: onnxruntime with {OrtSettings.from_env()}", file=sys.stderr)
    status = 0
    for path, lines in jobs:
        print(f"golden: running {path.name} …", file=sys.stderr)
        text = render(lines)
        if args.bless:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
            print(f"golden: wrote {path} ({text.count(chr(10))} lines)", file=sys.stderr)
        else:
            old = path.read_text(encoding="utf-8") if path.is_file() else ""
            diff = first_difference(old, text)
            print(f"{path.name}: {diff or 'unchanged'}")
            status |= bool(diff)
    return status


if __name__ == "__main__":
    sys.exit(main())

"""Fixed vs adaptive modality weights: accuracy side by side.

Runs (in process, deterministic) the scenario suite of testkit/scenarios plus the seeded sweep of degraded
trials of testkit/scenarios/sweep.py (noisy speech, dark frame, shaky gesture, clear gesture, clear both but
disagreeing), once with `--weights adaptive` and once with `--weights fixed`.
With ../shared/ present it also scores the scenes made from the real YOLOX-Nano detections on real photos
(testkit/scenarios/real.py: "the cup", "the person", "the fruit" -> question, "the banana" -> not found …) and the
real indoor scenes of ../shared/data/scenes/ line by line (testkit/scenarios/indoor.py).
An outcome counts as correct only if it is exactly the expected command or question.

Run: .venv/bin/python benchmarks/fusion_eval.py [--trials N]
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from pathlib import Path

from services.fusion.core import Config
from testkit.scenarios import Scenario, check, run_in_process
from testkit.scenarios.suite import SCENARIOS
from testkit.scenarios.sweep import degraded_sweep

ROOT = Path(__file__).resolve().parent.parent


def evaluate(scenarios: list[Scenario], mode: str) -> dict[str, list[bool]]:
    results: dict[str, list[bool]] = defaultdict(list)
    for sc in scenarios:
        ok = not check(sc, run_in_process(sc, Config(weights=mode, **sc.config)))
        results[sc.tags[0] if sc.tags else "untagged"].append(ok)
        results["ALL"].append(ok)
    return results


def real_photo_scenarios() -> list[Scenario]:
    """The scenes of testkit/scenarios/real.py, when ../shared/ (the YOLOX-Nano model, photos) and onnxruntime are
    there; else none, said on stderr."""
    import os

    shared = Path(os.environ.get("HRI_SHARED") or ROOT.parent / "shared")
    model = Path(os.environ.get("HRI_YOLOX_MODEL") or shared / "models" / "yolox_nano.onnx")
    if not model.is_file():
        print(f"real photos: skipped, no model at {model} (set HRI_SHARED or HRI_YOLOX_MODEL)", file=sys.stderr)
        return []
    try:
        from testkit.scenarios.real import real_scenarios, yolox_detector

        return real_scenarios(
            yolox_detector(model), lambda name: ROOT / name[5:] if name.startswith("repo:") else shared / name
        )
    except (ImportError, FileNotFoundError) as exc:
        print(f"real photos: skipped ({exc})", file=sys.stderr)
        return []


def indoor_scenes() -> None:
    """The real indoor scenes (../shared/data/scenes/: 12 photos, 30 sentences with the right answers) through
    vision's own pipeline and the fusion core, line by line (testkit/scenarios/indoor.py)."""
    import os

    shared = Path(os.environ.get("HRI_SHARED") or ROOT.parent / "shared")
    folder = shared / "data" / "scenes"
    model = Path(os.environ.get("HRI_YOLOX_MODEL") or shared / "models" / "yolox_nano.onnx")
    if not (folder / "scenes.json").is_file() or not model.is_file():
        print(f"indoor scenes: skipped, no {folder / 'scenes.json'} or no model at {model}", file=sys.stderr)
        return
    try:
        from testkit.scenarios.indoor import evaluate as evaluate_lines, load_lines, report, vision_pipeline

        print("indoor scenes (real photos, YOLOX-Nano + vision's colours, adaptive weights)")
        print(report(evaluate_lines(load_lines(folder), vision_pipeline(model), folder)))
    except ImportError as exc:
        print(f"indoor scenes: skipped ({exc})", file=sys.stderr)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=40, help="degraded trials per kind (default 40)")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    sweep = degraded_sweep(args.seed, args.trials)
    print(
        f"scenario suite: {len(SCENARIOS)} scenarios; degraded sweep: {len(sweep)} trials "
        f"({args.trials} per kind, seed {args.seed})\n"
    )
    sets = [("scenario suite (by first tag)", SCENARIOS), ("degraded sweep", sweep)]
    real = real_photo_scenarios()
    if real:
        sets.append(("real photos (YOLOX-Nano detections)", real))
    for title, scenarios in sets:
        adaptive, fixed = evaluate(scenarios, "adaptive"), evaluate(scenarios, "fixed")
        print(f"{title:34s} {'n':>4s} {'adaptive':>9s} {'fixed':>9s}")
        for group in sorted(adaptive, key=lambda g: (g == "ALL", g)):
            n = len(adaptive[group])
            a, f = sum(adaptive[group]) / n, sum(fixed[group]) / n
            print(f"  {group:32s} {n:4d} {a:9.0%} {f:9.0%}")
        print()
    indoor_scenes()


if __name__ == "__main__":
    main()

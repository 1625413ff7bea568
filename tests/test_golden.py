"""The golden net (testkit/golden.py): fusion's in-process outputs, byte for byte as committed.

A refactor leaves these files unchanged. A change of behaviour re-blesses them on purpose
(`.venv/bin/python -m testkit.golden --bless`) and the commit's diff shows every output that changed.
"""

from __future__ import annotations

from typing import Any

import pytest

from testkit import golden


def test_synthetic_runs_match_the_golden_file():
    assert golden.SYNTHETIC.is_file(), f"{golden.SYNTHETIC} is missing: python -m testkit.golden --bless"
    diff = golden.first_difference(golden.SYNTHETIC.read_text(encoding="utf-8"), golden.render(golden.synthetic_lines))
    assert not diff, diff + "\n(on purpose? re-bless with: python -m testkit.golden --bless)"


@pytest.fixture(scope="module")
def real_run() -> tuple[str, Any]:
    """The real-photo runs rendered once, with the detectors that saw their photos."""
    why_not = golden.real_available()
    if why_not:
        pytest.skip(why_not)
    from testkit.golden_detections import OrtSettings

    detectors = golden.real_detectors(OrtSettings())
    return golden.render(lambda: golden.real_lines(detectors)), detectors


def test_real_scene_runs_match_the_golden_file(real_run):
    text, _ = real_run
    diff = golden.first_difference(golden.REAL.read_text(encoding="utf-8"), text)
    assert not diff, diff + "\n(on purpose? re-bless with: python -m testkit.golden --bless)"


def _photos(detector: Any) -> dict[str, tuple[Any, Any]]:
    """photo -> (frame, rounded detections), each photo once."""
    return {photo: (frame, found) for photo, frame, found in detector.seen}


def test_every_real_detection_sits_clear_of_the_edges_where_a_last_digit_would_change_the_file(real_run):
    """A box figure on a rounding boundary, a score at the threshold, an overlap at the NMS limit, two candidates
    of one object with nearly equal scores: each would make the file hang on onnxruntime's last digits."""
    from testkit.golden_detections import margins

    _, detectors = real_run
    close = [
        f"{photo}: {what} only {distance:.2g} away (wants {guard:.0e})"
        for detector in detectors
        for photo, (frame, _) in _photos(detector).items()
        for what, distance, guard in margins(detector, frame)
        if distance < guard
    ]
    assert sum(len(_photos(d)) for d in detectors) >= 10
    assert not close, "\n".join(close)


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("optimise", [True, False], ids=["graph-optimised", "graph-as-is"])
def test_the_rounded_detections_are_the_same_under_other_onnxruntime_settings(real_run, threads, optimise):
    from testkit.golden_detections import GoldenDetector, OrtSettings

    _, detectors = real_run
    for detector in detectors:
        other = GoldenDetector(
            golden.yolox_model(), detector.conf_threshold, detector.iou_threshold, OrtSettings(threads, optimise)
        )
        for photo, (frame, found) in _photos(detector).items():
            assert other.detect(frame) == found, f"{photo} with {OrtSettings(threads, optimise)}"


def test_a_changed_output_is_reported_with_its_run():
    text = golden.SYNTHETIC.read_text(encoding="utf-8")
    lines = text.splitlines()
    i = next(n for n, line in enumerate(lines) if line.startswith("  FusedCommand"))
    changed = "\n".join(lines[:i] + [lines[i].replace('"confidence": ', '"confidence": 1', 1)] + lines[i + 1 :])
    diff = golden.first_difference(text, changed)
    assert f"line {i + 1}" in diff and "# suite [adaptive] 0:" in diff


def test_a_changed_figure_is_named_by_its_field():
    line = '  FusedCommand {"target": {"bbox": [1.0, 2.5], "id": "cup_3"}, "confidence": 0.5}'
    assert (
        golden.differing_figure(line, line.replace("2.5", "3.0"))
        == "FusedCommand target.bbox[1]: 2.5 in the file, 3.0 now"
    )

"""The golden net (testkit/golden.py): fusion's in-process outputs, byte for byte as committed.

A refactor leaves these files unchanged. A change of behaviour re-blesses them on purpose
(`.venv/bin/python -m testkit.golden --bless`) and the commit's diff shows every output that changed.
"""

from __future__ import annotations

import pytest

from testkit import golden


def test_synthetic_runs_match_the_golden_file():
    assert golden.SYNTHETIC.is_file(), f"{golden.SYNTHETIC} is missing: python -m testkit.golden --bless"
    diff = golden.first_difference(golden.SYNTHETIC.read_text(encoding="utf-8"), golden.render(golden.synthetic_lines))
    assert not diff, diff + "\n(on purpose? re-bless with: python -m testkit.golden --bless)"


def test_real_scene_runs_match_the_golden_file():
    why_not = golden.real_available()
    if why_not:
        pytest.skip(why_not)
    diff = golden.first_difference(golden.REAL.read_text(encoding="utf-8"), golden.render(golden.real_lines))
    assert not diff, diff + "\n(on purpose? re-bless with: python -m testkit.golden --bless)"


def test_a_changed_output_is_reported_with_its_run():
    text = golden.SYNTHETIC.read_text(encoding="utf-8")
    lines = text.splitlines()
    i = next(n for n, line in enumerate(lines) if line.startswith("  FusedCommand"))
    changed = "\n".join(lines[:i] + [lines[i].replace('"confidence": ', '"confidence": 1', 1)] + lines[i + 1 :])
    diff = golden.first_difference(text, changed)
    assert f"line {i + 1}" in diff and "# suite [adaptive] 0:" in diff

"""How `make test` spreads the suite over pytest-xdist workers (TEST_WORKERS=2, the default; docs/foundation.md,
"CI time"). Workers take whole modules (`--dist loadfile`: a module's fixtures load once) in the order given here,
each taking the next when it is nearly done, so the run ends when the last long module ends:

- the modules that take minutes go first, longest first (list scheduling, longest first), and the hundreds of
  short modules fill in at the end;
- the two modules that decode hundreds of utterances with Whisper on two threads form one unit, so they run one
  after the other on one worker: run at the same time each got one core and took 1.6-2x longer.

The costs are seconds measured quiet in one process (fresh-clone runs, 29 Nov); a stale figure only costs time."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

# Whisper's decodes, on both cores each: one work unit, so never two at once
WHISPER_UNIT = ("tests/test_speech_commands.py", "tests/test_speech_whisper.py")
WHISPER_UNIT_NAME = "tests/whisper-decodes"
# seconds per module (measured; the rest take under ~40 s each)
MODULE_SECONDS = {
    WHISPER_UNIT_NAME: 560.0,
    "tests/test_fusion_scenes_real.py": 110.0,
    "tests/test_intent_clips.py": 100.0,
    "tests/test_gesture_still_photos.py": 76.0,
    "tests/test_speech_recognition.py": 70.0,
    "tests/test_voice_integration.py": 67.0,
    "tests/test_gesture_pose_pacing.py": 65.0,
    "tests/test_viewers_live.py": 60.0,
    "tests/test_docker.py": 56.0,
    "tests/test_gesture_persons.py": 50.0,
    "tests/test_gesture_photos.py": 49.0,
    "tests/test_system_e2e.py": 40.0,
    "tests/test_rgbd_e2e.py": 35.0,
}


def unit_of(module: str) -> str:
    """The work unit a test module belongs to (its own path, or the Whisper unit)."""
    return WHISPER_UNIT_NAME if module in WHISPER_UNIT else module


def module_of(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


def longest_first(nodeids: Sequence[str]) -> list[int]:
    """The positions of `nodeids` reordered: the units of MODULE_SECONDS first, costliest first (a unit's modules in
    their collected order), then the rest as collected. Stable within a module."""
    first_seen: dict[str, int] = {}  # units and modules: where each first appears
    for i, nodeid in enumerate(nodeids):
        first_seen.setdefault(unit_of(module_of(nodeid)), i)
        first_seen.setdefault(module_of(nodeid), i)

    def key(i: int) -> tuple[float, int, int, int]:
        module = module_of(nodeids[i])
        unit = unit_of(module)
        # a module's tests stay together: its module-scoped fixtures are built once
        return (-MODULE_SECONDS.get(unit, 0.0), first_seen[unit], first_seen[module], i)

    return sorted(range(len(nodeids)), key=key)


def make_scheduler(config: Any, log: Any) -> Any:
    """Under `--dist loadfile`: xdist's whole-module scheduler with the Whisper modules as one unit, in collected
    order (the reordering by test count is off: `--no-loadscope-reorder` in the Makefile). None (xdist's own) for
    any other --dist."""
    if config.getoption("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class UnitScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return unit_of(super()._split_scope(nodeid))

    return UnitScheduling(config, log)

"""The stack's CPU budget (issue #42, common/budget.py): the rates of the video stages for the cores of the machine,
lowered in the order a user would choose, and how `hri up` passes them (pure arithmetic, no process)."""

from __future__ import annotations

import argparse

import pytest

from common.budget import (
    FLOOR_HZ,
    FULL_HZ,
    RESERVE_CORES,
    STAGE_MS,
    TARGET_SHARE,
    MaxRate,
    budget_flags,
    plan_budget,
)
from hri.launcher import add_up_arguments, budget_lines, services_from_args

STACK = {"camera", "vision", "gesture", "speech", "fusion"}


def cores_of(rates: dict[str, float]) -> float:
    return sum(hz * STAGE_MS[s] / 1000.0 for s, hz in rates.items())


def test_a_big_machine_runs_every_stage_at_full_rate() -> None:
    budget = plan_budget(8, STACK)
    assert budget.rates == {s: FULL_HZ[s] for s in STAGE_MS}
    assert budget.fits and budget_flags(budget, 30.0) == {}
    assert budget.needed_cores == pytest.approx(cores_of(FULL_HZ))


def test_two_cores_lower_vision_first_and_only_it_when_that_is_enough() -> None:
    budget = plan_budget(2, STACK)
    video = TARGET_SHARE * 2 - sum(RESERVE_CORES.values())
    assert budget.video_cores == pytest.approx(video)
    # everything else at full rate; vision takes what is left, as long as it stays above its floor
    others = {s: FULL_HZ[s] for s in STAGE_MS if s != "vision"}
    expected_vision = (video - cores_of(others)) * 1000.0 / STAGE_MS["vision"]
    assert FLOOR_HZ["vision"] < expected_vision < FULL_HZ["vision"]
    assert budget.rates == pytest.approx({**others, "vision": expected_vision})
    assert budget.needed_cores == pytest.approx(video)
    assert budget_flags(budget, 30.0) == {"vision": [f"--max-rate={expected_vision:.1f}"]}
    assert "first" in budget.why["vision"] and budget.why["hands"].startswith("full rate")


def test_less_room_lowers_persons_and_faces_together_then_pose_and_never_hands() -> None:
    tight = plan_budget(1.7, STACK)
    assert tight.rates["vision"] == pytest.approx(FLOOR_HZ["vision"])
    assert FLOOR_HZ["persons"] <= tight.rates["persons"] < FULL_HZ["persons"]
    assert FLOOR_HZ["faces"] <= tight.rates["faces"] < FULL_HZ["faces"]
    # in proportion to what each could give: the same share of the way from full to floor
    gone = {s: (FULL_HZ[s] - tight.rates[s]) / (FULL_HZ[s] - FLOOR_HZ[s]) for s in ("persons", "faces")}
    assert gone["persons"] == pytest.approx(gone["faces"])
    assert tight.rates["pose"] == FULL_HZ["pose"] and tight.rates["hands"] == FULL_HZ["hands"]
    assert tight.needed_cores == pytest.approx(tight.video_cores) and tight.fits
    one = plan_budget(1, STACK)
    assert {s: one.rates[s] for s in ("vision", "persons", "faces", "pose")} == {
        s: FLOOR_HZ[s] for s in ("vision", "persons", "faces", "pose")
    }
    assert one.rates["hands"] == FULL_HZ["hands"]  # hands last: never lowered here
    assert not one.fits and "floor" in one.notes[0]


def test_only_the_services_on_count_and_the_camera_rate_caps_every_stage() -> None:
    vision_only = plan_budget(1, {"camera", "vision"})
    assert set(vision_only.rates) == {"vision"}
    video = TARGET_SHARE - RESERVE_CORES["camera"] - RESERVE_CORES["router"]
    assert vision_only.rates["vision"] == pytest.approx(video * 1000.0 / STAGE_MS["vision"])
    slow_camera = plan_budget(8, STACK, fps=5.0)
    assert slow_camera.rates["vision"] == 5.0 and slow_camera.rates["pose"] == 5.0
    assert budget_flags(slow_camera, 5.0) == {}  # at the camera's rate: nothing to lower
    cheap = plan_budget(2, STACK, costs={"vision": 8.0})
    assert cheap.rates["vision"] == FULL_HZ["vision"]  # the colour backend fits at full rate


def test_the_persons_rate_becomes_every_nth_frame_never_above_the_budget() -> None:
    budget = plan_budget(1.7, STACK)
    flags = budget_flags(budget, 30.0)["gesture"]
    every = int(next(f for f in flags if f.startswith("--persons-every=")).split("=")[1])
    assert 30.0 / every <= budget.rates["persons"] < 30.0 / (every - 1)


def test_max_rate_takes_frames_at_the_rate_on_average() -> None:
    pace = MaxRate(12.0)
    taken = [k for k in range(300) if pace.take(1000.0 + k / 30.0)]  # 10 s at 30 fps
    assert len(taken) == pytest.approx(120, abs=2)
    assert all(b - a in (2, 3) for a, b in zip(taken, taken[1:]))
    assert all(MaxRate(0.0).take(k / 30.0) for k in range(10))
    back = MaxRate(10.0)
    assert back.take(100.0) and back.take(50.0)  # a clock gone back starts afresh


def up(*flags: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_up_arguments(p)
    return p.parse_args(["--camera", "clip.mp4", "--vision-backend", "onnx", "--model", "m.onnx", *flags])


def test_hri_up_passes_the_budget_before_the_users_own_flags_and_says_why() -> None:
    specs = {s.name: s.argv for s in services_from_args(up("--cores", "2", "--vision-arg=--max-rate=20"))}
    rate = [a for a in specs["vision"] if a.startswith("--max-rate=")]
    assert len(rate) == 2 and rate[-1] == "--max-rate=20"  # the user's last: argparse keeps it
    assert specs["gesture"] == ["services.gesture"]  # nothing of gesture lowered on 2 cores
    assert not [a for a in services_from_args(up("--cores", "2", "--budget", "off"))[1].argv if "max-rate" in a]
    lines = budget_lines(plan_budget(2, STACK))
    assert "budget for 2 cores" in lines[0] and any("vision: lowered to" in line for line in lines)
    colour = up("--cores", "2")
    colour.vision_backend = "color"  # no model: vision is cheap, nothing lowered
    assert not [a for s in services_from_args(colour) for a in s.argv if "max-rate" in a]

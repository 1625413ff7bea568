"""benchmarks/stack.py's verdict against issue #42's goal (`goal_misses`, pure): a run's figures in, each figure
that misses the goal named with the service behind it."""

from __future__ import annotations

from typing import Any

from benchmarks.stack import GOAL, SCENES, goal_misses


def output(hz: float, p99: float, first: float = 30.0, last: float = 30.0) -> dict[str, Any]:
    return {
        "count": int(hz * 60),
        "rate_hz": hz,
        "lag_p50_ms": 30.0,
        "lag_p99_ms": p99,
        "lag_p50_first_third_ms": first,
        "lag_p50_last_third_ms": last,
    }


def run(**change: Any) -> dict[str, Any]:
    """A run that meets the goal on 2 cores, with `change` applied."""
    result: dict[str, Any] = {
        "services": {
            "vision": {"cpu_share_of_machine": 0.35, "skipped": 10},
            "gesture": {"cpu_share_of_machine": 0.3, "skipped": 5},
            "speech": {"cpu_share_of_machine": 0.05, "skipped": 0},
            "total_cpu_cores": 1.5,
        },
        "outputs": {
            "gesture hands": output(28.0, 90.0),
            "vision objects": output(25.0, 120.0),
            "gesture faces": output(19.0, 90.0),
            "gesture persons": output(14.0, 90.0),
        },
        "commands": {"last_word_to_command_p50_ms": 420.0, "emitted_without_speech": 0},
    }
    for key, value in change.items():
        section, _, name = key.partition("__")
        if name:
            result[section][name.replace("_", " ")] = value
        else:
            result[section] = value
    return result


def test_a_run_that_meets_every_figure_misses_nothing() -> None:
    assert goal_misses(run(), 2) == []


def test_each_missed_figure_is_named_with_its_service() -> None:
    misses = goal_misses(run(outputs__gesture_hands=output(15.1, 175.0)), 2)
    assert len(misses) == 2
    assert misses[0].startswith("gesture hands 15.1 Hz < 20") and "gesture 30 % of the machine" in misses[0]
    assert misses[1].startswith("gesture hands lag p99 175 ms > 120")
    # why: 0.3 of 2 cores at 15.1 Hz is 40 ms of CPU a frame; 20 Hz needs 0.79 cores
    assert "; 40 ms of CPU a frame: 20 Hz needs 0.79 cores, it had 0.60" in misses[0]


def test_the_stack_the_speech_and_the_unasked_commands() -> None:
    services = run()["services"] | {"total_cpu_cores": 1.91}
    commands = {"last_word_to_command_p50_ms": 797.0, "emitted_without_speech": 1}
    misses = goal_misses(run(services=services, commands=commands), 2)
    assert misses[0].startswith("stack 1.91 of 2 cores > 1.8 (the most: vision")
    assert misses[1].startswith("last word -> command p50 797 ms > 450")
    commands |= {"last_word_to_transcript_p50_ms": 616.0, "transcript_to_command_p50_ms": 181.0}
    why = goal_misses(run(commands=commands), 2)[0]
    assert "speech: the transcript p50 616 ms after the last word (300 ms of it the end-of-utterance silence" in why
    assert "fusion: p50 181 ms from the transcript to the command (a window ends 300 ms after" in why
    assert misses[2] == "1 command(s) nobody gave"
    assert goal_misses(run(services=services), 4) == []  # 1.91 of 4 cores is within 3.6


def test_a_growing_lag_and_a_silent_output_are_misses() -> None:
    misses = goal_misses(run(outputs__vision_objects=output(12.0, 150.0, first=40.0, last=200.0)), 2)
    assert misses == [misses[0]] and "vision objects lag grows: p50 40 -> 200 ms" in misses[0]
    outputs = run()["outputs"]
    del outputs["gesture persons"]
    assert goal_misses(run(outputs=outputs), 2)[0].startswith("gesture persons: nothing arrived")
    # the speech-alone variant runs no video service: only its speech is judged
    speech_alone = {"speech": {"cpu_share_of_machine": 0.05, "skipped": 0}, "total_cpu_cores": 0.12}
    assert goal_misses(run(services=speech_alone, outputs={}), 2) == []
    assert GOAL["persons_hz"] == 5.0


def test_the_scenes_are_the_development_set_only() -> None:
    held_back = (
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
    material = [p for s in SCENES for p in (s.audio, s.video or "", *s.photos)]
    assert not [p for p in material if any(h in p for h in held_back)]
    assert len(SCENES) >= 4 and any(s.photos for s in SCENES)

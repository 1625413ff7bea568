"""Who is speaking, end to end through real processes: camera (a real two-person clip from ../shared/data/talking),
gesture (its face stage), speech (Whisper on the audio) and fusion, on loopback.

The clip is comp_turns_bbaf2n_lbbc2a.mp4: the left person talks 0.95-2.56 s, then the right one 3.44-5.41 s (real
GRID footage side by side; each listener's mouth stays still). GRID's sentences ("bin blue at f two now") are no
commands, and fusion publishes nothing for them, so the audio here is the piper voice saying a command in each of
the two labelled speech intervals (testkit/talking.py `spoken_commands`): the mouths and the timing are the real
clip's, the words are synthetic. Camera and speech start together (--start-at), as one recording's video and audio.
Each command's speaker is the person who talked in that turn (their face id: the person stage is off here, see
the comment at its start; tests/test_speaker.py covers faces tied to persons).
"""

from __future__ import annotations

import collections
import json
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import pytest

from common.schema import Clarification, FusedCommand
from services.fusion.speaker import SpeakerConfig
from testkit.harness import Client, Collector, Proc, ProcessGroup, requires_services
from testkit.shared import shared_path
from testkit.talking import TALKING, spoken_commands, talking_json

pytestmark = pytest.mark.integration

CLIP = "comp_turns_bbaf2n_lbbc2a.mp4"
COMMANDS = ["please turn left", "come over here please"]  # said in the left, then the right person's turn
# s from launching camera and speech to the clip playing: each loads what it needs (the video, Whisper) before it
# declares itself live, ~3 s on a quiet 2-core machine. A run in which either was not live by then says nothing (the
# clip started without it) and is played again from the start, with a lead of twice the time they took
LEAD = 8.0
PLAYS = 3  # each with twice the start-up time the last one took: a machine that never gets there fails, named


@requires_services("camera", "gesture", "speech", "fusion")
def test_each_utterance_carries_the_person_who_said_it(tmp_path: Path) -> None:
    video = shared_path(f"{TALKING}/{CLIP}")
    clip = next(c for c in talking_json()["clips"] if c["clip"] == CLIP)
    wav = spoken_commands(clip, COMMANDS, tmp_path / "commands.wav")
    run = play_the_clip(video, wav, LEAD)
    for _ in range(PLAYS - 1):  # camera or speech was not live when the clip started: nothing to judge, play again
        if run.again is None:
            break
        run.group.close()
        run = play_the_clip(video, wav, run.again)
    if run.again is not None:
        run.group.close()
        raise AssertionError(
            f"camera or speech was not live a second before the clip in {PLAYS} plays ({run.again / 2:.0f} s)"
        )
    group, got, faces, transcripts, echo = run.group, run.outputs, run.faces, run.transcripts, run.echo
    try:
        outputs = [sample for _, sample in got]
        assert all(isinstance(o, (FusedCommand, Clarification)) for o in outputs)
        ids = people_left_to_right([s for _, s in faces.seen])
        assert all(i.startswith("cam0/face-") for i in ids), ids  # no person stage: the face ids stand for them
        intents = [o.intent for o in outputs if isinstance(o, FusedCommand)]
        assert intents == ["turn", "come_here"], (outputs, group.logs())
        speakers = [o.speaker for o in outputs]
        assert all(s is not None for s in speakers), group.logs()
        heard = [t for _, t in transcripts.seen]
        assert len(heard) == 2, heard
        # who said each command is only told from a mouth followed at speaker_min_rate frames/s while it was said; a
        # machine too busy for that must say "unknown" and why, never name anyone (the face stage's rate is the
        # machine's: 25 frames/s on a quiet 2-core machine, 3 with two busy loops beside the stack)
        need = SpeakerConfig().speaker_min_rate
        for said, speaker, person in zip(heard, speakers, ids):
            assert speaker is not None
            rate = face_rate(faces.seen, said.start, said.end)
            if rate >= need + 2:  # a margin: fusion's own count of the frames may differ by a frame or two
                assert speaker.person == person, (said.text, f"faces at {rate:.1f}/s", speaker.reason, group.logs())
                assert speaker.method == "mouth_motion" and speaker.addressed is True, speaker
            elif rate < need - 2:
                assert speaker.person is None and "seen well enough" in speaker.reason, (said.text, rate, speaker)
                warnings.warn(
                    f"{said.text!r}: the face stage ran at {rate:.1f} frames/s while it was said (a busy "
                    f"machine; {need:g} needed): its speaker was rightly unknown, not checked against the label",
                    stacklevel=1,
                )
            else:  # at the edge: named rightly or unknown, never someone else
                assert speaker.person in (person, None), (said.text, rate, speaker.reason)
        echoed = [json.loads(line) for line in wait_lines(echo, 2)]
        assert [line["speaker"]["person"] for line in echoed] == [s.person for s in speakers if s], echo.output()
    finally:
        group.close()


@dataclass
class Played:
    """One run of the stack over the clip: its processes (still running), what was collected, and `again`: the
    lead to play it again with when camera or speech was not live before the clip started (None: they were)."""

    group: ProcessGroup
    outputs: list
    faces: Collector
    transcripts: Collector
    echo: Proc
    again: float | None


def play_the_clip(video: Path, wav: Path, lead: float) -> Played:
    """Fusion and gesture started and live, then camera and speech launched to play the clip `lead` s later; waits
    for fusion's two outputs unless camera or speech was not live a second before the clip started."""
    group = ProcessGroup()
    try:
        group.router()
        group.service("fusion")
        # hands and faces. Not the person stage (a pose per person): on 2 shared cores under load it held the
        # gesture service to 3.5 frames/s, too slow to follow a mouth (attribution then says unknown, rightly);
        # without persons a face's person is its face id (docs/people.md)
        group.service("gesture", "--no-body", "--persons-every", "0")
        client = Client(group.endpoint)
        try:
            client.wait_alive("fusion", timeout=60)
            client.wait_alive("gesture", timeout=60)
            results = client.collect("hri/fusion/**")
            faces = client.collect("hri/gesture/*/faces")
            transcripts = client.collect("hri/speech/*/transcript")
            echo = group.start("echo", "hri.cli", "echo", "hri/fusion/**", "--count", "2")  # what a user sees
            launched = time.time()
            start = launched + lead
            group.service("camera", "--source", str(video), "--fps", "25", "--start-at", f"{start:.3f}")
            group.service("speech", "--input", "wav", "--wav", str(wav), "--realtime", "--start-at", f"{start:.3f}")
            for name in ("camera", "speech"):
                client.wait_alive(name, timeout=lead + 60)
            took = time.time() - launched
            if took > lead - 1.0:
                return Played(group, [], faces, transcripts, echo, again=2 * took)
            got = results.wait(2, timeout=start - time.time() + 60)
            assert time.time() > start, "the outputs came before the clip played"
            # both transcripts: a command goes out at a higher Zenoh priority than they do (real time, express), so
            # on a loaded machine the second command overtook its own transcript on the way to this test (issue #41)
            transcripts.wait(2, timeout=30)
            faces.drain(0.5)
        finally:
            client.close()
    except BaseException:
        group.close()
        raise
    return Played(group, got, faces, transcripts, echo, again=None)


def wait_lines(proc: Proc, n: int, timeout: float = 30.0) -> list[str]:
    """The first `n` JSON lines a process printed (waits for them)."""
    deadline = time.monotonic() + timeout
    while True:
        lines = [line for line in proc.output().splitlines() if line.startswith("{")]
        if len(lines) >= n or time.monotonic() > deadline:
            return lines[:n]
        time.sleep(0.1)


def face_rate(seen: list, start: float, end: float) -> float:
    """Faces samples per second the gesture service published over [start, end] of source time."""
    return sum(1 for _, f in seen if start <= f.stamp <= end) / max(end - start, 1e-3)


def people_left_to_right(samples: list) -> list[str]:
    """The person of each of the two face tracks the gesture service published, left one first: the person id its
    faces were given most (the person stage links them), else the face id."""
    centres: dict[str, list[float]] = {}
    people: dict[str, collections.Counter] = {}
    for s in samples:
        for f in s.faces:
            centres.setdefault(f.id, []).append(f.bbox[0] + f.bbox[2] / 2)
            people.setdefault(f.id, collections.Counter())[f.person or f.id] += 1
    assert len(centres) == 2, centres
    left_first = sorted(centres, key=lambda i: sum(centres[i]) / len(centres[i]))
    return [people[i].most_common(1)[0][0] for i in left_first]

"""Who said an utterance, and was it said to the robot (issue #33, items 2 and 4). Pure: Faces samples and a
Transcript in, a wire `Speaker` out.

The rule is TIMING, not loudness: a speaker's mouth moves while the words are heard and much less just before and
after them; a listener's mouth is still while the words are heard. For each face track seen during the utterance:

- motion = how fast the mouth opening changes (|d mouth_open / dt|, per second: scale- and frame-rate-free);
- `during` = its mean inside the utterance [start, end]; `around` = its mean in `context` s before the start and
  after the end (a `guard` s gap on each side, where the mouth still closes or already opens);
- timing = (during - around) / (during + around), in [-1, 1]: 1 = moves only with the speech.

A face moves with the speech when `during` >= `still` and timing >= `min_timing`. One such face (or the only face
in view, whose mouth is not still) is the speaker; when two or more move with it and the best leads by less than
`margin`, the speaker is unknown ("dub": two mouths move over one voice, and no timing tells them apart) —
never a silent person. A face's person id is `Face.person`, else its face id (persons may be absent).

THE SOUND (issue #40), when the transcript carries its `loudness`: with two or more mouths moving (not still)
during the utterance, the one that opens and closes with the rise and fall of the sound is the speaker:
`sound_match` is the correlation of each mouth's frame-to-frame change with the sound's; the best must reach
`sound_min_match` and lead the next moving mouth by `sound_margin`, else the speaker is unknown (a voice no
visible mouth matches is nobody's in view, never a silent person's). Without loudness, timing decides as above.

`addressed`: the speaker was engaged with the robot over the utterance and at its end (common/engagement.py:
head turned to the camera, in its field of view, within reach); nil when the speaker or their head's orientation
is unknown.
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

from common.engagement import EngagementConfig, engaged_over
from common.schema import Faces, Loudness, Persons, Speaker, Transcript
from common.settings import setting


@dataclass(frozen=True)
class SpeakerConfig:
    """Attribution's settings; each is a flag of `hri-fusion` (docs/people.md "Who is speaking")."""

    speaker_still: float = setting(
        0.2,
        "mouth motion (change of mouth_open per second) below which a mouth is still while the words are heard",
        at_least=0,
        metavar="RATE",
    )
    speaker_min_timing: float = setting(
        0.3,
        "timing score (motion during vs around the utterance, -1..1) a mouth needs to go with the speech",
        at_least=-1,
        at_most=1,
    )
    speaker_margin: float = setting(
        0.25,
        "the lead in timing score the best mouth needs over a second moving mouth; less: unknown",
        at_least=0,
        at_most=2,
    )
    speaker_context: float = setting(
        1.0, "seconds before the start and after the end compared with the utterance", above=0, metavar="S"
    )
    speaker_guard: float = setting(
        0.1, "seconds next to the utterance left out of the comparison", at_least=0, metavar="S"
    )
    speaker_min_rate: float = setting(
        8.0,
        "frames per second of a face needed inside the utterance to follow its mouth (sparser: not judged)",
        at_least=0,
        metavar="FPS",
    )
    speaker_coverage: float = setting(
        0.5, "share of the utterance a face's mouth must be seen in to be judged", above=0, at_most=1, metavar="P"
    )
    sound_min_match: float = setting(
        0.3,
        "correlation of a mouth's opening and closing with the sound's rise and fall it needs to be the voice's mouth "
        "(two mouths moving)",
        at_least=-1,
        at_most=1,
        metavar="R",
    )
    sound_margin: float = setting(
        0.1,
        "the lead in that correlation the best mouth needs over a second moving mouth; less: unknown",
        at_least=0,
        at_most=2,
        metavar="R",
    )


@dataclass
class Track:
    """One face's samples over time (stamps ascending): mouth opening and whether it looked at the camera."""

    face: str
    people: Counter[str] = field(default_factory=Counter)  # the person ids the face was given, how often
    stamps: list[float] = field(default_factory=list)
    mouth: list[float | None] = field(default_factory=list)
    looking: list[bool | None] = field(default_factory=list)

    @property
    def person(self) -> str:
        """The person the face belongs to: the person id it was given most (`Face.person`), else the face id (no
        person tracker). Keyed by the face track, a frame where the person tracker missed the face splits nothing."""
        return self.people.most_common(1)[0][0] if self.people else self.face


@dataclass(frozen=True)
class Judged:
    """One face's motion during and around the utterance."""

    person: str
    during: float | None  # mean mouth motion inside the utterance (per second); None: mouth not seen enough
    around: float | None  # in the context around it; None: no frames there
    timing: float | None  # (during - around) / (during + around)

    def moves(self, cfg: SpeakerConfig) -> bool:
        return self.during is not None and self.during >= cfg.speaker_still

    def goes_with_speech(self, cfg: SpeakerConfig) -> bool:
        return self.moves(cfg) and self.timing is not None and self.timing >= cfg.speaker_min_timing


def tracks_of(samples: Iterable[Faces]) -> dict[str, Track]:
    """Faces samples (any order, any camera) -> one Track per face id, in source time."""
    tracks: dict[str, Track] = {}
    for sample in sorted(samples, key=lambda s: s.stamp):
        for face in sample.faces:
            track = tracks.setdefault(face.id, Track(face.id))
            if face.person:
                track.people[face.person] += 1
            track.stamps.append(sample.stamp)
            track.mouth.append(face.mouth_open)
            track.looking.append(face.looking_at_camera)
    return tracks


def _motion(track: Track, lo: float, hi: float) -> tuple[float | None, int]:
    """Mean |d mouth / dt| over consecutive measured samples both inside [lo, hi], and how many samples."""
    rates: list[float] = []
    seen = 0
    prev: tuple[float, float] | None = None
    for stamp, mouth in zip(track.stamps, track.mouth):
        if not lo <= stamp <= hi or mouth is None:
            prev = None
            continue
        seen += 1
        if prev is not None and stamp > prev[0]:
            rates.append(abs(mouth - prev[1]) / (stamp - prev[0]))
        prev = (stamp, mouth)
    return (sum(rates) / len(rates) if rates else None), seen


def _frames_in(stamps: Sequence[float], lo: float, hi: float) -> int:
    return sum(1 for s in stamps if lo <= s <= hi)


def judge(track: Track, start: float, end: float, stream_frames: int, cfg: SpeakerConfig) -> Judged:
    """`stream_frames`: frames of any face stream in [start, end] (the coverage's denominator)."""
    during, seen = _motion(track, start, end)
    too_sparse = seen < cfg.speaker_min_rate * (end - start)  # a mouth sampled slowly looks still
    if during is None or too_sparse or seen < cfg.speaker_coverage * max(stream_frames, 2):
        return Judged(track.person, None, None, None)
    before, n_before = _motion(track, start - cfg.speaker_guard - cfg.speaker_context, start - cfg.speaker_guard)
    after, n_after = _motion(track, end + cfg.speaker_guard, end + cfg.speaker_guard + cfg.speaker_context)
    sides = [(v, n) for v, n in ((before, n_before), (after, n_after)) if v is not None]
    if not sides:
        return Judged(track.person, during, None, None)
    around = sum(v * n for v, n in sides) / sum(n for _, n in sides)
    total = during + around
    return Judged(track.person, during, around, (during - around) / total if total > 0 else 0.0)


def addressed(
    faces: Sequence[Faces],
    person: str,
    t: Transcript,
    engagement: EngagementConfig | None = None,
    persons: Sequence[Persons] = (),
) -> bool | None:
    """Said to the robot: the speaker engaged with it over the utterance and at its end (common/engagement.py)."""
    return engaged_over(faces, person, t.start, t.end, engagement, persons).engaged


MIN_SOUND_FRAMES = 8  # frames of a mouth inside the utterance needed to correlate it with the sound


def sound_match(track: Track, loudness: Loudness, start: float, end: float) -> float | None:
    """How well the mouth moves with the sound over [start, end]: the correlation of the mouth's opening and closing
    from frame to frame with the rise and fall of the sound's amplitude (RMS, from the dB values, averaged within
    one frame spacing of each frame) between the same frames. Changes, not levels: lips open into a syllable and
    close after it, while a mouth left ajar or a slowly changing level only adds a trend that a short window turns
    into correlation; and amplitude, not dB, whose log would blow up the noise of the quiet stretches. None: too few
    frames in a row, or either series flat."""
    rows = [(s, m) for s, m in zip(track.stamps, track.mouth) if start <= s <= end and m is not None]
    if len(rows) < MIN_SOUND_FRAMES or not loudness.db:
        return None
    stamps = np.array([r[0] for r in rows])
    mouth = np.array([r[1] for r in rows])
    amplitude = 10.0 ** (np.asarray(loudness.db, dtype=float) / 20.0)
    centres = loudness.start + (np.arange(len(amplitude)) + 0.5) * loudness.step
    reach = max(float(np.median(np.diff(stamps))), loudness.step / 2)
    heard = np.array(
        [float(near.mean()) if len(near := amplitude[np.abs(centres - s) <= reach]) else np.nan for s in stamps]
    )
    d_mouth, d_sound = np.diff(mouth), np.diff(heard)
    keep = ~np.isnan(d_sound)
    if keep.sum() < MIN_SOUND_FRAMES - 1 or np.std(d_mouth[keep]) < 1e-9 or np.std(d_sound[keep]) < 1e-12:
        return None
    return float(np.corrcoef(d_mouth[keep], d_sound[keep])[0, 1])


def _by_sound(moving: list[tuple[Judged, float | None]], cfg: SpeakerConfig) -> Speaker | None:
    """Of two or more moving mouths, the one that moves with the sound; None when no correlation could be made."""
    scored = sorted(((j, r) for j, r in moving if r is not None), key=lambda jr: -jr[1])
    if not scored:
        return None
    best, r = scored[0]
    listing = ", ".join(f"{j.person} {v:.2f}" for j, v in scored)
    if r < cfg.sound_min_match:
        return _unknown(f"mouths moved but none with the sound (correlation {listing}): not anyone in view")
    if len(scored) > 1 and r - scored[1][1] < cfg.sound_margin:
        return _unknown(f"{best.person} and {scored[1][0].person} both moved with the sound ({listing})")
    lead = r - scored[1][1] if len(scored) > 1 else r
    return Speaker(
        person=best.person,
        confidence=round(0.5 + 0.5 * min(1.0, lead), 3),
        method="mouth_motion",
        reason=f"{best.person}'s mouth moved with the sound (correlation {listing})",
    )


def _unknown(reason: str) -> Speaker:
    return Speaker(person=None, confidence=0.0, method="unknown", addressed=None, reason=reason)


def _only_face(j: Judged, cfg: SpeakerConfig) -> Speaker:
    if j.during is None:
        return Speaker(person=j.person, confidence=0.5, method="only_face", reason="the only face in view")
    if not j.moves(cfg):
        return _unknown(f"the only face in view ({j.person}) kept its mouth still: the voice is not theirs")
    timing = max(0.0, j.timing) if j.timing is not None else 0.0
    return Speaker(
        person=j.person,
        confidence=round(0.6 + 0.4 * min(1.0, timing), 3),
        method="only_face",
        reason=f"the only face in view, its mouth moving ({_numbers(j)})",
    )


def _numbers(j: Judged) -> str:
    timing = "n/a" if j.timing is None else f"{j.timing:.2f}"
    return f"motion {j.during or 0.0:.2f}/s during, timing {timing}"


def _several(judged: list[Judged], cfg: SpeakerConfig) -> Speaker:
    fits = sorted((j for j in judged if j.goes_with_speech(cfg)), key=lambda j: -(j.timing or 0.0))
    if not fits:
        moving = [j.person for j in judged if j.moves(cfg)]
        if moving:
            return _unknown(f"mouths moved ({', '.join(moving)}) but not with the speech's timing")
        return _unknown("no mouth in view moved while the words were heard")
    best = fits[0]
    best_timing = best.timing or 0.0
    if len(fits) > 1:
        lead = best_timing - (fits[1].timing or 0.0)
        if lead < cfg.speaker_margin:
            return _unknown(
                f"{best.person} and {fits[1].person} both moved their mouths with the speech "
                f"(timing {best_timing:.2f} vs {fits[1].timing or 0.0:.2f}): cannot tell who spoke"
            )
        confidence = 0.5 + 0.5 * min(1.0, lead)
    else:
        confidence = 0.6 + 0.4 * min(1.0, best_timing)
    still = [j.person for j in judged if j is not best and not j.goes_with_speech(cfg)]
    return Speaker(
        person=best.person,
        confidence=round(confidence, 3),
        method="mouth_motion",
        reason=f"{best.person}'s mouth moved with the words ({_numbers(best)})"
        + (f"; not {', '.join(still)}" if still else ""),
    )


def _with_sound(t: Transcript, tracks: dict[str, Track], seen: list[Judged], cfg: SpeakerConfig) -> Speaker | None:
    """With the utterance's loudness and two or more mouths moving: the one that moves with the sound decides."""
    if t.loudness is None:
        return None
    by_person = {tr.person: tr for tr in tracks.values()}
    moving = [(j, sound_match(by_person[j.person], t.loudness, t.start, t.end)) for j in seen if j.moves(cfg)]
    return _by_sound(moving, cfg) if len(moving) > 1 else None


def attribute(
    t: Transcript,
    faces: Iterable[Faces],
    cfg: SpeakerConfig | None = None,
    engagement: EngagementConfig | None = None,
    persons: Sequence[Persons] = (),
) -> Speaker:
    """Who said `t`, from the faces around it (source time), with a confidence; unknown says why. `persons`: the
    `Persons` around it, whose depth positions tell the speaker's distance for `addressed`."""
    cfg = cfg or SpeakerConfig()
    samples = list(faces)
    tracks = tracks_of(samples)
    in_utterance = [s for s in samples if t.start <= s.stamp <= t.end]
    present = {f.id for s in in_utterance for f in s.faces}
    if not present:
        return _unknown("no face in view while the words were heard")
    stream_frames = max(
        _frames_in(sorted({s.stamp for s in in_utterance if s.cam == cam}), t.start, t.end)
        for cam in {s.cam for s in in_utterance}
    )
    judged = [judge(tracks[p], t.start, t.end, stream_frames, cfg) for p in sorted(present)]
    seen = [j for j in judged if j.during is not None]
    if len(present) == 1:
        speaker = _only_face(judged[0], cfg)
    elif not seen:
        rate = stream_frames / max(t.end - t.start, 1e-3)
        speaker = _unknown(
            f"{len(present)} faces in view, no mouth seen well enough (faces at {rate:.0f} frames/s, "
            f"{cfg.speaker_min_rate:g} needed)"
        )
    else:
        speaker = _with_sound(t, {f: tracks[f] for f in present}, seen, cfg) or _several(seen, cfg)
    if speaker.person is not None:
        speaker.addressed = addressed(samples, speaker.person, t, engagement, persons)
    return speaker


class FaceHistory:
    """Fusion's buffer of Faces samples (every camera), pruned to `horizon` s of source time behind the newest.
    A sample older than that is dropped (`add` returns False) unless `reset_after` such come in a row: then the
    timeline went back (a replay restarted) and the buffer starts over; one stray stamp never wipes it."""

    def __init__(self, horizon: float, reset_after: int = 10):
        self.horizon = horizon
        self.reset_after = reset_after
        self.samples: deque[Faces] = deque()
        self.newest: float | None = None
        self.stale_in_a_row = 0

    def add(self, sample: Faces) -> bool:
        if self.newest is not None and sample.stamp < self.newest - self.horizon:
            self.stale_in_a_row += 1
            if self.stale_in_a_row < self.reset_after:
                return False
            self.samples.clear()
            self.newest = None
        self.stale_in_a_row = 0
        self.newest = sample.stamp if self.newest is None else max(self.newest, sample.stamp)
        self.samples.append(sample)
        while self.samples and self.samples[0].stamp < self.newest - self.horizon:
            self.samples.popleft()
        return True

    def around(self, lo: float, hi: float) -> list[Faces]:
        return [s for s in self.samples if lo <= s.stamp <= hi]

    def __len__(self) -> int:
        return len(self.samples)

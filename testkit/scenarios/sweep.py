"""The seeded sweep of degraded trials: two cups, one modality weakened at a time, with the right outcome.

Kinds:
- noisy speech: ASR heard the wrong colour, with low confidence; the person points clearly at the
  right object -> expected: the pointed object;
- dark frame: vision mislabels colours in a dark frame (the red cup comes out "blue" and vice
  versa); the person says "the red cup" and points at it -> expected: the pointed object;
- shaky gesture: clear speech names the object; a weak, wobbling ray points near the other one
  -> expected: the named object;
- clear gesture: "that cup" + a steady point -> the pointed object;
- clear both, disagreeing: says one, points at the other -> expected: a conflict question.

benchmarks/fusion_eval.py scores it with fixed and with adaptive weights; testkit/golden.py writes its outputs into
the golden net. Pure Python, seeded: the same seed gives the same trials on any machine.
"""

from __future__ import annotations

import random

from testkit.scenarios import DARK, Expect, Obj, Scenario, by_time, pointing, say, scene

COLORS = ("red", "blue", "green", "yellow")
KINDS = ("noisy speech", "dark frame", "shaky gesture", "clear gesture", "clear both, disagreeing")


def two_cups(rng: random.Random) -> tuple[Obj, Obj]:
    ca, cb = rng.sample(COLORS, 2)
    xa = rng.uniform(80, 260)
    xb = rng.uniform(380, 560)
    y = rng.uniform(200, 330)
    a = Obj("cup_a", "cup", ca, (xa, y), score=rng.uniform(0.75, 0.95))
    b = Obj("cup_b", "cup", cb, (xb, y + rng.uniform(-40, 40)), score=rng.uniform(0.75, 0.95))
    return a, b


def cmd(target: str) -> Expect:
    return Expect("command", intent="pick_up", target=target)


def trial(kind: str, rng: random.Random) -> Scenario:
    a, b = two_cups(rng)
    truth, other = (a, b) if rng.random() < 0.5 else (b, a)
    if kind == "noisy speech":
        steps = scene([a, b]) + pointing(truth.center)
        steps.append(say(0.0, 1.5, f"pick up the {other.color} cup", conf=rng.uniform(0.3, 0.5)))
        expect = [cmd(truth.id)]
    elif kind == "dark frame":
        swapped = [Obj(o.id, o.label, (b.color if o is a else a.color), o.center, o.size, o.score) for o in (a, b)]
        steps = scene(swapped, quality=DARK) + pointing(truth.center)
        steps.append(say(0.0, 1.5, f"pick up the {truth.color} cup", conf=rng.uniform(0.8, 0.95)))
        expect = [cmd(truth.id)]
    elif kind == "shaky gesture":
        steps = scene([a, b]) + pointing(
            other.center, jitter_deg=rng.uniform(12, 25), score=rng.uniform(0.4, 0.7), ray_conf=rng.uniform(0.4, 0.7)
        )
        steps.append(say(0.0, 1.5, f"pick up the {truth.color} cup", conf=rng.uniform(0.85, 0.97)))
        expect = [cmd(truth.id)]
    elif kind == "clear gesture":
        steps = scene([a, b]) + pointing(truth.center)
        steps.append(say(0.0, 1.5, "pick up that cup", conf=rng.uniform(0.8, 0.97)))
        expect = [cmd(truth.id)]
    elif kind == "clear both, disagreeing":
        steps = scene([a, b]) + pointing(other.center)
        steps.append(say(0.0, 1.5, f"pick up the {truth.color} cup", conf=rng.uniform(0.85, 0.97)))
        expect = [Expect("clarification", reason="conflict")]
    else:
        raise ValueError(kind)
    return Scenario(f"{kind} #{rng.random():.6f}", by_time(steps), expect, (kind,))


def degraded_sweep(seed: int = 1, trials: int = 40) -> list[Scenario]:
    """`trials` trials of every kind, kind by kind, from one generator seeded with `seed`."""
    rng = random.Random(seed)
    return [trial(kind, rng) for kind in KINDS for _ in range(trials)]

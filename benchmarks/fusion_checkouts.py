"""Fusion's decision latency in whichever checkout is the working directory: two checkouts compared side by side.

The core path of `benchmarks/fusion.py`'s `decision_latency` (one FusionCore for all decisions, as the service runs
one; the Detections sample that closes the window -> join -> grounding -> FusedCommand -> encoded bytes), written
against the parts of the code every checkout since relations has (FusionCore, testkit.scenarios), so the same
loop times an older tree and a newer one. Run it from each checkout's root in turn, alternating, in one shell loop:

    for round in 1 2; do for tree in /work/main .; do
        (cd $tree && python /path/to/benchmarks/fusion_checkouts.py 1000 200); done; done

CPU time of the process (time.process_time) and wall time per decision, p50 / p99, plain phrase and relation.
"""

from __future__ import annotations

import gc
import os
import sys
import time

sys.path.insert(0, os.getcwd())  # the checkout being measured, ahead of any installed copy

from common.codec import encode  # noqa: E402
from common.schema import FusedCommand  # noqa: E402
from services.fusion import ground  # noqa: E402
from services.fusion.core import Config, FusionCore  # noqa: E402
from testkit.scenarios import BASE_STAMP, Obj, deliver, hands, say, see  # noqa: E402

COLORS = ("red", "blue", "green", "yellow", "orange", "purple")
PLAIN = "pick up that red cup"
RELATION = "pick up that red cup next to the bowl"


def objects(n: int, bowls: bool) -> list[Obj]:
    """The scene of benchmarks/fusion.py (`objects`), repeated here so that an older checkout gets the same one."""
    out = []
    for i in range(n):
        label = "bowl" if bowls and i % 7 == 0 else "cup" if i % 3 else "candy"
        xy = (float(20 + (i * 37) % 600), float(40 + (i * 53) % 400))
        out.append(Obj(f"o{i}", label, COLORS[i % len(COLORS)], xy, (20.0, 20.0), 0.5 + (i % 50) / 100))
    out.append(Obj("target", "cup", "red", (500.0, 120.0), (50.0, 60.0), 0.95))
    if bowls:
        out.append(Obj("target_bowl", "bowl", "white", (560.0, 125.0), (60.0, 40.0), 0.95))
    return out


def pct(values: list[float], p: float) -> float:
    values = sorted(values)
    return values[min(len(values) - 1, int(round(p / 100 * (len(values) - 1))))]


def decisions(n: int, reps: int, text: str) -> tuple[list[float], list[float]]:
    """(CPU ms, wall ms) of each decision."""
    objs = objects(n, bowls=text == RELATION)
    core = FusionCore(Config(), "fusion/bench")
    for m in ("vision", "gesture"):
        core.on_liveliness(m, "bench", True)
    cpu, wall = [], []
    for r in range(reps):
        base, now = BASE_STAMP + r * 100, 1000.0 + r * 100
        for t in (-0.5, 0.5, 1.0):
            deliver(core, *see(t, objs).build(base), now)
        for i in range(20):
            deliver(core, *hands(-0.5 + i * 0.1, point_at=(500.0, 120.0)).build(base), now)
        deliver(core, *say(0.0, 1.4, text).build(base), now)
        core.tick(now)
        deliver(core, *hands(2.0).build(base), now)
        closing = see(2.0, objs).build(base)
        w0, c0 = time.perf_counter(), time.process_time()
        deliver(core, *closing, now)
        outs = core.tick(now)
        encode(outs[0].sample)
        cpu.append((time.process_time() - c0) * 1000)
        wall.append((time.perf_counter() - w0) * 1000)
        fused = outs[0].sample
        assert isinstance(fused, FusedCommand) and fused.target is not None and fused.target.id == "target", fused
    return cpu, wall


def main() -> None:
    n, reps = (int(a) for a in sys.argv[1:3]) if len(sys.argv) > 2 else (1000, 200)
    tree = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(ground.__file__))))
    gc.freeze()  # as the fusion service does after start-up, where it does (and harmless where it does not)
    for text in (PLAIN, RELATION):
        cpu, wall = decisions(n, reps, text)
        print(
            f"{tree} {n:5d} {'relation' if text == RELATION else 'plain   '} {reps} decisions: "
            f"cpu p50 {pct(cpu, 50):6.2f} p99 {pct(cpu, 99):6.2f} | wall p50 {pct(wall, 50):6.2f} "
            f"p99 {pct(wall, 99):6.2f} ms",
            flush=True,
        )


if __name__ == "__main__":
    main()

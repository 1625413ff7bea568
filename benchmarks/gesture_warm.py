"""New cameras through the real gesture process (issue #41, warm start): each of the 27 real hand photos
(testkit/gesture_photos.py) shown as its own camera for `--seconds` at `--fps`, one camera after the other, published
over Zenoh as JPEG Frames stamped now; counts the frames gesture answered (a Hands sample of that frame's seq) and
skipped, and judges the gesture that started on each camera as tests/test_gesture_photos.py does. The photos of the
held-back split (issue #41's brief) are counted apart.

`--checkout DIR` runs the gesture service of another checkout (e.g. `git archive main | tar -x -C /tmp/before`), to
measure before and after with the same script; `--gesture-args` passes flags (e.g. "--spare-graphs 1").

Usage: python benchmarks/gesture_warm.py [--seconds 1] [--fps 10] [--checkout DIR] [--gesture-args '...']
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

import cv2

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # this checkout's testkit, when run as `python benchmarks/gesture_warm.py`

from common.schema import Frame, GestureEvent, Hands  # noqa: E402
from testkit.gesture_photos import HAND_PHOTOS_27, judge, photo_path  # noqa: E402
from testkit.harness import Client, Proc, ProcessGroup  # noqa: E402
from testkit.images import read_image  # noqa: E402

HELD_BACK = {"lowcam_man_image7_right_arm_to_floor.jpeg", "room_woman_0219_t6_left_arm_to_image_right.png"}
TAIL_S = 3.0  # after the last camera: answers still on their way


def jpeg_frame(jpeg: bytes, width: int, height: int, seq: int, cam: str) -> Frame:
    return Frame(
        stamp=time.time(), source="camera/bench", seq=seq, cam=cam, width=width, height=height, encoding="jpeg",
        data=jpeg,
    )  # fmt: skip


def gesture_proc(group: ProcessGroup, checkout: Path, extra: list[str]) -> Proc:
    """The gesture service of `checkout` on the group's router."""
    code = (
        f"import sys, runpy; sys.path.insert(0, {str(checkout)!r}); "
        "runpy.run_module('services.gesture', run_name='__main__')"
    )
    proc = Proc("gesture", [sys.executable, "-c", code, "--connect", group.endpoint, *extra])
    group.procs.append(proc)
    return proc


def show_cameras(client: Client, photos: list, seconds: float, fps: float) -> None:
    frames = round(seconds * fps)
    for k, (where, name, _, _) in enumerate(photos):
        img = read_image(str(photo_path(where, name)))
        ok, jpeg = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 90])
        assert ok
        cam = f"photo{k:02d}"
        start = time.monotonic()
        for seq in range(frames):
            time.sleep(max(0.0, start + seq / fps - time.monotonic()))
            client.publish(f"hri/camera/{cam}/frame", jpeg_frame(jpeg.tobytes(), img.shape[1], img.shape[0], seq, cam))
        time.sleep(max(0.0, start + frames / fps - time.monotonic()))


def run(args: argparse.Namespace) -> None:
    photos = [p for p in HAND_PHOTOS_27 if photo_path(p[0], p[1]).exists()]
    group = ProcessGroup()
    try:
        group.router()
        started = time.monotonic()
        gesture_proc(group, Path(args.checkout).resolve(), shlex.split(args.gesture_args))
        client = Client(group.endpoint)
        client.wait_alive("gesture", timeout=120)
        print(f"gesture live after {time.monotonic() - started:.1f} s (graphs built before: see its log)")
        hands, events = client.collect("hri/gesture/*/hands"), client.collect("hri/gesture/*/event")
        client.wait_matched(["hri/camera/photo00/frame"])
        show_cameras(client, photos, args.seconds, args.fps)
        hands.drain(TAIL_S)
        events.drain(0.0)
        stats = client.stats("gesture")
        client.close()
    finally:
        group.close()
    report(photos, hands.seen, events.seen, round(args.seconds * args.fps), stats)


def report(photos: list, hands: list, events: list, frames: int, stats: dict) -> None:
    answered: dict[str, set[int]] = {}
    for _, h in hands:
        assert isinstance(h, Hands)
        answered.setdefault(h.cam, set()).add(h.seq)
    totals = {"dev": [0, 0, 0, 0], "held back": [0, 0, 0, 0]}  # cameras, frames answered, first frame answered, right
    for k, (_, name, expected, side) in enumerate(photos):
        cam = f"photo{k:02d}"
        mine = [e for _, e in events if isinstance(e, GestureEvent) and e.cam == cam]
        starts: list[tuple[str, str]] = [(e.gesture, e.hand) for e in mine if e.phase == "start"]
        right = judge(starts, expected, side)["right"]
        got = answered.get(cam, set())
        split = "held back" if name in HELD_BACK else "dev"
        for i, v in enumerate((1, len(got), 0 in got, right)):
            totals[split][i] += int(v)
        first, verdict = "yes" if 0 in got else "no", "right" if right else "WRONG"
        print(f"{cam} {name[:44]:44} answered {len(got):2}/{frames} first {first:3} {verdict} {starts}")
    for split, (cams, n_got, n_first, n_right) in totals.items():
        print(
            f"{split}: {cams} cameras, frames answered {n_got}/{cams * frames} (skipped {cams * frames - n_got}), "
            f"first frame answered on {n_first}, gesture right on {n_right}"
        )
    print("gesture stats:", {k: v for k, v in stats.items() if k in ("received", "published", "skipped", "other")})


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=1.0, help="how long each photo is shown as its camera")
    p.add_argument("--fps", type=float, default=10.0)
    p.add_argument("--checkout", default=str(ROOT), help="the checkout whose gesture service runs")
    p.add_argument("--gesture-args", default="", help="flags for the gesture service")
    run(p.parse_args())


if __name__ == "__main__":
    main()

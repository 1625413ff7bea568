"""Pointing in metres: what the 3-D ray costs and buys.

1. Cost: the gesture service's 3-D step per pointing frame (decode the DepthFrame, lift the ray, fit the planes near
   it, meet them: `depth_view` + `FrameRays.arm`) on the real RGB-D frames of ../shared/data/rgbd (YCB-Video
   640x480, RealSense 1280x720), beside the bare decode (`common.depth.depth_metres`) of the same frame; and the
   step done on every frame where a body is seen (issue #31: decode + lift the 33 landmarks, `lift_pose`).
2. Hit accuracy on those frames: rays from a virtual eye 0.4 m above the camera to table pixels spread over the
   table; the distance from the hit to the pixel's own back-projected depth (an independent reading).
3. Grounding: random rooms (2-6 objects 1-3 m from a person at 2.5-3.5 m from the camera, f 600 px, 640x480), the
   person points at one with a Gaussian angular error; how often the object pointed at wins by the gesture alone,
   in 2-D (the image: today without depth) and in 3-D (fusion with depth).

Usage: python benchmarks/pointing_3d.py [--rooms 2000] [--noise 3] [--repeats 20]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import cv2
import numpy as np

from common.depth import depth_frame, depth_metres
from common.schema import (
    CameraInfo,
    DetectedObject,
    Detections,
    Hand,
    Hands,
    ImageQuality,
    Ray,
    Ray3D,
)
from services.fusion.evidence import pointing_from_hands, select_pointing
from services.fusion.ground import best_pointed, scene_objects
from services.gesture.space import DepthView, FrameRays, Lifted, depth_view, lift_pose, surface_hit
from testkit.images import read_image
from testkit.shared import shared_dir

SHARED = shared_dir() / "data" / "rgbd"  # $HRI_SHARED, else ../shared beside the checkout


def real_frames() -> list[tuple[str, np.ndarray, CameraInfo, float, list[tuple[int, int]]]]:
    """(name, depth units, intrinsics, scale, table pixels) of the real RGB-D frames that are present."""
    out = []
    ycb = SHARED / "ycb_video" / "000002-depth.png"
    if ycb.exists():
        info = CameraInfo(
            width=640, height=480, k=[1066.778, 0, 312.9869, 0, 1067.487, 241.3109, 0, 0, 1], frame_id="ycb"
        )
        out.append(
            (
                "YCB-Video 640x480",
                read_image(str(ycb), cv2.IMREAD_UNCHANGED),
                info,
                1e-4,
                [(600, 440), (60, 420), (560, 330), (120, 300), (400, 400), (500, 460), (20, 470)],
            )
        )
    rs = SHARED / "realsense_tabletop" / "realsense_frame.npz"
    if rs.exists():
        data = np.load(rs)
        fx, fy, cx, cy = (float(v) for v in data["intrinsics"])
        info = CameraInfo(width=1280, height=720, k=[fx, 0, cx, 0, fy, cy, 0, 0, 1], frame_id="rs")
        out.append(
            (
                "RealSense 1280x720",
                data["depth"].reshape(720, 1280),
                info,
                1e-3,
                [(1000, 400), (200, 500), (900, 600), (150, 150), (1200, 100), (700, 300), (300, 650)],
            )
        )
    return out


def known_depth(view: DepthView, px: tuple[int, int]) -> float:
    """The depth at a pixel the benchmark chose where the camera has depth."""
    z = view.depth_at(*px)
    assert z is not None, f"no depth at {px}"
    return z


def pose_towards(view: DepthView, eye: np.ndarray, target_px: tuple[int, int]) -> np.ndarray:
    """A 33x3 skeleton whose eyes and index fingertip, lifted with this depth, line up towards `target_px`: the eyes
    and fingertip pixels are painted into the depth at their 3-D distance (the cost of lifting is the same)."""
    target = view.back_project(*target_px, known_depth(view, target_px))
    tip = eye + 0.4 * (target - eye)  # these cameras are 0.5-1 m from the table: a short "arm"
    pose = np.zeros((33, 3))
    for i, p in ((2, eye), (5, eye), (20, tip)):
        u, v = view.project(p)
        pose[i] = [u, v, 0.99]
        cv2.circle(view.metres, (int(round(u)), int(round(v))), 6, float(p[2]), -1)
    return pose


def cost(repeats: int) -> None:
    print("1. cost per pointing frame (ms, median of runs; 2 shared cores, other work running: noisy)")
    for name, units, info, scale, pixels in real_frames():
        msg = depth_frame(units, stamp=1.0, source="bench", seq=0, cam="cam", depth_scale=scale, camera_info=info)
        eye = np.array([0.0, -0.08, 0.45]) if info.width == 640 else np.array([0.0, -0.05, 0.12])  # in view
        bare, full, cpu, body = [], [], [], []
        skeleton = np.column_stack(  # 33 visible landmarks spread over the image
            [np.linspace(0.1, 0.9, 33) * info.width, np.linspace(0.2, 0.8, 33) * info.height, np.ones(33)]
        )
        for r in range(repeats):
            t0 = time.perf_counter()
            lift_pose(depth_view(msg), skeleton)
            body.append((time.perf_counter() - t0) * 1e3)
            t0 = time.perf_counter()
            depth_metres(msg)
            t1 = time.perf_counter()
            c1 = time.process_time()
            view = depth_view(msg)
            pose = pose_towards(view, eye, pixels[r % len(pixels)])
            ray = FrameRays(view, pose, None).arm("right")
            t2 = time.perf_counter()
            cpu.append((time.process_time() - c1) * 1e3)
            assert ray is not None and ray.hit is not None, name
            bare.append((t1 - t0) * 1e3)
            full.append((t2 - t1) * 1e3)
        print(
            f"   {name}: decode {statistics.median(bare):.1f} ms; decode + lift + planes + hit "
            f"{statistics.median(full):.1f} ms wall (p90 {sorted(full)[int(0.9 * len(full))]:.1f}), "
            f"{statistics.median(cpu):.1f} ms CPU (numpy may use both cores); every frame with a body: decode + "
            f"lift_pose {statistics.median(body):.1f} ms"
        )


def accuracy() -> None:
    print("2. hit vs the depth's own point at the table pixel pointed at (cm)")
    for name, units, info, scale, pixels in real_frames():
        view = DepthView(units.astype(np.float32) * scale, info.fx, info.fy, info.cx, info.cy, info.frame_id)
        eye = np.array([0.1, -0.4, 0.1])
        errors = []
        for px in pixels:
            measured = view.back_project(*px, known_depth(view, px))
            d = (measured - eye) / np.linalg.norm(measured - eye)
            hit = surface_hit(view, Lifted(eye, d, "eye_fingertip", 0.3))
            errors.append(float("nan") if hit is None else float(np.linalg.norm(hit - measured)) * 100)
        print(f"   {name}: {len(errors)} pixels, median {statistics.median(errors):.2f} cm, max {max(errors):.2f} cm")


F, CX, CY, W, H = 600.0, 320.0, 240.0, 640, 480


def project(p: np.ndarray) -> np.ndarray:
    return np.array([p[0] * F / p[2] + CX, p[1] * F / p[2] + CY])


def grounding(rooms: int, noise_deg: float, seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    right = {"2-D": 0, "3-D": 0}
    disagree = 0
    done = 0
    while done < rooms:
        eyes = np.array([rng.uniform(-0.8, 0.8), rng.uniform(-0.7, -0.4), rng.uniform(2.5, 3.5)])
        n = int(rng.integers(2, 7))
        objects = []
        for i in range(n):
            for _ in range(100):  # somewhere in view, 1-3 m from the person, in front of the camera
                p = np.array([rng.uniform(-1.5, 1.5), rng.uniform(-0.3, 0.7), rng.uniform(0.8, 4.5)])
                u, v = project(p)
                if 1.0 <= np.linalg.norm(p - eyes) <= 3.0 and 20 <= u < W - 20 and 20 <= v < H - 20:
                    break
            else:
                break
            size = rng.uniform(0.06, 0.25)
            w, h = size * F / p[2], size * 1.5 * F / p[2]
            c = project(p)
            objects.append(
                DetectedObject(
                    id=f"o{i}",
                    label="bottle",
                    score=0.9,
                    bbox=[c[0] - w / 2, c[1] - h / 2, w, h],
                    center=c.tolist(),
                    position=p.tolist(),
                    extent=[size, size * 1.5, size],
                )
            )
        if len(objects) < 2:
            continue
        k = int(rng.integers(0, len(objects)))
        d = np.array(objects[k].position) - eyes
        d /= np.linalg.norm(d)
        # angular error: rotate about a random axis perpendicular to d
        axis = np.cross(d, rng.normal(size=3))
        axis /= np.linalg.norm(axis)
        a = math.radians(rng.normal(0.0, noise_deg))
        d = d * math.cos(a) + np.cross(axis, d) * math.sin(a) + axis * (axis @ d) * (1 - math.cos(a))
        tip = eyes + 0.7 * d
        tip_px, eye_px = project(tip), project(eyes)
        d2 = (tip_px - eye_px) / np.linalg.norm(tip_px - eye_px)
        hand = Hand(
            hand="right",
            score=0.95,
            landmarks=[tip_px.tolist()] * 21,
            gesture="point",
            ray=Ray(
                origin=tip_px.tolist(),
                direction=d2.tolist(),
                confidence=0.9,
                source="body",
                ray3d=Ray3D(
                    origin=eyes.tolist(),
                    direction=(d / np.linalg.norm(d)).tolist(),
                    method="eye_fingertip",
                    frame_id="cam",
                ),
            ),
        )
        pointing = select_pointing(
            pointing_from_hands(Hands(stamp=1.0, source="b", seq=0, cam="cam0", width=W, height=H, hands=[hand])), 1.0
        )
        assert pointing is not None
        picks = {}
        for mode in ("2-D", "3-D"):
            objs = (
                objects
                if mode == "3-D"
                else [
                    DetectedObject(id=o.id, label=o.label, score=o.score, bbox=o.bbox, center=o.center) for o in objects
                ]
            )
            det = Detections(
                stamp=1.0,
                source="b",
                seq=0,
                cam="cam0",
                width=W,
                height=H,
                objects=objs,
                quality=ImageQuality(brightness=0.5, contrast=0.5, sharpness=0.5),
                frame_id="cam" if mode == "3-D" else None,
            )
            best = best_pointed(pointing, scene_objects([det]))
            assert best is not None
            picks[mode] = best.obj.id
            right[mode] += picks[mode] == objects[k].id
        disagree += picks["2-D"] != picks["3-D"]
        done += 1
    print(
        f"3. grounding by the gesture alone, {rooms} random rooms, {noise_deg:g}° pointing error (seed {seed}): "
        f"2-D {100 * right['2-D'] / rooms:.1f} %, 3-D {100 * right['3-D'] / rooms:.1f} % right; "
        f"they disagree in {100 * disagree / rooms:.1f} %"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rooms", type=int, default=2000)
    parser.add_argument("--noise", type=float, default=3.0, help="pointing error, degrees (std)")
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    if not real_frames():
        print(f"(no real RGB-D frames under {SHARED}: parts 1 and 2 skipped)")
    else:
        cost(args.repeats)
        accuracy()
    grounding(args.rooms, args.noise)


if __name__ == "__main__":
    main()

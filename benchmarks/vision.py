"""Vision: the service's detection paths vs the bare libraries doing the same work, one run.

Colour backend:
1. Throughput on the same 640x480 frames (the shipped photos, resized):
   - bare: blur, HSV, one mask per palette colour plus black and white, open/close, connected components,
     bounding boxes — plain OpenCV;
   - service path: JPEG decode is excluded from both; VisionPipeline.process = the same segmentation plus
     colour naming, background and sliver rules, tracking, image quality and building the contract objects.
2. End-to-end lag at 30 fps input: camera-like publisher -> router -> vision service -> subscriber; lag =
   receive time - frame stamp, p50/p99 per 10 s slice over 60 s (it must not grow).

ONNX backend (the real YOLOX-Nano model, --model or $HRI_YOLOX_MODEL or ../shared/models/yolox_nano.onnx):
3. Throughput on the same 640x480 frames:
   - bare: an onnxruntime session and a plain loop: top-left letterbox to 416 (BGR, 0-255), run, YOLOX grid
     decoding (rows with objectness < 0.3 skipped first), objectness x class score >= 0.3,
     cv2.dnn.NMSBoxesBatched at IoU 0.45;
   - service path: VisionPipeline(YoloDetector).process = the same plus labels through the language, each
     object's colour from its own pixels (reused for a still object: colour_memory.py; also shown measured on
     every frame), tracking, image quality and the contract objects.
   On two sequences: the photos, a new scene every frame (every colour measured), and the first --frames frames
   of a real clip in order (talking/real_single_vr1_cfr25.mp4: a camera's consecutive frames).
4. The colour step's cost per frame beside the detector's: on the same frames, the detector alone
   (YoloDetector.detect) and the colour model alone on its boxes (one illuminant estimate per frame, then
   each box's own pixels measured and named: core.object_colour), median ms per frame.
5. End-to-end lag at 30 fps for 60 s through `python -m services.vision --backend onnx --model ...`: the model
   runs slower than 30 fps here, so the service must drop to the latest frame (counted as skipped), not queue.
Target for 1 and 3: service >= 0.9x the bare loop's frames/s.

Depth (the real YCB-Video RGB-D frames of ../shared/data/rgbd/ycb_video, 640x480, colour backend):
5. Throughput of VisionPipeline.process colour only vs with the aligned depth (positions for every object),
   the depth decoded from a raw 16UC1 DepthFrame and from a PNG one, interleaved on the same frames.
   Target: with depth >= 0.9x colour only.
6. End-to-end lag at 30 fps with depth: colour + depth frames of each capture published like the camera does
   (depth first, both latest-only) into a real vision process for --seconds; lag per slice must stay flat.

Usage: python benchmarks/vision.py [--seconds 60] [--frames 300] [--backends color,onnx,depth] [--model PATH]
       [--fps 30] [--skip-lag] [--colour-only]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import cv2
import numpy as np

from common.codec import decode
from common.depth import depth_frame
from common.runner import SamplePublisher
from common.schema import CameraInfo, Detections, Frame
from services.vision.color import CHROMATIC, HUE_RANGES, illuminant_gains
from services.vision.core import VisionPipeline, object_colour
from services.vision.depth import DepthImage
from services.vision.segment import ColorSegmenter
from services.vision.yolo import YoloDetector
from testkit.frames import read_frames
from testkit.harness import DATA, Client, ProcessGroup
from testkit.images import read_image
from testkit.lag import frame_lag, print_lag_slices, print_throughput
from testkit.shared import shared_dir


def frames_640() -> list[np.ndarray]:
    paths = sorted((DATA / "images" / "tabletop").iterdir()) + sorted((DATA / "demo").glob("*.png"))
    return [cv2.resize(read_image(str(p)), (640, 480)) for p in paths]


def hue_lut() -> np.ndarray:
    lut = np.zeros(256, np.uint8)
    for k, name in enumerate(CHROMATIC):
        for lo, hi in HUE_RANGES[name]:
            lut[lo:hi] = k + 1
    return lut


def bare_segmentation(bgr: np.ndarray, kernel: np.ndarray, lut: np.ndarray) -> list[tuple[int, int, int, int]]:
    """The same masks as the colour backend (one per palette colour, then black and white), plain OpenCV."""
    hsv = cv2.cvtColor(cv2.GaussianBlur(bgr, (5, 5), 0), cv2.COLOR_BGR2HSV)
    index = cv2.bitwise_and(cv2.LUT(hsv[..., 0], lut), cv2.inRange(hsv, (0, 100, 75), (180, 255, 255)))
    masks = [cv2.inRange(index, k, k) for k in range(1, len(CHROMATIC) + 1)]
    masks += [cv2.inRange(hsv, (0, 0, 0), (180, 255, 74)), cv2.inRange(hsv, (0, 0, 180), (180, 59, 255))]
    boxes = []
    for m in masks:
        m = cv2.morphologyEx(m, cv2.MORPH_OPEN, kernel)
        m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, kernel)
        n, _, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
        boxes += [(int(x), int(y), int(w), int(h)) for x, y, w, h, area in stats[1:n] if area > 460]
    return boxes


def interleaved(
    loops: list, frames: list[np.ndarray], n: int, chunk: int = 20, cpu_ms: list[list[float]] | None = None
) -> list[list[float]]:
    """frames/s of each loop, per round: every round runs each loop on the same `chunk` frames in turn, so the
    load of a shared machine (it changes by the second) hits all loops alike, in an order rotated every round.
    n frames per loop in all (a stateful loop, the service's pipeline, sees the frames in order).
    `cpu_ms`, when given, gets each loop's CPU time per frame per round (all the process's threads, ms): on a
    machine shared with other users' work it moves far less than the wall clock."""
    fps: list[list[float]] = [[] for _ in loops]
    cpu: list[list[float]] = [[] for _ in loops]
    for start in range(0, n, chunk):
        batch = [frames[i % len(frames)] for i in range(start, start + chunk)]
        first = (start // chunk) % len(loops)  # each round starts with the next loop: no loop always runs first
        for k in [*range(first, len(loops)), *range(first)]:
            loop = loops[k]
            t0, c0 = time.perf_counter(), time.process_time()
            for f in batch:
                loop(f)
            fps[k].append(chunk / (time.perf_counter() - t0))
            cpu[k].append((time.process_time() - c0) * 1e3 / chunk)
    if cpu_ms is not None:
        cpu_ms.extend(cpu)
    return fps


def print_cpu(labels: list[str], cpu_ms: list[list[float]]) -> None:
    """Median CPU ms per frame of each loop, and the median over rounds of the first loop's CPU time over each
    other's in the same round (the ratio of the frame rates one core would give; a round's ratio cancels the
    load's drift between rounds)."""
    for label, ms in zip(labels, cpu_ms):
        ratio = statistics.median(f / m for f, m in zip(cpu_ms[0], ms))
        print(f"  CPU {label:28s} {statistics.median(ms):7.2f} ms per frame   ratio {ratio:.2f}x")


def throughput(frames: list[np.ndarray], n: int) -> None:
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    lut = hue_lut()
    pipeline = VisionPipeline(ColorSegmenter())
    bare_fps, service_fps = interleaved(
        [lambda f: bare_segmentation(f, kernel, lut), lambda f: pipeline.process("cam0", f)], frames, n
    )
    print_throughput(
        f"throughput on {n} frames 640x480, rounds of 20",
        "bare OpenCV segmentation",
        bare_fps,
        "vision service path",
        service_fps,
    )


def onnx_frames() -> list[np.ndarray]:
    """Photos with things a COCO detector knows (a cup, a player and a ball, fruit), 640x480."""
    names = [
        "coffee.png",
        "messi5.jpg",
        "apple.jpg",
        "tabletop/fruits.jpg",
        "tabletop/smarties.png",
        "tabletop/stuff.jpg",
    ]
    return [cv2.resize(read_image(str(DATA / "images" / n)), (640, 480)) for n in names]


class BareYolox:
    """onnxruntime and a plain numpy/OpenCV loop: the same pre- and post-processing as the service's YOLOX path."""

    def __init__(self, model: str, size: int = 416, conf: float = 0.3, iou: float = 0.45, spinning: bool = False):
        import onnxruntime as ort

        options = ort.SessionOptions()
        if not spinning:  # the service's session option; onnxruntime's default spins between runs
            options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        self.session = ort.InferenceSession(model, options, providers=["CPUExecutionProvider"])
        self.size, self.conf, self.iou = size, conf, iou
        grids = []
        for s in (8, 16, 32):
            gy, gx = np.mgrid[0 : size // s, 0 : size // s]
            grids.append(np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, s)], 1))
        self.grid = np.concatenate(grids).astype(np.float32)

    def detect(self, bgr: np.ndarray) -> list:
        h, w = bgr.shape[:2]
        r = min(self.size / h, self.size / w)
        canvas = np.full((self.size, self.size, 3), 114, np.uint8)
        canvas[: int(h * r), : int(w * r)] = cv2.resize(bgr, (int(w * r), int(h * r)), interpolation=cv2.INTER_LINEAR)
        out = self.session.run(None, {"images": canvas.transpose(2, 0, 1)[None].astype(np.float32)})[0][0]
        sel = out[:, 4] >= self.conf  # objectness first: obj × cls cannot exceed obj
        out, g = out[sel], self.grid[sel]
        scores = out[:, 5:] * out[:, 4:5]
        cls, conf = scores.argmax(1), scores.max(1)
        keep = conf >= self.conf
        cx, cy = (out[keep, 0] + g[keep, 0]) * g[keep, 2], (out[keep, 1] + g[keep, 1]) * g[keep, 2]
        bw, bh = np.exp(out[keep, 2]) * g[keep, 2], np.exp(out[keep, 3]) * g[keep, 2]
        boxes = np.stack([(cx - bw / 2) / r, (cy - bh / 2) / r, bw / r, bh / r], 1)
        idx = cv2.dnn.NMSBoxesBatched(boxes.tolist(), conf[keep].tolist(), cls[keep].tolist(), self.conf, self.iou)
        return [(int(cls[keep][i]), float(conf[keep][i]), boxes[i]) for i in np.array(idx).ravel()]


def clip_frames(n: int) -> list[np.ndarray]:
    """The first n frames of a real clip (a man talking at a desk, 700x700), cropped to 4:3 and resized to
    640x480, in order: what a camera sends (consecutive frames of one scene). Empty when ../shared is absent."""
    frames: list[np.ndarray] = []
    for frame in read_frames(shared_dir() / "data" / "talking" / "real_single_vr1_cfr25.mp4", n):
        h, w = frame.shape[:2]
        top = (h - w * 3 // 4) // 2
        frames.append(cv2.resize(frame[top : top + w * 3 // 4], (640, 480)))
    return frames


def onnx_throughput(model: str, frames: list[np.ndarray], n: int, what: str) -> None:
    """The service's onnx path (colour reused as shipped, and measured on every frame) vs the bare loop."""
    bare = BareYolox(model)
    detector = YoloDetector(model)
    pipeline, every_frame = VisionPipeline(detector), VisionPipeline(detector, colour_reuse_frames=0)
    for f in frames[:2]:  # warm the sessions up
        bare.detect(f)
        pipeline.process("cam0", f)
        every_frame.process("cam0", f)
    cpu: list[list[float]] = []
    bare_fps, service_fps, every_fps = interleaved(
        [bare.detect, lambda f: pipeline.process("cam0", f), lambda f: every_frame.process("cam0", f)],
        frames,
        n,
        cpu_ms=cpu,
    )
    print_throughput(
        f"onnx throughput on {n} {what}, rounds of 20",
        "bare onnxruntime YOLOX loop",
        bare_fps,
        "vision service onnx path",
        service_fps,
    )
    e = statistics.median(every_fps)
    print(
        f"  {'(colour on every frame)':32s} {e:7.1f} frames/s   ratio {e / statistics.median(bare_fps):.2f}x; "
        f"colours measured for {pipeline.colours['cam0'].measured} of {every_frame.colours['cam0'].measured} objects"
    )
    print_cpu(["bare", "service", "service, colour every frame"], cpu)


def spinning_throughput(model: str, frames: list[np.ndarray], n: int) -> None:
    """On its own: a spinning pool goes on burning CPU after its run and would slow whatever runs next."""
    bare_spinning = BareYolox(model, spinning=True)
    bare_spinning.detect(frames[0])
    (spinning_fps,) = interleaved([bare_spinning.detect], frames, n)
    print(f"  (bare loop with onnxruntime's default thread spinning: {statistics.median(spinning_fps):.1f} frames/s)")


def rgbd_frames() -> list[tuple[np.ndarray, np.ndarray]] | None:
    """The YCB-Video colour/depth pairs (640x480, 0.1 mm units), or None when ../shared is absent."""
    folder = shared_dir() / "data" / "rgbd" / "ycb_video"
    pairs = [
        (read_image(str(c)), read_image(str(c).replace("-color", "-depth"), cv2.IMREAD_UNCHANGED))
        for c in sorted(folder.glob("*-color.png"))
    ]
    return pairs or None


YCB_INFO = CameraInfo(
    width=640,
    height=480,
    k=[1066.778, 0.0, 312.9869, 0.0, 1067.487, 241.3109, 0.0, 0.0, 1.0],
    frame_id="ycb_camera_optical_frame",
)


def depth_throughput(pairs: list[tuple[np.ndarray, np.ndarray]], n: int) -> None:
    pipeline = VisionPipeline(ColorSegmenter())
    colours = [c for c, _ in pairs]
    raw = [
        depth_frame(d, stamp=1.0, source="bench/cam", seq=0, cam="bench", depth_scale=0.0001, camera_info=YCB_INFO)
        for _, d in pairs
    ]
    png = [
        depth_frame(
            d,
            stamp=1.0,
            source="bench/cam",
            seq=0,
            cam="bench",
            depth_scale=0.0001,
            camera_info=YCB_INFO,
            compression="png",
        )
        for _, d in pairs
    ]
    index = {id(c): i for i, c in enumerate(colours)}
    objects = sum(len(pipeline.process("bench", c)[0]) for c in colours) / len(colours)
    cpu: list[list[float]] = []
    colour_fps, raw_fps, png_fps = interleaved(
        [
            lambda c: pipeline.process("bench", c),
            lambda c: pipeline.process("bench", c, DepthImage.from_frame(raw[index[id(c)]])),
            lambda c: pipeline.process("bench", c, DepthImage.from_frame(png[index[id(c)]])),
        ],
        colours,
        n,
        cpu_ms=cpu,
    )
    print_throughput(
        f"depth: throughput on {n} YCB-Video RGB-D frames 640x480 ({objects:.0f} objects per frame "
        f"on average), rounds of 20",
        "colour only",
        colour_fps,
        "with depth (raw 16UC1)",
        raw_fps,
    )
    p = statistics.median(png_fps)
    print(
        f"  {'with depth (PNG, decode included)':32s} {p:7.1f} frames/s   ratio "
        f"{p / statistics.median(colour_fps):.2f}x"
    )
    print_cpu(["colour only", "with depth (raw 16UC1)", "with depth (PNG)"], cpu)


def rgbd_lag(pairs: list[tuple[np.ndarray, np.ndarray]], seconds: float, fps: float) -> None:
    """Colour + depth of each capture at `fps` into a real vision process; lag of its Detections."""
    group = ProcessGroup()
    group.router()
    group.service("vision")
    client = Client(group.endpoint)
    lags: list[tuple[float, float]] = []
    positioned = [0]
    start = time.time()

    def on_output(sample) -> None:
        out = decode(sample.payload.to_bytes(), Detections)
        now = time.time()
        lags.append((now - start, now - out.stamp))
        positioned[0] += out.frame_id is not None

    try:
        client.wait_alive("vision", timeout=90)
        sub = client.session.declare_subscriber("hri/vision/bench/objects", on_output)
        frame_pub = SamplePublisher(client.session, "hri/camera/bench/frame", lossless=False)
        depth_pub = SamplePublisher(client.session, "hri/camera/bench/depth", lossless=False)
        jpegs = [cv2.imencode(".jpg", c, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes() for c, _ in pairs]
        sent = 0
        start = time.time()
        next_at = time.monotonic()
        while time.time() - start < seconds:
            next_at += 1.0 / fps
            k = sent % len(pairs)
            stamp = time.time()
            depth_pub.put(
                depth_frame(
                    pairs[k][1],
                    stamp=stamp,
                    source="bench/cam",
                    seq=sent,
                    cam="bench",
                    depth_scale=0.0001,
                    camera_info=YCB_INFO,
                )
            )
            frame_pub.put(
                Frame(
                    stamp=stamp,
                    source="bench/cam",
                    seq=sent,
                    cam="bench",
                    width=640,
                    height=480,
                    encoding="jpeg",
                    data=jpegs[k],
                    camera_info=YCB_INFO,
                )
            )
            sent += 1
            delay = next_at - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        time.sleep(1.0)
        sub.undeclare()
        frame_pub.undeclare()
        depth_pub.undeclare()
        stats = client.stats("vision")
    finally:
        client.close()
        group.close()
    print(
        f"depth: end-to-end lag at {fps:.0f} fps with depth for {seconds:.0f} s: {sent} RGB-D captures sent, "
        f"{len(lags)} Detections received ({positioned[0]} with positions), {stats['skipped']} stale samples "
        f"skipped by the service"
    )
    print_lag_slices(lags, seconds)


def colour_cost(model: str, frames: list[np.ndarray], n: int) -> None:
    detector = YoloDetector(model)
    boxes = [[box for _, _, box in detector.detect(f)] for f in frames]

    def colour_step(i: int) -> None:
        gains = illuminant_gains(frames[i])
        for box in boxes[i]:
            object_colour(frames[i], box, gains)

    detect_ms, colour_ms = [], []
    for k in range(n):  # interleaved, so both see the same machine load
        i = k % len(frames)
        t0 = time.perf_counter()
        detector.detect(frames[i])
        t1 = time.perf_counter()
        colour_step(i)
        t2 = time.perf_counter()
        detect_ms.append((t1 - t0) * 1e3)
        colour_ms.append((t2 - t1) * 1e3)
    per_frame = sum(len(b) for b in boxes) / len(boxes)
    print(
        f"colour step vs detector on {n} frames 640x480 ({per_frame:.1f} objects per frame): detector "
        f"{statistics.median(detect_ms):.2f} ms, colour model {statistics.median(colour_ms):.3f} ms per frame "
        f"(p90 {np.percentile(colour_ms, 90):.3f} ms; "
        f"{100 * statistics.median(colour_ms) / statistics.median(detect_ms):.1f} % of the detector)"
    )


def default_model() -> str:
    return os.environ.get("HRI_YOLOX_MODEL") or str(shared_dir() / "models" / "yolox_nano.onnx")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=60.0, help="length of each lag run (default 60)")
    parser.add_argument("--frames", type=int, default=300, help="frames per throughput measurement (default 300)")
    parser.add_argument(
        "--backends", default="color,onnx,depth", help="which backends to measure (default color,onnx,depth)"
    )
    parser.add_argument("--model", default=default_model(), help="YOLOX ONNX model for the onnx backend")
    parser.add_argument("--fps", type=float, default=30.0, help="frame rate of the lag runs (default 30)")
    parser.add_argument("--skip-lag", action="store_true", help="throughput only")
    parser.add_argument("--colour-only", action="store_true", help="onnx: only the colour step's cost per frame")
    args = parser.parse_args()
    backends = args.backends.split(",")
    if "color" in backends:
        images = frames_640()
        throughput(images, args.frames)
        if not args.skip_lag:
            frame_lag("vision", [], "hri/vision/bench/objects", Detections, images, args.seconds, args.fps)
    if "depth" in backends:
        pairs = rgbd_frames()
        if pairs is None:
            print("depth: no RGB-D frames under ../shared/data/rgbd/ycb_video (set HRI_SHARED); skipped")
        else:
            depth_throughput(pairs, args.frames)
            if not args.skip_lag:
                rgbd_lag(pairs, args.seconds, args.fps)
    if "onnx" in backends:
        if not Path(args.model).is_file():
            print(f"onnx: no model at {args.model} (give --model or HRI_YOLOX_MODEL); skipped")
            return
        images = onnx_frames()
        colour_cost(args.model, images, args.frames)
        if args.colour_only:
            return
        onnx_throughput(args.model, images, args.frames, "photos 640x480 (a new scene every frame)")
        clip = clip_frames(args.frames)
        if clip:
            onnx_throughput(args.model, clip, args.frames, "frames of a real clip 640x480 (in order)")
        spinning_throughput(args.model, images, args.frames)
        if not args.skip_lag:
            frame_lag(
                "vision",
                ["--backend", "onnx", "--model", args.model],
                "hri/vision/bench/objects",
                Detections,
                images,
                args.seconds,
                args.fps,
            )


if __name__ == "__main__":
    main()

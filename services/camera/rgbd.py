"""RGB-D sources and intrinsics — no Zenoh here.

* A folder of colour/depth pairs (`000002-color.png` + `000002-depth.png`, …) with an `intrinsics.json`.
* An Intel RealSense through `pyrealsense2` (the optional extra `realsense`), depth aligned to colour.
* `--intrinsics FILE` gives any colour source (webcam, video, image folder) its intrinsics.

The intrinsics file (JSON; docs/vision.md "Depth"):

    {"width": 640, "height": 480,                  # the resolution K belongs to (required)
     "fx": 1066.778, "fy": 1067.487, "cx": 312.9869, "cy": 241.3109,   # or "K": 3×3 (nested or 9 row-major)
     "depth_scale": 0.0001,                        # metres per depth unit (required with 16-bit depth images)
     "frame_id": "camera_color_optical_frame",     # optional, this is the default
     "distortion_model": "none", "distortion": []} # optional (plumb_bob = OpenCV k1 k2 p1 p2 k3)
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import cv2
import msgspec
import numpy as np

from common.schema import CameraInfo, InvalidSample
from services.camera.source import IMAGE_EXTENSIONS, Source, SourceError

DEFAULT_FRAME_ID = "camera_color_optical_frame"
INTRINSICS_FILE = "intrinsics.json"
MIRRORED_SUFFIX = "_mirrored"
PAIR = re.compile(r"^(?P<name>.+)[-_](?P<kind>color|colour|rgb|depth)$", re.IGNORECASE)


@dataclass
class Capture:
    """One capture: a BGR colour image and, from an RGB-D source, its aligned depth (uint16 units or float32)."""

    color: np.ndarray
    depth: np.ndarray | None = None
    depth_scale: float | None = None  # metres per unit of `depth`
    camera_info: CameraInfo | None = None


@dataclass
class Intrinsics:
    camera_info: CameraInfo
    depth_scale: float | None


def read_intrinsics(path: str | Path) -> Intrinsics:
    """Read an intrinsics file (module docstring); raises SourceError saying what is wrong and how to fix it."""
    path = Path(path)
    try:
        spec = json.loads(path.read_text())
    except OSError as exc:
        raise SourceError(f"cannot read intrinsics file {path}: {exc.strerror or exc}") from None
    except json.JSONDecodeError as exc:
        raise SourceError(f"intrinsics file {path} is not JSON: {exc}") from None
    if not isinstance(spec, dict):
        raise SourceError(f"intrinsics file {path}: expected a JSON object with width, height, fx, fy, cx, cy")
    return parse_intrinsics(spec, str(path))


def parse_intrinsics(spec: dict[str, Any], where: str = "intrinsics") -> Intrinsics:
    def number(name: str, value: Any) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise SourceError(f"{where}: {name} must be a finite number, not {value!r}")
        return float(value)

    for name in ("width", "height"):
        if not isinstance(spec.get(name), int) or spec[name] <= 0:
            raise SourceError(
                f"{where}: {name} must be a positive integer (the resolution K belongs to), not {spec.get(name)!r}"
            )
    if "K" in spec or "k" in spec:
        raw = spec.get("K", spec.get("k"))
        flat = [v for row in raw for v in row] if raw and isinstance(raw[0], list) else raw
        if not isinstance(flat, list) or len(flat) != 9:
            raise SourceError(f"{where}: K must be 3×3 (nested rows or 9 numbers row-major)")
        k = [number("K", v) for v in flat]
    else:
        missing = [n for n in ("fx", "fy", "cx", "cy") if n not in spec]
        if missing:
            raise SourceError(f"{where}: missing {', '.join(missing)} (give fx, fy, cx, cy in pixels, or K)")
        fx, fy, cx, cy = (number(n, spec[n]) for n in ("fx", "fy", "cx", "cy"))
        k = [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]
    depth_scale = spec.get("depth_scale")
    if depth_scale is not None and not (number("depth_scale", depth_scale) > 0):
        raise SourceError(f"{where}: depth_scale must be > 0 metres per unit (RealSense 0.001, YCB-Video 0.0001)")
    distortion = spec.get("distortion", []) or []
    try:
        info = CameraInfo(
            width=spec["width"],
            height=spec["height"],
            k=k,
            distortion_model=str(spec.get("distortion_model", "none")),
            distortion=[number("distortion", v) for v in distortion],
            frame_id=str(spec.get("frame_id", DEFAULT_FRAME_ID)),
        )
    except InvalidSample as exc:
        raise SourceError(f"{where}: {exc.detail}") from None
    return Intrinsics(info, None if depth_scale is None else float(depth_scale))


def check_intrinsics(info: CameraInfo, width: int, height: int, what: str) -> None:
    """Refuse intrinsics of another resolution (SourceError with the remedy)."""
    if (info.width, info.height) != (width, height):
        raise SourceError(
            f"{what}: the intrinsics are for {info.width}x{info.height} but the images are "
            f"{width}x{height}: give the intrinsics of this resolution (scale fx, fy, cx, cy by the "
            f"same factor as the image)"
        )


def mirror_camera_info(info: CameraInfo) -> CameraInfo:
    """Intrinsics of the horizontally flipped image: pixel u becomes width − 1 − u, so cx' = width − 1 − cx.
    The image then shows a mirrored world: positions computed with it have x negated relative to the physical
    camera, so the frame_id says so (`…_mirrored`)."""
    k = list(info.k)
    k[2] = info.width - 1 - k[2]
    k[1] = -k[1]  # skew (0 on every real camera) changes sign with the u axis
    frame_id = info.frame_id if info.frame_id.endswith(MIRRORED_SUFFIX) else info.frame_id + MIRRORED_SUFFIX
    return msgspec.structs.replace(info, k=k, frame_id=frame_id)


def mirror_capture(capture: Capture) -> Capture:
    """The capture flipped left–right (colour and depth together), with its intrinsics adjusted."""
    return Capture(
        color=np.ascontiguousarray(capture.color[:, ::-1]),
        depth=None if capture.depth is None else np.ascontiguousarray(capture.depth[:, ::-1]),
        depth_scale=capture.depth_scale,
        camera_info=None if capture.camera_info is None else mirror_camera_info(capture.camera_info),
    )


# ---------------------------------------------------------------------------
# A folder of colour/depth pairs
# ---------------------------------------------------------------------------
def find_pairs(folder: Path) -> list[tuple[Path, Path]]:
    """(colour, depth) files paired by name (`X-color.*` with `X-depth.png`), in name order."""
    colour: dict[str, Path] = {}
    depth: dict[str, Path] = {}
    for p in folder.iterdir():
        m = PAIR.match(p.stem)
        if m and p.suffix.lower() in IMAGE_EXTENSIONS:
            (depth if m["kind"].lower() == "depth" else colour)[m["name"]] = p
    return [(colour[name], depth[name]) for name in sorted(colour.keys() & depth.keys())]


def is_rgbd_folder(folder: Path) -> bool:
    """Colour/depth pairs by name make a folder RGB-D (its intrinsics.json, or --intrinsics, is then required)."""
    return bool(find_pairs(folder))


def read_depth(path: Path) -> np.ndarray:
    depth = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if depth is None:
        raise SourceError(f"cannot decode depth image {path}: is it a valid 16-bit PNG?")
    if depth.ndim != 2 or depth.dtype not in (np.uint16, np.float32):
        raise SourceError(
            f"depth image {path} is {depth.dtype} with {1 if depth.ndim == 2 else depth.shape[2]} "
            f"channel(s): a depth image is one channel of 16-bit units (or 32-bit float metres)"
        )
    return depth


class RgbdFolderSource(Source):
    """Colour/depth pairs of a folder with its intrinsics.json; the first pair is checked when opened."""

    def __init__(self, folder: Path, intrinsics: Intrinsics | None = None):
        pairs = find_pairs(folder)
        if not pairs:
            raise SourceError(f"folder {folder} holds no colour/depth pairs (NAME-color.png + NAME-depth.png)")
        if intrinsics is None:
            if not (folder / INTRINSICS_FILE).is_file():
                raise SourceError(
                    f"RGB-D folder {folder} has no {INTRINSICS_FILE}: write one (width, height, fx, fy, "
                    f"cx, cy, depth_scale; docs/vision.md) or give --intrinsics FILE"
                )
            intrinsics = read_intrinsics(folder / INTRINSICS_FILE)
        super().__init__(f"RGB-D folder {folder} ({len(pairs)} pairs)", None, True)
        self.pairs = pairs
        self.info = intrinsics.camera_info
        self.depth_scale = intrinsics.depth_scale
        first_colour, first_depth = self._read(*pairs[0])  # refuse a wrong resolution at start-up
        if first_depth.dtype == np.uint16 and self.depth_scale is None:
            raise SourceError(
                f"{folder / INTRINSICS_FILE}: 16-bit depth images need depth_scale (metres per "
                f"unit: RealSense 0.001, YCB-Video 0.0001, TUM 0.0002)"
            )

    def _read(self, colour_path: Path, depth_path: Path) -> tuple[np.ndarray, np.ndarray]:
        colour = cv2.imread(str(colour_path), cv2.IMREAD_COLOR)
        if colour is None:
            raise SourceError(f"cannot decode image {colour_path}: is it a valid image file?")
        depth = read_depth(depth_path)
        if depth.shape != colour.shape[:2]:
            raise SourceError(
                f"{depth_path.name} is {depth.shape[1]}x{depth.shape[0]} but {colour_path.name} is "
                f"{colour.shape[1]}x{colour.shape[0]}: depth must be aligned to the colour image"
            )
        check_intrinsics(self.info, colour.shape[1], colour.shape[0], str(colour_path))
        return colour, depth

    def frames(self) -> Iterator[Capture]:
        for pair in self.pairs:
            colour, depth = self._read(*pair)
            yield Capture(colour, depth, 1.0 if depth.dtype == np.float32 else self.depth_scale, self.info)


# ---------------------------------------------------------------------------
# Intel RealSense
# ---------------------------------------------------------------------------
REALSENSE_INSTALL = (
    "pip install 'hri-fusion[realsense]' (pyrealsense2; on Linux it also needs libusb-1.0-0: "
    "apt-get install libusb-1.0-0)"
)


def import_realsense() -> Any:
    try:
        import pyrealsense2 as rs
    except ImportError as exc:
        raise SourceError(
            f"a RealSense source needs pyrealsense2, which is not usable here ({exc}): {REALSENSE_INSTALL}"
        ) from None
    return rs


def realsense_camera_info(rs: Any, intrinsics: Any, frame_id: str) -> CameraInfo:
    """CameraInfo of a pyrealsense2 `intrinsics` (of the colour stream, which depth is aligned to)."""
    coeffs = [float(c) for c in intrinsics.coeffs]
    if not any(coeffs):
        model, coeffs = "none", []
    elif intrinsics.model == rs.distortion.brown_conrady:
        model = "plumb_bob"  # same k1 k2 p1 p2 k3 order as OpenCV
    else:
        model = str(intrinsics.model).rsplit(".", 1)[-1]  # e.g. inverse_brown_conrady: say what it is
    return CameraInfo(
        width=intrinsics.width,
        height=intrinsics.height,
        k=[
            float(intrinsics.fx),
            0.0,
            float(intrinsics.ppx),
            0.0,
            float(intrinsics.fy),
            float(intrinsics.ppy),
            0.0,
            0.0,
            1.0,
        ],
        distortion_model=model,
        distortion=coeffs,
        frame_id=frame_id,
    )


def realsense_capture(rs: Any, frameset: Any, depth_scale: float, frame_id: str = DEFAULT_FRAME_ID) -> Capture | None:
    """A Capture from a frameset whose depth is aligned to colour (after `rs.align(rs.stream.color)`);
    None when the frameset lacks one of the two."""
    colour_frame = frameset.get_color_frame()
    depth_frame = frameset.get_depth_frame()
    if not colour_frame or not depth_frame:
        return None
    colour = np.asanyarray(colour_frame.get_data())
    fmt = colour_frame.profile.format()
    if fmt == rs.format.rgb8:
        colour = cv2.cvtColor(colour, cv2.COLOR_RGB2BGR)
    elif fmt != rs.format.bgr8:
        raise SourceError(f"RealSense colour format {fmt} is not supported: enable rgb8 or bgr8")
    depth = np.array(depth_frame.get_data(), dtype=np.uint16, copy=True)
    info = realsense_camera_info(rs, colour_frame.profile.as_video_stream_profile().get_intrinsics(), frame_id)
    if depth.shape != colour.shape[:2]:
        raise SourceError(f"RealSense depth {depth.shape[::-1]} is not aligned to colour {colour.shape[1::-1]}")
    return Capture(np.ascontiguousarray(colour), depth, depth_scale, info)


class RealSenseSource(Source):
    """An Intel RealSense: colour (bgr8) and depth (z16) at one resolution and rate, depth aligned to colour."""

    def __init__(
        self,
        serial: str | None = None,
        width: int = 640,
        height: int = 480,
        fps: int = 30,
        frame_id: str = DEFAULT_FRAME_ID,
    ):
        rs = import_realsense()
        self.rs = rs
        devices = [d.get_info(rs.camera_info.serial_number) for d in rs.context().query_devices()]
        if not devices:
            raise SourceError(
                "no RealSense device found: is it plugged in (a USB 3 port) and readable by this user "
                "(librealsense's udev rules)? Use --source FOLDER for recorded colour/depth pairs."
            )
        if serial and serial not in devices:
            raise SourceError(f"no RealSense with serial {serial}; connected: {', '.join(devices)}")
        config = rs.config()
        if serial:
            config.enable_device(serial)
        config.enable_stream(rs.stream.color, width, height, rs.format.bgr8, fps)
        config.enable_stream(rs.stream.depth, width, height, rs.format.z16, fps)
        self.pipeline = rs.pipeline()
        try:
            profile = self.pipeline.start(config)
        except RuntimeError as exc:
            raise SourceError(
                f"the RealSense could not start {width}x{height} at {fps} fps ({exc}): try another "
                f"--rs-size/--fps the camera supports"
            ) from None
        self.depth_scale = float(profile.get_device().first_depth_sensor().get_depth_scale())
        self.align = rs.align(rs.stream.color)
        self.frame_id = frame_id
        super().__init__(f"RealSense {serial or devices[0]} {width}x{height}", float(fps), False)

    def frames(self) -> Iterator[Capture]:
        while True:
            try:
                frameset = self.pipeline.wait_for_frames(5000)
            except RuntimeError as exc:
                raise SourceError(f"{self.description} stopped delivering frames ({exc}): unplugged?") from None
            capture = realsense_capture(self.rs, self.align.process(frameset), self.depth_scale, self.frame_id)
            if capture is not None:
                yield capture

    def close(self) -> None:
        try:
            self.pipeline.stop()
        except RuntimeError:
            pass


def open_realsense(spec: str, size: tuple[int, int], fps: float | None) -> RealSenseSource:
    """`realsense` or `realsense:SERIAL`."""
    serial = spec.split(":", 1)[1] if ":" in spec else None
    return RealSenseSource(serial or None, size[0], size[1], int(fps or 30))

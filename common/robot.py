"""The robot's profile: what this robot can do, read from one TOML file (docs/robot.md), or the default.

Fusion's affordances and refusals, its planner prompt and the ROS 2 node read it; fusion publishes it on the wire
(`RobotProfile`, `robot/profile`). The default is today's behaviour: the classes of `common.language.NEVER_GRASPED`
are never grasped, nothing measured over `GRASP_MAX_EXTENT_M` is, there is no weight limit, and the robot carries,
navigates and speaks. A file that is not a valid profile is refused with what is wrong and where (`ProfileError`).

Standard library (tomllib) and msgspec, beside the contract it fills (`common.schema.RobotProfile`).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar, get_args

import msgspec

from common.language import COCO_LABELS, EXTRA_LABELS, GRASP_MAX_EXTENT_M, NEVER_GRASPED, canonical_label
from common.schema import CameraMount, Location, RobotProfile, Target, WhileBusy

# Typical weight of one object of each class, kg: an ASSUMPTION written down (an everyday household example of each,
# rounded: a full 0.5-1 l bottle, a ceramic mug, a 13" laptop, a dining chair or stool), not a measurement of any
# object in view. A profile's [weights_kg] overrides any of them; a class not listed has no weight and is limited by
# its class and size only.
TYPICAL_WEIGHT_KG: dict[str, float] = {
    **{"person": 70.0, "bird": 0.3, "cat": 4.0, "dog": 15.0, "horse": 500.0, "sheep": 60.0, "cow": 600.0},
    **{"elephant": 4000.0, "bear": 200.0, "zebra": 300.0, "giraffe": 900.0},
    **{"bicycle": 12.0, "car": 1300.0, "motorcycle": 180.0, "airplane": 40000.0, "bus": 12000.0, "train": 50000.0},
    **{"truck": 8000.0, "boat": 500.0, "traffic light": 20.0, "fire hydrant": 50.0, "stop sign": 5.0},
    **{"parking meter": 20.0, "bench": 20.0},
    **{"backpack": 2.0, "umbrella": 0.5, "handbag": 1.0, "tie": 0.05, "suitcase": 4.0, "frisbee": 0.2, "skis": 3.0},
    **{"snowboard": 4.0, "sports ball": 0.4, "kite": 0.3, "baseball bat": 1.0, "baseball glove": 0.6},
    **{"skateboard": 2.5, "surfboard": 6.0, "tennis racket": 0.3},
    **{"bottle": 0.8, "wine glass": 0.2, "cup": 0.3, "fork": 0.05, "knife": 0.1, "spoon": 0.05, "bowl": 0.4},
    **{"banana": 0.15, "apple": 0.2, "sandwich": 0.3, "orange": 0.2, "broccoli": 0.4, "carrot": 0.1},
    **{"hot dog": 0.15, "pizza": 0.8, "donut": 0.1, "cake": 1.0},
    **{"chair": 5.0, "couch": 40.0, "potted plant": 3.0, "bed": 60.0, "dining table": 30.0, "toilet": 25.0},
    **{"tv": 10.0, "laptop": 2.0, "mouse": 0.1, "remote": 0.15, "keyboard": 0.8, "cell phone": 0.2},
    **{"microwave": 12.0, "oven": 50.0, "toaster": 2.0, "sink": 15.0, "refrigerator": 70.0},
    **{"book": 0.5, "clock": 1.0, "vase": 1.0, "scissors": 0.1, "teddy bear": 0.5, "hair drier": 0.6},
    **{"toothbrush": 0.02, "candy": 0.01, "box": 0.5, "block": 0.1},
}
KNOWN_LABELS = frozenset(COCO_LABELS) | frozenset(EXTRA_LABELS)
# What each ability lets the robot do (an intent needing an ability it lacks is refused with the reason)
ABILITY_INTENTS: dict[str, tuple[str, ...]] = {
    "carries": ("bring",),
    "navigates": ("go_to", "come_here", "follow", "move", "turn"),
}
ABILITY_REASON = {"carries": "I can't carry things to you", "navigates": "I can't move from where I stand"}
WHILE_BUSY: tuple[str, ...] = get_args(WhileBusy)


class ProfileError(ValueError):
    """A profile file that cannot be used: the message says what is wrong and where (file, table, key)."""


@dataclass(frozen=True)
class Profile:
    name: str = "default"
    description: str = "the default: grasps what a household arm lifts, carries, navigates and speaks"
    never_grasp: dict[str, tuple[str, ...]] = field(default_factory=lambda: dict(NEVER_GRASPED))
    max_weight_kg: float | None = None
    max_size_m: float = GRASP_MAX_EXTENT_M
    weights_kg: dict[str, float] = field(default_factory=lambda: dict(TYPICAL_WEIGHT_KG))
    carries: bool = True
    navigates: bool = True
    speaks: bool = True
    while_busy: WhileBusy = "ask"
    camera: CameraMount | None = None
    path: str | None = None  # the file it was read from; None: the built-in default

    @property
    def is_default(self) -> bool:
        return self.path is None

    def never_kind(self, label: str) -> str | None:
        """The kind under which `label` is never grasped ("furniture"), None when its class may be."""
        return next((kind for kind, labels in self.never_grasp.items() if label in labels), None)

    def too_heavy(self, label: str) -> float | None:
        """The typical weight of `label` when it is over this robot's limit, else None."""
        weight = self.weights_kg.get(label)
        if self.max_weight_kg is None or weight is None or weight <= self.max_weight_kg:
            return None
        return weight

    def class_reason(self, label: str) -> str | None:
        """Why no object of class `label` is grasped, in words after "I can't pick up a chair: " (None: it may be,
        subject to its measured size)."""
        kind = self.never_kind(label)
        if kind is not None:
            return f"I don't lift {kind}"
        weight = self.too_heavy(label)
        if weight is not None:
            assert self.max_weight_kg is not None
            return f"it weighs about {weight:g} kg, over my {self.max_weight_kg:g} kg"
        return None

    def size_reason(self, size_m: float | None) -> str | None:
        if size_m is None or size_m <= self.max_size_m:
            return None
        return f"{size_m:.2f} m across, over my {self.max_size_m:.1f} m"

    def missing_ability(self, intent: str | None) -> str | None:
        """Why this robot cannot do `intent` at all ("I can't move from where I stand"), None when it can."""
        for ability, intents in ABILITY_INTENTS.items():
            if intent in intents and not getattr(self, ability):
                return ABILITY_REASON[ability]
        return None

    def words(self) -> str:
        """What the robot can do, one line for a planner."""
        abilities = [a for a, on in (("carries", self.carries), ("navigates", self.navigates)) if on]
        cannot = [a for a, on in (("carry", self.carries), ("navigate", self.navigates)) if not on]
        weight = f"up to {self.max_weight_kg:g} kg" if self.max_weight_kg is not None else "of any weight"
        never = "; never grasps " + ", ".join(self.never_grasp) if self.never_grasp else ""
        return (
            f"{self.name}: grasps objects {weight}, at most {self.max_size_m:g} m across{never}; "
            + (", ".join(abilities) or "stays in place")
            + (f"; cannot {' or '.join(cannot)}" if cannot else "")
            + f"; {'speaks' if self.speaks else 'has no voice'}; a command while busy: {self.while_busy}"
        )

    def sample(self, stamp: float, source: str) -> RobotProfile:
        return RobotProfile(
            stamp=stamp,
            source=source,
            name=self.name,
            description=self.description,
            never_grasp={kind: list(labels) for kind, labels in self.never_grasp.items()},
            max_weight_kg=self.max_weight_kg,
            max_size_m=self.max_size_m,
            weights_kg=dict(self.weights_kg),
            carries=self.carries,
            navigates=self.navigates,
            speaks=self.speaks,
            while_busy=self.while_busy,
            camera=self.camera,
        )


DEFAULT = Profile()

# -- reading a file: every key checked, an unknown one is an error (a typo must not silently mean the default) ------
TOP_KEYS = ("name", "description", "abilities", "grasp", "weights_kg", "busy", "camera")
TABLE_KEYS = {
    "abilities": ("carries", "navigates", "speaks"),
    "grasp": ("max_weight_kg", "max_size_m", "never"),
    "busy": ("while_busy",),
    "camera": ("parent", "frame_id", "xyz", "rpy"),
}


class _Reader:
    """Checks one parsed TOML document; `fail` raises with the file and the key path."""

    def __init__(self, path: str, data: dict[str, Any]):
        self.path = path
        self.data = data

    def fail(self, where: str, what: str) -> ProfileError:
        return ProfileError(f"robot profile {self.path}: {where}: {what}")

    def table(self, name: str) -> dict[str, Any]:
        value = self.data.get(name, {})
        if not isinstance(value, dict):
            raise self.fail(name, f"expected a table [{name}], got {type(value).__name__}")
        allowed = TABLE_KEYS[name]
        unknown = sorted(set(value) - set(allowed))
        if unknown:
            raise self.fail(f"[{name}]", f"unknown key(s) {', '.join(unknown)} (known: {', '.join(allowed)})")
        return value

    def boolean(self, table: dict[str, Any], where: str, key: str, default: bool) -> bool:
        value = table.get(key, default)
        if not isinstance(value, bool):
            raise self.fail(f"{where} {key}", f"expected true or false, got {value!r}")
        return value

    def number(self, value: Any, where: str, positive: bool = True) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.fail(where, f"expected a number, got {value!r}")
        if positive and value <= 0:
            raise self.fail(where, f"expected a number > 0, got {value!r}")
        return float(value)

    def text(self, value: Any, where: str) -> str:
        if not isinstance(value, str) or not value.strip():
            raise self.fail(where, f"expected a non-empty string, got {value!r}")
        return value.strip()

    def label(self, value: Any, where: str) -> str:
        label = canonical_label(self.text(value, where))
        if label not in KNOWN_LABELS:
            raise self.fail(where, f"{value!r} is not a class the detector names (COCO-80, candy, box, block)")
        return label

    def never(self, grasp: dict[str, Any]) -> dict[str, tuple[str, ...]]:
        value = grasp.get("never")
        if value is None:
            return dict(NEVER_GRASPED)
        if not isinstance(value, dict):
            raise self.fail("[grasp] never", 'expected a table of kind = [classes], e.g. furniture = ["couch", "bed"]')
        out: dict[str, tuple[str, ...]] = {}
        for kind, labels in value.items():
            where = f"[grasp.never] {kind}"
            if not isinstance(labels, list):
                raise self.fail(where, f"expected a list of classes, got {labels!r}")
            out[kind] = tuple(self.label(v, f"{where}[{i}]") for i, v in enumerate(labels))
        return out

    def weights(self) -> dict[str, float]:
        value = self.data.get("weights_kg", {})
        if not isinstance(value, dict):
            raise self.fail("weights_kg", "expected a table [weights_kg] of class = kilograms")
        out = dict(TYPICAL_WEIGHT_KG)
        for label, kg in value.items():
            out[self.label(label, f"[weights_kg] {label!r}")] = self.number(kg, f"[weights_kg] {label!r}")
        return out

    def point3(self, table: dict[str, Any], key: str) -> list[float]:
        value = table.get(key)
        if not isinstance(value, list) or len(value) != 3:
            raise self.fail(f"[camera] {key}", f"expected 3 numbers, got {value!r}")
        return [self.number(v, f"[camera] {key}[{i}]", positive=False) for i, v in enumerate(value)]

    def camera(self) -> CameraMount | None:
        if "camera" not in self.data:
            return None
        cam = self.table("camera")
        return CameraMount(
            parent=self.text(cam.get("parent", "base_link"), "[camera] parent"),
            frame_id=self.text(cam.get("frame_id"), "[camera] frame_id"),
            xyz=self.point3(cam, "xyz"),
            rpy=self.point3(cam, "rpy"),
        )

    def profile(self) -> Profile:
        unknown = sorted(set(self.data) - set(TOP_KEYS))
        if unknown:
            raise self.fail("top level", f"unknown key(s) {', '.join(unknown)} (known: {', '.join(TOP_KEYS)})")
        abilities, grasp, busy = self.table("abilities"), self.table("grasp"), self.table("busy")
        max_weight = grasp.get("max_weight_kg")
        while_busy = busy.get("while_busy", DEFAULT.while_busy)
        if while_busy not in WHILE_BUSY:
            raise self.fail("[busy] while_busy", f"expected one of {', '.join(WHILE_BUSY)}, got {while_busy!r}")
        return Profile(
            name=self.text(self.data.get("name"), "name"),
            description=str(self.data.get("description", "")),
            never_grasp=self.never(grasp),
            max_weight_kg=None if max_weight is None else self.number(max_weight, "[grasp] max_weight_kg"),
            max_size_m=self.number(grasp.get("max_size_m", DEFAULT.max_size_m), "[grasp] max_size_m"),
            weights_kg=self.weights(),
            carries=self.boolean(abilities, "[abilities]", "carries", DEFAULT.carries),
            navigates=self.boolean(abilities, "[abilities]", "navigates", DEFAULT.navigates),
            speaks=self.boolean(abilities, "[abilities]", "speaks", DEFAULT.speaks),
            while_busy=while_busy,
            camera=self.camera(),
            path=self.path,
        )


# -- where a point seen by the camera is on the robot (the profile's camera mount) -----------------------------------
def mount_rotation(rpy: list[float]) -> tuple[tuple[float, float, float], ...]:
    """The rotation matrix (rows) of roll, pitch, yaw in radians, fixed axes x, y, z (REP-103, URDF, tf2's
    static_transform_publisher): R = Rz(yaw) Ry(pitch) Rx(roll), the child's axes in the parent's frame."""
    (cr, sr), (cp, sp), (cy, sy) = ((math.cos(a), math.sin(a)) for a in rpy)
    return (
        (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
        (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
        (-sp, cp * sr, cp * cr),
    )


def in_base(mount: CameraMount | None, frame_id: str | None, position: list[float] | None) -> list[float] | None:
    """`position` (metres in the camera frame `frame_id`, REP-103 optical: x right, y down, z forward) in the robot's
    base frame `mount.parent` (REP-103 body: x forward, y left, z up): p_base = R(rpy) p + xyz. None when there is
    no position, no mount, or the mount places another frame: a base position is never guessed."""
    if mount is None or position is None or frame_id != mount.frame_id:
        return None
    rotation = mount_rotation(mount.rpy)
    return [round(sum(r * p for r, p in zip(row, position)) + t, 4) for row, t in zip(rotation, mount.xyz)]


Placed = TypeVar("Placed", Target, Location)


def with_base(where: Placed, mount: CameraMount | None) -> Placed:
    """A command's Target or Location with its position also in the robot's base frame (`base`, `base_frame_id`),
    when the mount places its camera frame; unchanged otherwise."""
    base = in_base(mount, where.frame_id, where.position)
    if base is None or mount is None:
        return where
    return msgspec.structs.replace(where, base=base, base_frame_id=mount.parent)


def parse_profile(text: str, path: str = "<text>") -> Profile:
    """A profile from TOML text; ProfileError saying what is wrong and where."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"robot profile {path}: not valid TOML: {exc}") from None
    return _Reader(path, data).profile()


def load_profile(path: str | Path | None) -> Profile:
    """The profile in the file at `path` (None: the default); ProfileError when it cannot be used."""
    if path is None:
        return DEFAULT
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ProfileError(f"robot profile {path}: cannot read it: {exc}") from None
    return parse_profile(text, str(path))

"""The face stage: MediaPipe Face Mesh (legacy `mediapipe.solutions.face_mesh`, the model ships in the wheel) on a
frame -> faces with a stable track id, mouth opening and head orientation (issue #33: who is speaking, to whom).

The rules are pure functions of the mesh's 468 landmarks (pixels; z in the scale of x, smaller = nearer the
camera): `mouth_opening`, `head_angles`, `looking_at`; `FaceTracker` keeps ids across frames by box overlap
(IoU), then centre distance, through a short miss. `FaceMesher` is the only part that calls MediaPipe.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from common.boxes import iou, match_in_order
from common.schema import Face, Faces, Frame, Persons
from common.settings import setting
from services.gesture.schedule import RatePace

# Face Mesh landmark indices (canonical face model): inner lips, inner mouth corners, cheeks, forehead, chin.
UPPER_INNER_LIP, LOWER_INNER_LIP = 13, 14
MOUTH_CORNER_RIGHT, MOUTH_CORNER_LEFT = 78, 308  # the person's right / left inner corner
CHEEK_RIGHT, CHEEK_LEFT = 234, 454
FOREHEAD, CHIN = 10, 152
# the face's outline (mediapipe's FACEMESH_FACE_OVAL): its box
FACE_OVAL = (10, 21, 54, 58, 67, 93, 103, 109, 127, 132, 136, 148, 149, 150, 152, 162, 172, 176, 234, 251, 284, 288,
             297, 323, 332, 338, 356, 361, 365, 377, 378, 379, 389, 397, 400, 454)  # fmt: skip
MESH_POINTS = 468
# the only landmarks the rules read: reading all 468 from the protobuf result costs as much as the rules
_OVAL = np.array(FACE_OVAL)
USED = tuple(sorted(set(FACE_OVAL) | {UPPER_INNER_LIP, LOWER_INNER_LIP, MOUTH_CORNER_RIGHT, MOUTH_CORNER_LEFT}))


@dataclass(frozen=True)
class FaceConfig:
    """The face stage's settings; each is also a flag of `hri-gesture` (common/settings.py)."""

    max_faces: int = setting(4, "faces tracked per camera by the face stage", at_least=1, metavar="N")
    look_yaw: float = setting(
        25.0,
        "a face turned at most this many degrees left or right looks at the camera",
        at_least=0,
        at_most=90,
        metavar="DEG",
    )
    look_pitch: float = setting(
        20.0, "and tilted at most this many degrees up or down", at_least=0, at_most=90, metavar="DEG"
    )
    mouth_max_yaw: float = setting(
        60.0,
        "beyond this yaw (degrees) the mouth is too side-on to measure: mouth_open is nil",
        at_least=0,
        at_most=90,
        metavar="DEG",
    )
    face_keep: float = setting(
        0.5,
        "seconds a face track is kept through frames that miss it (same id when it is found again)",
        at_least=0,
        metavar="S",
    )
    faces_max_rate: float = setting(
        20.0,
        "at most this many frames per second per camera go through the face stage (mouth motion needs >= 12); "
        "0: every frame",
        at_least=0,
        metavar="FPS",
    )


def mouth_opening(points: np.ndarray) -> float | None:
    """Inner-lip gap over inner mouth width (0 closed; ~0.5 wide open): scale-free, so near and far faces compare.
    None when the mouth width is degenerate."""
    width = float(np.linalg.norm(points[MOUTH_CORNER_RIGHT, :2] - points[MOUTH_CORNER_LEFT, :2]))
    if width < 1e-6:
        return None
    gap = float(np.linalg.norm(points[UPPER_INNER_LIP, :2] - points[LOWER_INNER_LIP, :2]))
    return gap / width


def head_angles(points: np.ndarray) -> tuple[float, float] | None:
    """(yaw, pitch) in degrees from the face plane's normal: the cross product of the cheek-to-cheek and the
    forehead-to-chin vectors (3-D mesh). Yaw > 0: turned to the image's right; pitch > 0: looking up."""
    ax, ay, az = (points[CHEEK_LEFT] - points[CHEEK_RIGHT]).tolist()  # the person's left cheek: image right
    dx, dy, dz = (points[CHIN] - points[FOREHEAD]).tolist()
    # down x across: out of the face, towards the camera (-z) for a frontal face (plain floats: np.cross is slow)
    nx, ny, nz = dy * az - dz * ay, dz * ax - dx * az, dx * ay - dy * ax
    if math.isnan(nx + ny + nz) or math.hypot(nx, ny, nz) < 1e-9:
        return None
    yaw = math.degrees(math.atan2(nx, -nz))
    pitch = math.degrees(math.atan2(-ny, math.hypot(nx, nz)))
    return yaw, pitch


def looking_at(yaw: float | None, pitch: float | None, cfg: FaceConfig) -> bool | None:
    if yaw is None or pitch is None:
        return None
    return abs(yaw) <= cfg.look_yaw and abs(pitch) <= cfg.look_pitch


def bbox_of(points: np.ndarray) -> list[float]:
    """The box of the face's outline (FACE_OVAL) in the mesh's pixels."""
    oval = points[_OVAL, :2]
    x0, y0 = oval.min(axis=0).tolist()
    x1, y1 = oval.max(axis=0).tolist()
    return [round(float(x0), 1), round(float(y0), 1), round(float(x1 - x0), 1), round(float(y1 - y0), 1)]


def centre_distance(a: list[float], b: list[float]) -> float:
    """Distance of the centres in units of the larger box's size (so it means the same near and far)."""
    dx = (a[0] + a[2] / 2) - (b[0] + b[2] / 2)
    dy = (a[1] + a[3] / 2) - (b[1] + b[3] / 2)
    return math.hypot(dx, dy) / max(a[2], a[3], b[2], b[3], 1e-6)


@dataclass
class _Track:
    id: str
    bbox: list[float]
    missed_since: float | None = None  # stamp of the first frame that missed it (None: found in the last one)


@dataclass
class FaceTracker:
    """Stable face ids: each new box goes to the live track it overlaps most (IoU >= min_iou), else the nearest
    live track whose centre is within max_centre box sizes; unmatched boxes start a new track. A track is dropped
    when the frames processed have missed it for more than `keep` seconds (a pause in the frames, a slow stage,
    is no miss); a clock going back resets the tracker."""

    keep: float = 0.5
    prefix: str = "face-"  # ids are prefix + a number (the gesture service uses "<cam>/face-": unique per camera)
    min_iou: float = 0.3
    max_centre: float = 0.5
    tracks: list[_Track] = field(default_factory=list)
    next_id: int = 1
    last_stamp: float | None = None

    def update(self, stamp: float, boxes: list[list[float]]) -> list[str]:
        if self.last_stamp is not None and stamp < self.last_stamp:
            self.tracks = []
        self.last_stamp = stamp
        self.tracks = [t for t in self.tracks if t.missed_since is None or stamp - t.missed_since <= self.keep]
        pairs = [(self._affinity(t.bbox, b), ti, bi) for ti, t in enumerate(self.tracks) for bi, b in enumerate(boxes)]
        matched = match_in_order(sorted((p for p in pairs if p[0] > 0), reverse=True))
        ids: list[str | None] = [None] * len(boxes)
        for bi, ti in matched.items():
            ids[bi] = self.tracks[ti].id
            self.tracks[ti].bbox, self.tracks[ti].missed_since = boxes[bi], None
        used = set(matched.values())
        for ti, track in enumerate(self.tracks):
            if ti not in used and track.missed_since is None:
                track.missed_since = stamp
        for bi, box in enumerate(boxes):
            if ids[bi] is None:
                track = _Track(f"{self.prefix}{self.next_id}", box)
                self.next_id += 1
                self.tracks.append(track)
                ids[bi] = track.id
        return [i for i in ids if i is not None]

    def _affinity(self, a: list[float], b: list[float]) -> float:
        """> 1 for an overlap (IoU + 1), (0, 1] for a near centre, 0 for no match: overlaps are matched first."""
        overlap = iou(a, b)
        if overlap >= self.min_iou:
            return 1.0 + overlap
        near = centre_distance(a, b)
        return 1.0 - near / self.max_centre if near < self.max_centre else 0.0


def face_of(points: np.ndarray, face_id: str, cfg: FaceConfig, bbox: list[float] | None = None) -> Face:
    """One mesh (468x3 px) -> the wire `Face` (`person` is left to the person tracker); `bbox`: its box if known."""
    angles = head_angles(points)
    yaw, pitch = angles if angles is not None else (None, None)
    mouth = mouth_opening(points) if yaw is not None and abs(yaw) <= cfg.mouth_max_yaw else None
    return Face(
        id=face_id,
        bbox=bbox if bbox is not None else bbox_of(points),
        # the legacy Face Mesh API reports no per-face score: a face it returns has passed its detection and
        # tracking thresholds (MESH_MIN_CONFIDENCE), which is the confidence we can state
        score=MESH_MIN_CONFIDENCE,
        mouth_open=None if mouth is None else round(mouth, 4),
        yaw=None if yaw is None else round(yaw, 1),
        pitch=None if pitch is None else round(pitch, 1),
        looking_at_camera=looking_at(yaw, pitch, cfg),
    )


MESH_MIN_CONFIDENCE = 0.5


def link_faces(faces: Faces | None, persons: Persons | None) -> None:
    """Tie each face to its person, both ways (`Face.person`, `Person.face`): the person whose box holds the face's
    centre, of those the one whose top is nearest the face's top (a face is at the top of its person's extent).
    Nothing changes without persons (no person stage): the face id then stands for the person."""
    if faces is None or persons is None:
        return
    for face in faces.faces:
        cx, cy = face.bbox[0] + face.bbox[2] / 2, face.bbox[1] + face.bbox[3] / 2
        holders = [
            p
            for p in persons.persons
            if p.bbox[0] <= cx <= p.bbox[0] + p.bbox[2] and p.bbox[1] <= cy <= p.bbox[1] + p.bbox[3]
        ]
        if not holders:
            continue
        person = min(holders, key=lambda p: abs(p.bbox[1] - face.bbox[1]))
        face.person = person.id
        if person.face is None:
            person.face = face.id


class FaceMesher:
    """One MediaPipe Face Mesh graph for one video stream (it tracks between frames). Not thread-safe."""

    def __init__(self, max_faces: int = 4, video: bool = True):
        from mediapipe.python.solutions import face_mesh

        self._mesh = face_mesh.FaceMesh(
            static_image_mode=not video,
            max_num_faces=max_faces,
            refine_landmarks=False,  # iris points: not needed for the mouth or the head's angles
            min_detection_confidence=MESH_MIN_CONFIDENCE,
            min_tracking_confidence=MESH_MIN_CONFIDENCE,
        )

    def detect(self, bgr: np.ndarray) -> list[np.ndarray]:
        """Each face's landmarks (468 x 3) in pixels (x, y, and z in the scale of x), left to right; only the
        rows in USED are read (the others are NaN)."""
        h, w = bgr.shape[:2]
        result = self._mesh.process(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
        meshes = []
        for lms in result.multi_face_landmarks or []:
            mesh = np.full((MESH_POINTS, 3), np.nan)
            points = lms.landmark
            mesh[list(USED)] = [(points[i].x * w, points[i].y * h, points[i].z * w) for i in USED]
            meshes.append(mesh)
        return sorted(meshes, key=lambda m: float(m[CHIN, 0]))

    def close(self) -> None:
        self._mesh.close()


class FaceStage:
    """Frames of one stream -> `Face`s with stable ids (the mesher's graph and the tracker together)."""

    def __init__(self, cfg: FaceConfig, video: bool = True, id_prefix: str = "face-"):
        self.cfg = cfg
        self.mesher = FaceMesher(cfg.max_faces, video)
        self.tracker = FaceTracker(keep=cfg.face_keep, prefix=id_prefix)

    def process(self, bgr: np.ndarray, stamp: float) -> list[Face]:
        meshes = self.mesher.detect(bgr)
        boxes = [bbox_of(m) for m in meshes]
        ids = self.tracker.update(stamp, boxes)
        return [face_of(m, i, self.cfg, b) for m, i, b in zip(meshes, ids, boxes)]

    def close(self) -> None:
        self.mesher.close()


class FaceStages:
    """The face stage of every camera: a frame -> its `Faces` sample, or None when `faces_max_rate` skips it."""

    def __init__(self, cfg: FaceConfig, enabled: bool = True):
        self.cfg = cfg
        self.enabled = enabled  # off (--no-faces): no sample, no cost
        self.stages: dict[str, FaceStage] = {}
        self.pace: dict[str, RatePace] = {}  # cam -> which of its frames the stage runs on

    def due(self, frame: Frame) -> bool:
        """Whether the stage is due on this frame of its camera (`faces_max_rate`); asks the camera's pacer."""
        if not self.enabled:
            return False
        return self.pace.setdefault(frame.cam, RatePace(self.cfg.faces_max_rate)).due(frame.stamp)

    def sample(self, frame: Frame, bgr: np.ndarray, source: str, run: bool | None = None) -> Faces | None:
        """`run`: whether the stage runs on this frame (the gesture core's schedule, which asked `due`); None: it
        runs when `due`."""
        if not self.enabled or not (self.due(frame) if run is None else run):
            return None
        if frame.cam not in self.stages:
            self.stages[frame.cam] = FaceStage(self.cfg, id_prefix=f"{frame.cam}/face-")
        faces = self.stages[frame.cam].process(bgr, frame.stamp)
        return Faces(
            stamp=frame.stamp,
            source=source,
            seq=frame.seq,
            cam=frame.cam,
            width=frame.width,
            height=frame.height,
            faces=faces,
        )

    def close(self) -> None:
        for stage in self.stages.values():
            stage.close()

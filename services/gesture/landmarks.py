"""MediaPipe hand landmarks (the legacy `mediapipe.solutions.hands` API, models shipped in the wheel).

Handedness: the legacy API assumes a mirrored, selfie-style image. A robot's camera is not mirrored, so by
default the label is swapped and `hand` is the person's own left or right; pass `mirrored=True` for a
selfie view (a laptop webcam preview, a mirrored stream).
"""

from __future__ import annotations

import cv2
import numpy as np

from services.gesture.temporal import Observation

MODELS = {"lite": 0, "full": 1}


class LandmarkError(RuntimeError):
    """MediaPipe is missing or cannot start; the message says how to install it."""


class HandLandmarker:
    """One MediaPipe hands graph for one video stream (it tracks between frames). Not thread-safe."""

    def __init__(
        self,
        model: str = "lite",
        max_hands: int = 2,
        mirrored: bool = False,
        video: bool = True,
        min_detection: float = 0.5,
        min_tracking: float = 0.5,
    ):
        try:
            from mediapipe.python.solutions import hands as mp_hands
        except ImportError as exc:
            raise LandmarkError(
                f"mediapipe cannot be imported ({exc}); run `make setup` (it installs "
                f"mediapipe==0.10.21 with --no-deps plus protobuf<5, attrs, matplotlib)"
            ) from None
        if model not in MODELS:
            raise LandmarkError(f"unknown hand model {model!r}: use one of {', '.join(MODELS)}")
        self.mirrored = mirrored
        self._hands = mp_hands.Hands(
            static_image_mode=not video,
            max_num_hands=max_hands,
            model_complexity=MODELS[model],
            min_detection_confidence=min_detection,
            min_tracking_confidence=min_tracking,
        )

    def detect(self, bgr: np.ndarray) -> list[Observation]:
        h, w = bgr.shape[:2]
        result = self._hands.process(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
        if not result.multi_hand_landmarks:
            return []
        out = []
        for lms, handedness in zip(result.multi_hand_landmarks, result.multi_handedness):
            label = handedness.classification[0].label.lower()  # as seen in a mirror
            if not self.mirrored:
                label = "left" if label == "right" else "right"
            points = np.array([[lm.x * w, lm.y * h] for lm in lms.landmark], dtype=float)
            out.append(Observation(label, float(handedness.classification[0].score), points))
        return out

    def close(self) -> None:
        self._hands.close()


POSE_FULL = 1  # model_complexity of pose_landmark_full.tflite, the one pose model in the 0.10.21 wheel (lite and
# heavy are downloaded by MediaPipe on first use: not possible offline, and nothing is downloaded here)


SIMULATED_STEP_US = 33333  # what mediapipe's SolutionBase.process() adds to its clock per call


class PoseLandmarker:
    """One MediaPipe Pose graph for one video stream: the 33 body landmarks of the most prominent person."""

    def __init__(self, video: bool = True, min_detection: float = 0.5, min_tracking: float = 0.5):
        try:
            from mediapipe.python.solutions import pose as mp_pose
        except ImportError as exc:
            raise LandmarkError(
                f"mediapipe cannot be imported ({exc}); run `make setup` (it installs "
                f"mediapipe==0.10.21 with --no-deps plus protobuf<5, attrs, matplotlib)"
            ) from None
        self.world: np.ndarray | None = None  # the last detect()'s 33x3 world landmarks
        self.video = video
        self._last_us: int | None = None  # the graph's clock at the last run given a stamp (us)
        self._pose = mp_pose.Pose(
            static_image_mode=not video,
            model_complexity=POSE_FULL,
            min_detection_confidence=min_detection,
            min_tracking_confidence=min_tracking,
        )

    def detect(self, bgr: np.ndarray, stamp: float | None = None) -> np.ndarray | None:
        """33x3 [x px, y px, visibility], or None when no person is seen. `stamp`: the frame's source time (s), so
        that the graph's landmark smoothing sees the real time between its runs (the legacy API assumes 33 ms; a
        graph run on every 2nd frame would otherwise follow a moving arm half as fast)."""
        h, w = bgr.shape[:2]
        if stamp is not None and self.video:
            self._set_time(stamp)
        result = self._pose.process(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
        world = result.pose_world_landmarks
        # metres, origin between the hips (the 3-D ray when the arm has no depth: services/gesture/space.py)
        self.world = np.array([[lm.x, lm.y, lm.z] for lm in world.landmark], dtype=float) if world else None
        if not result.pose_landmarks:
            return None
        return np.array([[lm.x * w, lm.y * h, lm.visibility] for lm in result.pose_landmarks.landmark], dtype=float)

    def _set_time(self, stamp: float) -> None:
        # SolutionBase.process() stamps its packet `_simulated_timestamp` + 33333 us (private, but the one way
        # into the legacy graph's clock); kept strictly increasing, as the graph requires
        now_us = int(stamp * 1e6)
        last = self._last_us
        if last is not None:
            now_us = max(now_us, last + 1)
        self._pose._simulated_timestamp = now_us - SIMULATED_STEP_US
        self._last_us = now_us

    def close(self) -> None:
        self._pose.close()


class FaceDetector:
    """MediaPipe face detection (the full-range model in the wheel): face boxes of every person in a frame."""

    def __init__(self, min_detection: float = 0.5):
        try:
            from mediapipe.python.solutions import face_detection as mp_face
        except ImportError as exc:
            raise LandmarkError(f"mediapipe cannot be imported ({exc}); run `make setup`") from None
        self._faces = mp_face.FaceDetection(model_selection=1, min_detection_confidence=min_detection)

    def detect(self, bgr: np.ndarray) -> list[tuple[tuple[float, float, float, float], float]]:
        """[((x, y, w, h) px, score)], left to right."""
        h, w = bgr.shape[:2]
        result = self._faces.process(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
        out = []
        for d in result.detections or []:
            b = d.location_data.relative_bounding_box
            out.append(((b.xmin * w, b.ymin * h, b.width * w, b.height * h), float(d.score[0])))
        return sorted(out, key=lambda f: f[0][0])

    def close(self) -> None:
        self._faces.close()


class RegionPose:
    """MediaPipe Pose on one region of a frame at a time (each person's region: services/gesture/persons.py).
    Single images, no tracking between calls: the regions of different people take turns on one graph."""

    def __init__(self, min_detection: float = 0.5):
        self._pose = PoseLandmarker(video=False, min_detection=min_detection)

    def detect(self, bgr: np.ndarray, region: tuple[int, int, int, int]) -> np.ndarray | None:
        """33x3 [x px, y px, visibility] in the frame's pixels, or None; `region` = (x0, y0, x1, y1) px."""
        x0, y0, x1, y1 = region
        found = self._pose.detect(np.ascontiguousarray(bgr[y0:y1, x0:x1]))
        if found is None:
            return None
        found[:, 0] += x0
        found[:, 1] += y0
        return found

    def close(self) -> None:
        self._pose.close()

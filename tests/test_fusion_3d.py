"""Grounding in metres (services/fusion/space.py + the hooks in ground.py): a synthetic room seen by a pinhole camera
(f 600 px, 640x480), a person pointing with a known 3-D ray at objects 1-3 m away. Where the image's 2-D geometry and
the 3-D geometry disagree, the 3-D answer is the right one; without depth nothing changes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.schema import (
    Bodies,
    Body,
    DetectedObject,
    Detections,
    FusedCommand,
    Hand,
    ImageQuality,
    Ray,
    Ray3D,
    Weights,
)
from services.fusion import space
from services.fusion.evidence import pointing_from_hands, select_pointing
from services.fusion.ground import best_pointed, pointed_location, scene_objects, score
from services.fusion.parse import parse
from testkit.room3d import (
    CX,
    CY,
    EYES,
    FRAME,
    F,
    H,
    W,
    detections,
    hands,
    pointing_hand,
    project,
    step,
    thing,
    unit,
)
from testkit.scenarios import BASE_STAMP, KEYS, Scenario, Step, deliver, run_in_process, say


def pointed(objects, hand, depth=True) -> str:
    p = select_pointing(pointing_from_hands(hands(hand)), BASE_STAMP)
    assert p is not None, "the hand does not point"
    best = best_pointed(p, scene_objects([detections(objects, depth=depth)]))
    assert best is not None, "nothing is pointed at"
    return best.obj.id


# ---------------------------------------------------------------------------
# Pointing
# ---------------------------------------------------------------------------
def test_two_d_and_three_d_disagree_and_three_d_is_right():
    """B is seen just past the fingertip, on the image of the ray, but it stands 1.2 m farther from the camera,
    beside the person (its line of sight crosses the 3-D ray there); A, the bottle pointed at, is 6 cm off the 3-D
    ray. In the image B is "under the fingertip" and wins; in metres A does."""
    target = np.array([-0.7, 0.45, 1.6])
    d = unit(target - EYES)
    a = target + unit(np.cross(d, [0, 1, 0])) * 0.06
    on_ray = EYES + 0.9 * d  # a point of the 3-D ray just past the fingertip (0.7 m)...
    b = on_ray * (on_ray[2] + 1.2) / on_ray[2]  # ...pushed back along the camera's line of sight: same pixel
    objects = [thing("A", "bottle", a), thing("B", "bottle", b)]
    hand = pointing_hand(target)
    assert pointed(objects, hand, depth=False) == "B"  # the image alone is fooled
    assert pointed(objects, hand) == "A"
    p = select_pointing(pointing_from_hands(hands(hand)), BASE_STAMP)
    angles = {
        s.obj.id: s.angle
        for s in score(
            parse("that bottle").obj,
            scene_objects([detections(objects)]),
            p,
            Weights(speech=0.5, vision=0.0, gesture=0.5),
        )
    }
    assert angles["A"] < 3.0 < 45.0 < angles["B"]


@pytest.mark.parametrize("which", range(6))
def test_pointing_at_objects_one_to_three_metres_away_picks_the_right_one(which):
    """Six bottles 1-3 m from the person, spread over the room; pointing at each picks it, with and without a
    3° error in the ray."""
    places = [
        np.array(p)
        for p in (
            [-0.8, 0.5, 2.4],
            [-0.2, 0.5, 1.6],
            [0.6, 0.5, 1.2],
            [-1.3, 0.3, 3.0],
            [1.2, 0.4, 2.0],
            [0.0, 0.2, 4.6],
        )
    ]
    for p in places:
        assert 1.0 <= np.linalg.norm(p - EYES) <= 3.0
    objects = [thing(f"b{i}", "bottle", p) for i, p in enumerate(places)]
    assert pointed(objects, pointing_hand(places[which])) == f"b{which}"
    # a 3° error (rotated about the vertical)
    d = places[which] - EYES
    c, s = math.cos(math.radians(3)), math.sin(math.radians(3))
    off = EYES + np.array([c * d[0] + s * d[2], d[1], -s * d[0] + c * d[2]])
    assert pointed(objects, pointing_hand(off)) == f"b{which}"


def test_the_object_under_the_fingertip_wins_over_the_one_farther_along_the_ray():
    target = np.array([-0.3, 0.2, 2.3])
    d = unit(target - EYES)
    near = EYES + 0.78 * d  # at the fingertip (0.7 m from the eyes) + its own size
    far = EYES + 2.0 * d
    objects = [thing("touched", "cup", near, size=(0.08, 0.1, 0.08)), thing("far", "cup", far)]
    ray = space.from_wire(pointing_hand(target).ray.ray3d)
    assert space.under_fingertip(ray, near, [0.08, 0.1, 0.08])
    assert not space.under_fingertip(ray, far, [0.08, 0.22, 0.08])
    assert pointed(objects, pointing_hand(target)) == "touched"


def test_a_box_around_the_fingertip_pixel_far_behind_the_person_is_not_touched():
    """The 2-D touch rule (the smallest box holding the fingertip's pixel) is for objects without depth: a TV on the
    wall behind the person holds the fingertip's pixel, but in metres it is 1.5 m behind the finger."""
    target = np.array([-0.3, 0.2, 1.6])
    tip = EYES + 0.7 * unit(target - EYES)
    tv = thing("tv", "tv", [tip[0], tip[1], EYES[2] + 1.5], size=(0.9, 0.6, 0.1))
    x, y, w, h = tv.bbox
    tip_px = project(tip)
    assert x <= tip_px[0] <= x + w and y <= tip_px[1] <= y + h
    objects = [tv, thing("cup", "cup", target)]
    assert pointed(objects, pointing_hand(target)) == "cup"


def test_a_ray_in_another_frame_is_compared_in_two_d():
    target = np.array([-0.7, 0.45, 1.6])
    d = unit(target - EYES)
    on_ray = EYES + 0.9 * d
    b = on_ray * (on_ray[2] + 1.2) / on_ray[2]
    objects = [thing("A", "bottle", target + unit(np.cross(d, [0, 1, 0])) * 0.06), thing("B", "bottle", b)]
    hand = pointing_hand(target)
    other = Ray3D(
        origin=hand.ray.ray3d.origin,
        direction=hand.ray.ray3d.direction,
        method="eye_fingertip",
        frame_id="another_camera",
    )
    hand = Hand(
        hand="right",
        score=0.95,
        landmarks=hand.landmarks,
        gesture="point",
        ray=Ray(origin=hand.ray.origin, direction=hand.ray.direction, confidence=0.9, ray3d=other),
    )
    assert pointed(objects, hand) == "B"


def test_mean_ray_averages_a_gesture_and_keeps_the_hit_most_observations_saw():
    r1 = space.Ray3((0, 0, 1), (1, 0, 0), "eye_fingertip", FRAME, (1.0, 0.5, 2.0))
    r2 = space.Ray3((0, 0, 1.2), (0, 1, 0), "forearm", FRAME, None)
    r3 = space.Ray3((0, 0, 1.1), (1, 0, 0), "eye_fingertip", FRAME, (1.2, 0.5, 2.0))
    m = space.mean_ray([(r1, 1.0), (r2, 1.0), (r3, 1.0)])
    assert m.method == "eye_fingertip" and m.origin[2] == pytest.approx(1.1)
    assert m.direction == pytest.approx(tuple(unit([2, 1, 0])))
    assert m.hit == pytest.approx((1.1, 0.5, 2.0))
    assert space.mean_ray([(r2, 1.0), (r2, 1.0), (r1, 1.0)]).hit is None


# ---------------------------------------------------------------------------
# Nearest / farthest
# ---------------------------------------------------------------------------
def test_the_nearest_bottle_by_depth_not_by_the_lowest_box():
    """The farther bottle stands lower in the image (on the floor, 2.5 m); the nearer one on a shelf (1 m)."""
    floor = thing("floor_bottle", "bottle", [0.0, 0.6, 2.5])
    shelf = thing("shelf_bottle", "bottle", [0.3, 0.1, 1.0])
    assert floor.bbox[1] + floor.bbox[3] > shelf.bbox[1] + shelf.bbox[3]  # the floor bottle is the lower one
    w = Weights(speech=1.0, vision=0.0, gesture=0.0)
    for text, depth, expected in (
        ("the nearest bottle", True, "shelf_bottle"),
        ("the farthest bottle", True, "floor_bottle"),
        ("the nearest bottle", False, "floor_bottle"),
    ):  # 2-D: lowest = nearest
        ranked = score(parse(f"pick up {text}").obj, scene_objects([detections([floor, shelf], depth=depth)]), None, w)
        assert ranked[0].obj.id == expected, text
        assert ranked[0].total - ranked[1].total > 0.3, text


# ---------------------------------------------------------------------------
# "Go there"
# ---------------------------------------------------------------------------
def test_go_there_is_the_hit_in_metres_and_its_pixel():
    spot = np.array([-0.5, 0.9, 2.0])  # on the floor, 0.9 m below the camera's axis
    objects = [thing("far", "chair", [1.0, 0.5, 4.0]), thing("near", "bottle", [0.6, 0.5, 1.5])]
    hand = pointing_hand(spot, hit=spot)
    p = select_pointing(pointing_from_hands(hands(hand)), BASE_STAMP)
    loc = pointed_location(p, scene_objects([detections(objects)]))
    assert loc.position == pytest.approx(list(spot), abs=1e-3) and loc.frame_id == FRAME
    assert (loc.x, loc.y) == pytest.approx(tuple(project(spot)), abs=0.5)  # the pinhole fitted to the objects


def test_an_object_behind_the_spot_on_the_floor_is_not_there():
    spot = np.array([-0.5, 0.9, 2.0])
    d = unit(spot - EYES)
    beyond = EYES + 4.0 * d  # on the ray's line, 1.6 m past the floor: hidden by the floor in fact
    objects = [thing("beyond", "box", beyond, size=(0.4, 0.4, 0.4))]
    p = select_pointing(pointing_from_hands(hands(pointing_hand(spot, hit=spot))), BASE_STAMP)
    assert best_pointed(p, scene_objects([detections(objects)])).gesture > 0.9
    loc = pointed_location(p, scene_objects([detections(objects)]))
    assert loc.position == pytest.approx(list(spot), abs=1e-3)
    # a box in front of the spot is "there"
    before = EYES + 1.5 * d
    loc = pointed_location(p, scene_objects([detections([thing("before", "box", before, size=(0.3, 0.3, 0.3))])]))
    assert loc.position == pytest.approx(list(before), abs=1e-3)


def test_fit_projection_recovers_the_pinhole_despite_an_odd_object():
    objects = scene_objects(
        [
            detections(
                [
                    thing("a", "cup", [0.1, 0.2, 1.0]),
                    thing("b", "cup", [-0.5, 0.3, 2.0]),
                    thing("c", "cup", [0.7, -0.2, 3.0]),
                ]
            )
        ]
    )
    assert space.fit_projection(objects) == pytest.approx((F, CX, CY))
    odd = DetectedObject(
        id="table",
        label="dining table",
        score=0.5,
        bbox=[0, 100, 640, 380],
        center=[320, 290],
        position=[0.4, 0.35, 1.5],
        extent=[1.5, 0.5, 1.2],
    )  # its median point is not its centre
    objects = scene_objects(
        [detections([thing("a", "cup", [0.1, 0.2, 1.0]), thing("b", "cup", [-0.5, 0.3, 2.0]), odd])]
    )
    assert space.fit_projection(objects)[0] == pytest.approx(F, rel=0.01)
    on_axis = scene_objects([detections([thing("a", "cup", [0.01, 0.02, 1.0])])])
    assert space.fit_projection(on_axis) is None


# ---------------------------------------------------------------------------
# Through the core: a FusedCommand carries the target's position
# ---------------------------------------------------------------------------
def test_a_command_carries_position_extent_and_frame():
    places = [[-0.8, 0.5, 2.4], [0.6, 0.5, 1.2]]
    objects = [thing("b0", "bottle", places[0]), thing("b1", "bottle", places[1])]
    steps = [step(t / 10, lambda s: detections(objects, stamp=s)) for t in range(-10, 20, 2)]
    steps += [step(t / 10, lambda s: hands(pointing_hand(np.array(places[0])), stamp=s)) for t in range(-10, 20)]
    steps.append(say(0.0, 0.8, "pick up that bottle"))
    out = run_in_process(Scenario("3-D", sorted(steps, key=lambda s: s.t), []))
    assert len(out) == 1 and out[0].target is not None, out
    target = out[0].target
    assert target.id == "b0" and target.position == pytest.approx(places[0]) and target.frame_id == FRAME
    assert target.extent == pytest.approx([0.08, 0.22, 0.08])
    assert "at (-0.80, 0.50, 2.40) m in cam0_optical" in out[0].prompt  # the planner sees metres
    assert "3-D ray (eye_fingertip) from (0.45, -0.55, 3.20) m" in out[0].prompt


# ---------------------------------------------------------------------------
# "On my left": the speaker's side, from the body's orientation
# ---------------------------------------------------------------------------
def body(facing: bool | None) -> Body:
    """A standing person in the middle of the image: facing the camera (their left shoulder on the image's right),
    their back to it, or side-on (None: shoulders one behind the other)."""
    p = [[320.0, 150.0]] * 33
    p = [list(q) for q in p]
    if facing is None:
        p[11], p[12] = [322.0, 200.0], [318.0, 200.0]
    else:
        left, right = (370.0, 270.0) if facing else (270.0, 370.0)
        p[11], p[12] = [left, 200.0], [right, 200.0]
    p[23], p[24] = [p[11][0] - 10, 330.0], [p[12][0] + 10, 330.0]
    return Body(landmarks=p, visibility=[0.99] * 33)


def body_step(person: Body | None, t: float) -> Step:
    """The Bodies of `person` at `t` seconds after the base stamp."""
    return Step(t, lambda base: (KEYS.bodies("cam0"), bodies(person, base + t)))


def bodies(b: Body | None, stamp: float) -> Bodies:
    return Bodies(
        stamp=stamp, source="gesture/cam0", seq=1, cam="cam0", width=W, height=H, bodies=[] if b is None else [b]
    )


def test_side_words_said_from_the_speaker():
    assert space.said_from_speaker("pick up the cup on my left") == {"left"}
    assert space.said_from_speaker("bring me the one to my Right, please") == {"right"}
    assert space.said_from_speaker("the bottle left of me") == {"left"}
    assert space.said_from_speaker("the cup on your left") == set()
    assert space.said_from_speaker("the left cup") == set()


def test_facing_from_the_shoulders():
    assert space.facing_camera(body(True).landmarks, body(True).visibility) is True
    assert space.facing_camera(body(False).landmarks, body(False).visibility) is False
    assert space.facing_camera(body(None).landmarks, body(None).visibility) is None
    hidden = Body(landmarks=body(True).landmarks, visibility=[0.1] * 33)
    assert space.facing_camera(hidden.landmarks, hidden.visibility) is None


def run_with_body(text: str, person: Body | None) -> str:
    """Two cups, one on each side of the image; the person's body (if any) seen throughout."""
    cups = [
        DetectedObject(id="image_left", label="cup", score=0.9, bbox=[60, 300, 60, 80], center=[90, 340]),
        DetectedObject(id="image_right", label="cup", score=0.9, bbox=[520, 300, 60, 80], center=[550, 340]),
    ]

    def see(s):
        return Detections(
            stamp=s,
            source="vision/cam0",
            seq=1,
            cam="cam0",
            width=W,
            height=H,
            objects=cups,
            quality=ImageQuality(brightness=0.5, contrast=0.5, sharpness=0.6),
        )

    steps = [step(t / 10, see) for t in range(-10, 20, 2)]
    if person is not None:
        steps += [body_step(person, t / 10) for t in range(-10, 20, 2)]
    steps.append(say(0.0, 0.8, text))
    from services.fusion.core import Config, FusionCore

    core = FusionCore(Config(), "fusion/test")
    for modality in ("vision", "gesture"):
        core.on_liveliness(modality, "test", True)
    out = []
    for s in sorted(steps, key=lambda s: s.t):
        out += [o.sample for o in deliver(core, *s.build(BASE_STAMP), 1000.0)] + [o.sample for o in core.tick(1000.0)]
    out += [o.sample for o in core.tick(2000.0)]
    assert len(out) == 1, out
    command = out[0]
    assert isinstance(command, FusedCommand) and command.target is not None, out
    return command.target.id


@pytest.mark.parametrize(
    "text,person,expected",
    [
        ("pick up the cup on my left", body(True), "image_right"),  # face to face: my left is your right
        ("pick up the cup on my right", body(True), "image_left"),
        ("pick up the cup on my left", body(False), "image_left"),  # seen from behind: the same side as the camera
        ("pick up the cup on my left", None, "image_right"),  # not seen: taken to face the robot
        ("pick up the cup on your left", body(True), "image_left"),  # the robot's = the camera's
        ("pick up the left cup", body(True), "image_left"),
    ],
)
def test_on_my_left_is_the_speakers_left(text, person, expected):
    assert run_with_body(text, person) == expected

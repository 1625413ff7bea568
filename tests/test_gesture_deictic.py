"""Fusion's deictic grounding with hand and body rays: what lies under the fingertip wins over what lies further
along the ray (services/fusion/ground.py, pure). Boxes are those the colour vision finds on the real photo
../shared/data/pointing/nico_table_f07_green_cube.jpg (a green cube under the fingertip, its dark shadow below it
on the same line), so the geometry is a real table's."""

from common.schema import Weights
from services.fusion.evidence import Pointing
from services.fusion.ground import SceneObject, choose, score, under_fingertip
from services.fusion.parse import ObjectPhrase

GESTURE_ONLY = Weights(speech=0.5, vision=0.0, gesture=0.5)


def obj(id_, color, bbox):
    x, y, w, h = bbox
    return SceneObject(
        id=id_,
        label="object",
        raw_label="object",
        color=color,
        bbox=bbox,
        center=(x + w / 2, y + h / 2),
        score=0.9,
        cam="cam0",
        width=700,
        height=950,
        stamp=100.0,
        quality=1.0,
    )


GREEN = obj("g", "green", (429.0, 495.0, 89.0, 63.0))
SHADOW = obj("s", "black", (424.0, 560.0, 90.0, 80.0))  # below the cube: further along the same ray
RED = obj("r", "red", (144.0, 511.0, 95.0, 86.0))
YELLOW = obj("y", "yellow", (276.0, 577.0, 98.0, 90.0))


def pointing(origin, direction, hand_box=None):
    return Pointing(
        stamp=100.0,
        cam="cam0",
        hand="right",
        origin=origin,
        direction=direction,
        confidence=0.9,
        stability=0.9,
        spread_deg=2.0,
        n=5,
        width=700,
        height=950,
        hand_box=hand_box,
    )


# the body ray from the fingertip (449, 471), and the hand ray from the index knuckle with the hand's box
BODY_RAY = pointing((449.0, 471.0), (0.2425, 0.9701))
HAND_RAY = pointing((435.0, 352.0), (0.1376, 0.9905), hand_box=(400.0, 300.0, 470.0, 475.0))


def test_the_object_under_the_fingertip_wins_over_the_one_further_along_the_ray():
    for ray in (BODY_RAY, HAND_RAY):
        assert under_fingertip(ray, GREEN) and not under_fingertip(ray, SHADOW)
        scored = score(ObjectPhrase(deictic=True), [SHADOW, GREEN, RED, YELLOW], ray, GESTURE_ONLY)
        choice = choose(ObjectPhrase(deictic=True), scored)
        assert choice.kind == "target" and choice.winner.obj is GREEN, [(c.obj.id, c.total) for c in scored]
        assert scored[1].obj is SHADOW and scored[1].gesture <= 0.5


def test_without_the_near_object_the_one_along_the_ray_is_chosen():
    scored = score(ObjectPhrase(deictic=True), [SHADOW, RED, YELLOW], BODY_RAY, GESTURE_ONLY)
    assert scored[0].obj is SHADOW and scored[0].gesture > 0.9


def test_an_object_beside_the_finger_is_not_under_it():
    assert not under_fingertip(BODY_RAY, RED) and not under_fingertip(BODY_RAY, YELLOW)
    across = pointing((449.0, 471.0), (1.0, 0.0))  # pointing sideways: the cube below is not under it
    assert not under_fingertip(across, GREEN)

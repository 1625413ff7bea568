"""The wire contract: every schema round-trips; every kind of bad payload is rejected with a clear reason."""

import copy
import math

import msgpack
import pytest

from common.codec import decode, encode
from common.keys import Keys
from common.schema import (
    ALL_SAMPLES,
    AudioChunk,
    Clarification,
    DepthFrame,
    Detections,
    Frame,
    FusedCommand,
    GestureEvent,
    Hands,
    InvalidSample,
    Ray,
    Stats,
    Transcript,
)
from testkit.examples import LANDMARKS, T, examples


def test_every_schema_has_an_example():
    assert {type(s) for s in examples()} == set(ALL_SAMPLES)


@pytest.mark.parametrize("sample", examples(), ids=lambda s: type(s).__name__)
def test_round_trip(sample):
    payload = encode(sample)
    assert isinstance(payload, bytes)
    back = decode(payload, type(sample))
    assert back == sample
    assert back.to_dict() == msgpack.unpackb(payload)


@pytest.mark.parametrize("sample", examples(), ids=lambda s: type(s).__name__)
def test_each_required_field_missing_is_rejected(sample):
    data = sample.to_dict()
    required = type(sample).required_fields()
    assert {"stamp", "source"} <= set(required)
    for name in required:
        broken = {k: v for k, v in data.items() if k != name}
        with pytest.raises(InvalidSample) as err:
            decode(msgpack.packb(broken), type(sample))
        assert err.value.reason == "missing_field" and name in err.value.detail


@pytest.mark.parametrize("sample", examples(), ids=lambda s: type(s).__name__)
def test_each_field_with_the_wrong_type_is_rejected(sample):
    data = sample.to_dict()
    for name, value in data.items():
        wrong = {"x": 1} if not isinstance(value, dict) else "not a map"
        broken = {**data, name: wrong}
        with pytest.raises(InvalidSample) as err:
            decode(msgpack.packb(broken), type(sample))
        assert err.value.reason in ("wrong_type", "bad_value"), (name, err.value)


def test_unknown_fields_are_ignored():
    sample = examples()[5]
    data = {**sample.to_dict(), "added_in_v1_5": {"anything": [1, 2]}}
    assert decode(msgpack.packb(data), Transcript) == sample


def _nested_set(data, path, value):
    node = data
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value


INVALID = [
    # (schema index, path in the map, bad value, expected reason)
    (0, ["stamp"], float("nan"), "not_finite"),
    (0, ["stamp"], float("inf"), "not_finite"),
    (0, ["stamp"], -5.0, "out_of_range"),
    (0, ["v"], 2, "bad_version"),
    (0, ["seq"], True, "wrong_type"),
    (0, ["encoding"], "gif", "bad_value"),
    (0, ["data"], bytes(11), "bad_value"),  # bgr8 size does not match width*height*3
    (0, ["width"], 0, "out_of_range"),
    (0, ["source"], "", "bad_value"),
    (1, ["rate"], 12, "out_of_range"),
    (1, ["data"], bytes(3), "bad_value"),  # half an s16 sample
    (1, ["format"], "f32le", "bad_value"),
    (2, ["objects", 0, "score"], 1.5, "out_of_range"),
    (2, ["objects", 0, "bbox"], [1, 2, 3], "bad_value"),
    (2, ["objects", 0, "bbox", 2], float("nan"), "not_finite"),
    (2, ["objects", 0, "center"], "middle", "wrong_type"),
    (2, ["quality", "sharpness"], -0.1, "out_of_range"),
    (2, ["objects"], {"o1": 1}, "wrong_type"),
    (3, ["hands", 0, "landmarks"], LANDMARKS[:20], "bad_value"),
    (3, ["hands", 0, "landmarks", 4], [1.0], "bad_value"),
    (3, ["hands", 0, "hand"], "middle", "bad_value"),
    (3, ["hands", 0, "ray", "direction"], [3.0, 4.0], "bad_value"),  # not a unit vector
    (4, ["phase"], "begin", "bad_value"),
    (4, ["start"], T + 5, "bad_value"),  # start after end
    (5, ["final"], 1, "wrong_type"),
    (5, ["words", 0, "confidence"], float("-inf"), "not_finite"),
    (5, ["confidence"], 2, "out_of_range"),
    (6, ["weights", "speech"], "high", "wrong_type"),
    (6, ["inputs", "speech"], "now", "wrong_type"),
    (6, ["target", "cam"], None, "wrong_type"),
    (7, ["reason"], "confused", "bad_value"),
    (7, ["candidates", 1], [], "wrong_type"),
]


@pytest.mark.parametrize(
    "index,path,value,reason",
    INVALID,
    ids=[f"{type(examples()[i]).__name__}.{'.'.join(str(step) for step in p)}" for i, p, _, _ in INVALID],  # type: ignore[attr-defined]  # rows are (int, list, value, str)
)
def test_invalid_values_are_rejected_with_a_reason(index, path, value, reason):
    sample = examples()[index]
    data = copy.deepcopy(sample.to_dict())
    _nested_set(data, path, value)
    with pytest.raises(InvalidSample) as err:
        decode(msgpack.packb(data), type(sample))
    assert err.value.reason == reason
    assert err.value.detail  # says where


@pytest.mark.parametrize("sample", examples(), ids=lambda s: type(s).__name__)
def test_truncated_msgpack_is_rejected(sample):
    payload = encode(sample)
    for cut in (1, len(payload) // 2, len(payload) - 1):
        with pytest.raises(InvalidSample) as err:
            decode(payload[:cut], type(sample))
        assert err.value.reason in ("not_msgpack", "not_a_map", "missing_field")


@pytest.mark.parametrize(
    "payload,reason",
    [
        (b"", "not_msgpack"),
        (b"\xc1", "not_msgpack"),  # never-used msgpack byte
        (msgpack.packb([1, 2, 3]), "not_a_map"),
        (msgpack.packb("pick up the cup"), "not_a_map"),
        (msgpack.packb(None), "not_a_map"),
        (b"\x81\xa1v\x01" + b"garbage", "not_msgpack"),  # a map followed by trailing bytes
        (b'{"json": "is not msgpack"}', "not_msgpack"),
    ],
)
def test_not_a_sample_at_all(payload, reason):
    with pytest.raises(InvalidSample) as err:
        decode(payload, Transcript)
    assert err.value.reason == reason


def test_oversized_payload_is_rejected_before_parsing():
    big = Transcript.MAX_BYTES + 1
    with pytest.raises(InvalidSample) as err:
        decode(b"\x00" * big, Transcript)
    assert err.value.reason == "oversized"
    sample = examples()[5]
    sample.text = "x" * big
    with pytest.raises(InvalidSample) as err:
        encode(sample)
    assert err.value.reason == "oversized"


def test_encode_refuses_what_decode_would_reject():
    sample = examples()[2]
    sample.objects[0].score = math.nan
    with pytest.raises(InvalidSample) as err:
        encode(sample)
    assert err.value.reason == "not_finite"


def test_keys_map_to_schemas_under_any_prefix():
    for prefix in ("hri", "lab/robot7"):
        keys = Keys(prefix)
        assert keys.schema_for(keys.frame("cam0")) is Frame
        assert keys.schema_for(keys.audio("m")) is AudioChunk
        assert keys.schema_for(keys.objects("cam0")) is Detections
        assert keys.schema_for(keys.hands("cam0")) is Hands
        assert keys.schema_for(keys.gesture_event("cam0")) is GestureEvent
        assert keys.schema_for(keys.transcript("m")) is Transcript
        assert keys.schema_for(keys.command()) is FusedCommand
        assert keys.schema_for(keys.clarification()) is Clarification
        assert keys.schema_for(keys.stats("vision", "a")) is Stats
        assert keys.schema_for(f"{prefix}/camera/cam0/other") is None
        assert keys.schema_for("elsewhere/camera/cam0/frame") is None
        assert keys.parse_alive(keys.alive("vision", "host-1")) == ("vision", "host-1")
    with pytest.raises(ValueError):
        Keys().frame("a/b")


# msgspec's error messages -> the documented reasons: the one table in common.schema, each row exercised.
@pytest.mark.parametrize(
    "index,change,reason",
    [
        (5, {"words": [{"word": "pick", "start": T - 9.0, "end": T - 8.9, "confidence": 0.9}]}, "bad_value"),
        (5, {"words": [{"word": "pick", "start": T - 0.5, "end": T - 0.6, "confidence": 0.9}]}, "bad_value"),
        (0, {"seq": -1}, "out_of_range"),  # int bound
        (0, {"cam": ""}, "bad_value"),  # empty string
        (3, {"hands": [{"hand": "left"}]}, "missing_field"),  # nested missing field
        (6, {"inputs": {1: 2.0}}, "wrong_type"),  # map key of the wrong type
        (6, {"weights": []}, "wrong_type"),  # nested map given as a list
        (6, {"confidence": float("nan")}, "not_finite"),  # NaN against a 0–1 bound
        (6, {"location": {"x": float("-inf"), "y": 0, "cam": "c"}}, "not_finite"),
        (6, {"motion": {"direction": "forward", "distance": -1.0}}, "out_of_range"),
        (9, {"bodies": [{"landmarks": [[0.0, 0.0]] * 33, "visibility": [1.5] * 33}]}, "out_of_range"),
        (9, {"bodies": [{"landmarks": [[0.0, 0.0]] * 32, "visibility": [0.5] * 33}]}, "bad_value"),
    ],
)
def test_each_row_of_the_error_table(index, change, reason):
    sample = examples()[index]
    data = {**sample.to_dict(), **change}
    with pytest.raises(InvalidSample) as err:
        decode(msgpack.packb(data), type(sample))
    assert err.value.reason == reason, err.value
    with pytest.raises(InvalidSample) as err:  # the same reason through from_dict (hri pub's path)
        type(sample).from_dict(msgpack.unpackb(msgpack.packb(data), strict_map_key=False))
    assert err.value.reason == reason, err.value


def test_nesting_too_deep_is_malformed_not_a_crash():
    deep = b"\x91" * 200_000 + b"\x01"
    payload = b"\x82\xa1v\x01\xa4deep" + deep
    with pytest.raises(InvalidSample) as err:
        decode(payload, Transcript)
    assert err.value.reason == "not_msgpack"


def test_malformed_msgpack_wins_over_a_missing_field():
    # msgspec checks fields as it parses: a map cut short must still be reported as not MessagePack
    with pytest.raises(InvalidSample) as err:
        decode(msgpack.packb({"v": 1}) + b"\xc1", Transcript)
    assert err.value.reason == "not_msgpack"


def test_encode_refuses_values_msgpack_has_no_form_for():
    import numpy as np

    sample = examples()[2]
    sample.objects[0].score = np.float32(0.5)
    with pytest.raises(InvalidSample) as err:
        encode(sample)
    assert err.value.reason == "wrong_type"


def test_constructing_a_sample_checks_its_cross_field_rules():
    with pytest.raises(InvalidSample) as err:
        Ray(origin=[0.0, 0.0], direction=[3.0, 4.0])
    assert err.value.reason == "bad_value" and "unit vector" in err.value.detail


def test_plain_msgpack_reads_and_writes_the_wire_format():
    # any MessagePack library is a valid peer: the contract path and the plain msgpack package agree
    for sample in examples():
        plain = msgpack.unpackb(encode(sample), raw=False)
        assert plain == sample.to_dict()
        assert decode(msgpack.packb(plain, use_bin_type=True), type(sample)) == sample


# --- v1 extensions: colour measurement and 3-D ---------------------------------------------------------------
def _reason(schema, data):
    with pytest.raises(InvalidSample) as err:
        decode(msgpack.packb(data), schema)
    return err.value.reason, err.value.detail


def test_intrinsics_of_another_resolution_are_refused():
    frame = examples()[0].to_dict()  # a 2x2 Frame with its intrinsics
    frame["camera_info"]["width"] = 640
    reason, detail = _reason(Frame, frame)
    assert reason == "bad_value" and "640x2" in detail and "2x2" in detail


def test_a_matrix_that_is_not_a_camera_matrix_is_refused():
    depth = examples()[-1].to_dict()
    depth["camera_info"]["k"][8] = 2.0
    assert _reason(DepthFrame, depth)[0] == "bad_value"
    depth = examples()[-1].to_dict()
    depth["camera_info"]["k"][0] = 0.0
    assert _reason(DepthFrame, depth)[0] == "bad_value"


def test_depth_sizes_and_png_rule():
    depth = examples()[-1].to_dict()
    depth["data"] = bytes(7)
    assert _reason(DepthFrame, depth)[0] == "bad_value"
    depth = examples()[-1].to_dict()
    depth["encoding"], depth["data"] = "32FC1", bytes(16)
    assert decode(msgpack.packb(depth), DepthFrame).encoding == "32FC1"
    depth["compression"] = "png"
    assert _reason(DepthFrame, depth)[0] == "bad_value"  # png carries 16UC1 only
    depth = examples()[-1].to_dict()
    depth["depth_scale"] = 0.0
    assert _reason(DepthFrame, depth)[0] == "out_of_range"


def test_object_measurements_are_checked():
    dets = examples()[2].to_dict()
    dets["objects"][1]["position"][2] = 0.0
    reason, detail = _reason(Detections, dets)
    assert reason == "bad_value" and "objects[1].position" in detail
    dets = examples()[2].to_dict()
    dets["objects"][1]["lab"][0] = 140.0
    assert _reason(Detections, dets)[0] == "out_of_range"
    dets = examples()[2].to_dict()
    dets["objects"][1]["colors"][0]["p"] = 1.5
    assert _reason(Detections, dets)[0] == "out_of_range"


def test_a_3d_ray_is_a_unit_vector():
    hands = examples()[3].to_dict()
    hands["hands"][0]["ray"]["ray3d"]["direction"] = [0.0, 1.0, 1.0]
    assert _reason(Hands, hands)[0] == "bad_value"


def test_a_sender_from_before_the_extensions_still_decodes():
    """Backward compatibility within v1: none of the new fields is required."""
    dets = examples()[2].to_dict()
    for o in dets["objects"]:
        for key in ("lab", "colors", "position", "extent", "depth_support"):
            o.pop(key, None)
    dets.pop("frame_id")
    back = decode(msgpack.packb(dets), Detections)
    assert back.objects[1].colors == [] and back.objects[1].position is None and back.frame_id is None

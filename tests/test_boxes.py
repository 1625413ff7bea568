"""common/boxes.py: the IoU and the greedy matching every tracker here shares."""

from __future__ import annotations

from common.boxes import iou, match_in_order


def test_iou_of_equal_disjoint_and_half_overlapping_boxes() -> None:
    assert iou([0, 0, 10, 10], [0, 0, 10, 10]) == 1.0
    assert iou([0, 0, 10, 10], [20, 0, 10, 10]) == 0.0
    assert iou([0, 0, 10, 10], [5, 0, 10, 10]) == 50 / 150
    assert iou([0, 0, 0, 0], [0, 0, 0, 0]) == 0.0


def test_matching_takes_pairs_in_the_given_order_each_side_once() -> None:
    # track 0 fits detection 1 best; track 1 then gets detection 0, not detection 1 again; track 2 gets nothing
    pairs = [(0.9, 0, 1), (0.8, 1, 1), (0.7, 1, 0), (0.6, 0, 0), (0.5, 2, 0)]
    assert match_in_order(pairs) == {1: 0, 0: 1}
    # the caller's order decides, not the score: the same pairs taken worst first
    assert match_in_order(reversed(pairs)) == {0: 2, 1: 1}
    assert match_in_order([]) == {}

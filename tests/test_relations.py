"""Properties of the Table 1 predicates, in any units (hypothesis draws the coordinates)."""
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from zsrm.tasks.relations import (
    RELATIONS, WORLD_THRESHOLDS, Thresholds, behind, below, camera_plane, close_to, holds_in_world,
    in_between, in_front_of, inside_of, left_of, on_top_of, right_of,
)

# Quarter units: sums and differences are exact, so no property flips on a rounding error.
def quarters(lo, hi):
    return st.integers(lo * 4, hi * 4).map(lambda n: n / 4)


coord = quarters(-100, 100)
point = st.tuples(coord, coord).map(np.array)
thresholds = st.builds(
    Thresholds,
    gap=quarters(0, 5), eps_x=quarters(1, 20), eps_y=quarters(1, 40), close=quarters(1, 30), inside=quarters(0, 1),
)


@given(point, point, thresholds)
def test_left_and_right_exclude_each_other(a, b, t):
    assert not (left_of(a, b, t) and right_of(a, b, t))
    assert left_of(a, b, t) == right_of(b, a, t)


@given(point, point, thresholds)
def test_on_top_of_implies_not_below(a, b, t):
    if on_top_of(a, b, t):
        assert not below(a, b, t)
    assert below(a, b, t) == on_top_of(b, a, t)


@given(point, point, thresholds)
def test_on_top_of_needs_horizontal_alignment_and_height(a, b, t):
    if on_top_of(a, b, t):
        assert abs(a[0] - b[0]) < t.eps_x and b[1] < a[1] < b[1] + t.eps_y


@given(point, point, thresholds)
def test_in_front_of_and_behind_exclude_each_other(a, b, t):
    assert not (in_front_of(a, b, t) and behind(a, b, t))
    assert in_front_of(a, b, t) == behind(b, a, t)


@given(point, point, point, thresholds)
def test_in_between_is_symmetric_in_the_outer_objects(a, b, c, t):
    assert in_between(a, b, c, t) == in_between(a, c, b, t)
    if in_between(a, b, c, t):
        # Between means right of one and left of the other.
        assert (left_of(a, b, t) and right_of(a, c, t)) or (left_of(a, c, t) and right_of(a, b, t))


@given(point, point, thresholds)
def test_inside_of_implies_close_to_and_both_are_symmetric(a, b, t):
    if inside_of(a, b, t):
        assert close_to(a, b, t)  # inside's radius is the smaller one
    assert close_to(a, b, t) == close_to(b, a, t)


@given(point, thresholds)
def test_nothing_is_left_right_or_on_top_of_itself(a, t):
    assert not left_of(a, a, t) and not right_of(a, a, t) and not on_top_of(a, a, t)


def test_predicates_are_vectorised():
    a = np.array([[0.0, 0.0], [2.0, 0.0]])
    b = np.array([[1.0, 0.0], [1.0, 0.0]])
    np.testing.assert_array_equal(left_of(a, b, WORLD_THRESHOLDS), [True, False])


def test_every_relation_names_a_camera_and_arity():
    assert len(RELATIONS) == 9
    cameras = {r.name: r.camera for r in RELATIONS.values()}
    assert {n for n, c in cameras.items() if c == "front"} == {"left_of", "right_of", "on_top_of", "below", "in_between"}
    assert {n for n, c in cameras.items() if c == "left"} == {"in_front_of", "behind"}
    assert {n for n, c in cameras.items() if c == "tilted"} == {"close_to", "inside_of"}
    assert RELATIONS["in_between"].arity == 3
    with pytest.raises(ValueError, match="relates 3 objects"):
        RELATIONS["in_between"](np.zeros(2), np.zeros(2), thresholds=WORLD_THRESHOLDS)


def test_camera_plane_matches_the_paper_frames():
    p = np.array([0.1, 0.2, 0.5])  # x right, y away from the front camera, z up
    np.testing.assert_allclose(camera_plane(p, "front"), [0.1, 0.5])
    np.testing.assert_allclose(camera_plane(p, "left"), [-0.2, 0.5])  # left camera's x points to the front
    np.testing.assert_allclose(camera_plane(p, "tilted"), [0.1, 0.2])
    with pytest.raises(ValueError, match="known cameras: front, left, tilted"):
        camera_plane(p, "top")


def test_oracle_on_world_positions():
    red = np.array([0.0, 0.0, 0.43])
    yellow_on_red = red + (0.005, 0, 0.06)
    yellow_beside = red + (0.08, 0, 0)
    assert holds_in_world("on_top_of", [yellow_on_red, red])
    assert not holds_in_world("on_top_of", [yellow_beside, red])
    assert holds_in_world("right_of", [yellow_beside, red])
    assert holds_in_world("in_front_of", [red - (0, 0.1, 0), red])  # closer to the front camera
    assert holds_in_world("close_to", [yellow_beside, red])
    assert not holds_in_world("close_to", [red + (0.3, 0, 0), red])


def test_thresholds_scale_to_pixels():
    px = WORLD_THRESHOLDS.scaled(100.0)
    assert px.eps_x == pytest.approx(WORLD_THRESHOLDS.eps_x * 100)
    assert px.close == pytest.approx(WORLD_THRESHOLDS.close * 100)


@given(point, point, point, thresholds)
def test_a_relations_mirror_holds_on_the_coordinates_mirrored_left_to_right(a, b, c, t):
    """The table's ``mirror`` (what zsrm distill --mirror reads a flipped frame's goal as)."""
    flip = np.array([-1.0, 1.0])
    for relation in RELATIONS.values():
        if relation.mirror is None:
            continue
        coords = (a, b, c)[:relation.arity]
        assert relation(*coords, thresholds=t) == RELATIONS[relation.mirror](*(p * flip for p in coords), thresholds=t)

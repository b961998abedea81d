"""The spatial labeler on hand-made pixel coordinates: every relation of Table 1, with the
row flip (pixel rows point down, Table 1's y points up) and per-camera pixel thresholds."""
import numpy as np
import pytest

from zsrm.grounding.labeler import SpatialLabeler, pixel_thresholds, world_table
from zsrm.tasks.language import Task
from zsrm.tasks.relations import RELATIONS, WORLD_THRESHOLDS

# 6 px per 6 cm block: 100 px per metre, so gap 1 px, eps_x 3, eps_y 9, close 10, inside 2.
# The colours and the box, which only "inside of" relates (a block inside of it).
LABELER = SpatialLabeler.from_block_widths({"front": 6.0, "left": 6.0, "tilted": 6.0},
                                           colours=("red", "green", "yellow", "blue", "box"))

CASES = {
    # relation: (coords, objects that must hold, objects that must not)
    "left_of": ({"front": {"red": (20, 30), "yellow": (40, 30)}}, ("red", "yellow"), ("yellow", "red")),
    "right_of": ({"front": {"red": (20, 30), "yellow": (40, 30)}}, ("yellow", "red"), ("red", "yellow")),
    # Row 30 is higher in the image than row 36: red sits on yellow.
    "on_top_of": ({"front": {"red": (30, 30), "yellow": (31, 36)}}, ("red", "yellow"), ("yellow", "red")),
    "below": ({"front": {"red": (30, 30), "yellow": (31, 36)}}, ("yellow", "red"), ("red", "yellow")),
    "in_between": ({"front": {"red": (30, 30), "yellow": (20, 30), "blue": (40, 30)}},
                   ("red", "yellow", "blue"), ("yellow", "red", "blue")),
    "in_front_of": ({"left": {"red": (40, 30), "yellow": (20, 30)}}, ("red", "yellow"), ("yellow", "red")),
    "behind": ({"left": {"red": (40, 30), "yellow": (20, 30)}}, ("yellow", "red"), ("red", "yellow")),
    "close_to": ({"tilted": {"red": (20, 20), "yellow": (25, 20), "blue": (50, 20)}},
                 ("red", "yellow"), ("red", "blue")),
    "inside_of": ({"tilted": {"red": (20, 20), "box": (21, 20), "blue": (25, 20)}},
                  ("red", "box"), ("blue", "box")),
}


def test_cases_cover_every_relation():
    assert set(CASES) == set(RELATIONS)


@pytest.mark.parametrize("relation", list(CASES))
def test_relation_from_pixels(relation):
    coords, yes, no = CASES[relation]
    captions = LABELER(coords)
    assert Task(relation, yes).text in captions
    assert Task(relation, no).text not in captions
    # Relations read off another camera never come from this camera's coordinates.
    camera = RELATIONS[relation].camera
    others = [RELATIONS[r].phrase for r in RELATIONS if RELATIONS[r].camera != camera]
    assert not any(f" {p} " in c for p in others for c in captions)


def test_stacked_blocks_too_far_apart_are_not_on_top():
    # 12 px up is two block widths: beyond eps_y (9 px), so not "on top of".
    captions = LABELER({"front": {"red": (30, 24), "yellow": (30, 36)}})
    assert Task("on_top_of", ("red", "yellow")).text not in captions


def test_missing_or_nan_objects_take_no_part():
    captions = LABELER({"front": {"red": (20, 30), "yellow": (np.nan, np.nan)}})
    assert captions == []


def test_unknown_colour_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown colour"):
        LABELER({"front": {"purple": (1, 2)}})
    with pytest.raises(ValueError, match="positive"):
        pixel_thresholds({"front": 0.0})


def test_batched_table_agrees_with_world_oracle_on_a_front_view():
    # Front camera plane: x = world x, y = world z; 100 px per metre, row = -100 z.
    positions = np.array([[[0.0, 0.0, 0.43], [0.2, 0.0, 0.43], [0.0, 0.0, 0.49], [0.1, 0.0, 0.43]]])
    present = np.ones((1, 4), bool)
    pixels = {"front": np.stack([100 * positions[..., 0], -100 * positions[..., 2]], -1)}
    table = SpatialLabeler.from_block_widths({"front": 6.0}, relations=("left_of", "on_top_of", "in_between"))
    got = table.table(pixels, present)
    world = world_table(positions, present, thresholds=WORLD_THRESHOLDS,
                        relations=("left_of", "on_top_of", "in_between"))
    for r in ("left_of", "on_top_of", "in_between"):
        np.testing.assert_array_equal(got.holds[r], world.holds[r])
    assert Task("on_top_of", ("yellow", "red")).text in got.captions()[0]


def test_table_cameras_are_read_in_metres():
    """A homography maps the tilted camera's pixels onto the table; its thresholds stay in
    metres while the other cameras' are scaled to pixels."""
    to_metres = np.diag([0.01, -0.01, 1.0])  # 1 px = 1 cm, rows down = y toward the camera
    th = pixel_thresholds({"front": 6.0, "tilted": 7.0}, table_cameras={"tilted"})
    assert th["tilted"] == WORLD_THRESHOLDS and th["front"].close == pytest.approx(10.0)
    labeler = SpatialLabeler(th, relations=("close_to",), table_homography={"tilted": to_metres})
    near = {"tilted": {"red": (20, 30), "yellow": (28, 30)}}  # 8 cm apart
    far = {"tilted": {"red": (20, 30), "yellow": (20, 42)}}  # 12 cm apart
    assert labeler(near) == ["a red block close to a yellow block", "a yellow block close to a red block"]
    assert labeler(far) == []


# --- on top of in 3-D (an own scene with calibrated cameras) -----------------------------------
SOLID = WORLD_THRESHOLDS  # metres: eps_x 3 cm over the footprint, at most 9 cm higher


def test_solid_on_top_of_reads_a_thin_stack_table_1_misses():
    """A bowl resting on a plate sits 8 mm over the plate's origin, under Table 1's 1 cm gap; in
    3-D it is over the plate's footprint and higher, and the reverse does not hold."""
    plate, bowl = np.array([0.0, 0.1, 0.8]), np.array([0.01, 0.105, 0.808])
    beside, held = np.array([0.12, 0.1, 0.8]), np.array([0.0, 0.1, 0.95])
    solid, below = RELATIONS["on_top_of"].solid, RELATIONS["below"].solid
    assert solid(bowl, plate, SOLID) and below(plate, bowl, SOLID)
    assert not solid(plate, bowl, SOLID) and not solid(beside, plate, SOLID) and not solid(held, plate, SOLID)
    positions, present = np.stack([bowl, plate])[None], np.ones((1, 2), bool)
    flat = world_table(positions, present, ("red", "yellow"), relations=("on_top_of",))
    deep = world_table(positions, present, ("red", "yellow"), relations=("on_top_of",), solid=True)
    assert flat.captions() == [[]]
    assert deep.captions() == [["a red block on top of a yellow block"]]


def test_labeler_triangulates_on_top_of_from_the_tilted_and_left_cameras():
    """Pixels of two points as a real scene's tilted and left cameras see them: the labeler with
    their rays reads the thin stack; without rays, Table 1 on the front camera does not."""
    import gymnasium as gym

    import zsrm.envs  # noqa: F401
    from zsrm.envs.cameras import pixel_rays, project

    env = gym.make("zsrm/Tabletop-v0", task="stack", cameras=("front",))
    env.reset(seed=0)
    base = env.unwrapped
    lower, upper = np.array([0.0, 0.0, 0.43]), np.array([0.005, 0.0, 0.438])
    cams = ("front", "left", "tilted")
    coords = {c: {"yellow": tuple(project(base, c, upper, 64)), "red": tuple(project(base, c, lower, 64))}
              for c in cams}
    rays = {c: pixel_rays(base, c, 64) for c in cams}
    env.close()
    widths = {"front": 6.0, "left": 6.0, "tilted": 6.0}
    flat = SpatialLabeler.from_block_widths(widths, colours=("red", "yellow"), relations=("on_top_of",))
    deep = SpatialLabeler(pixel_thresholds(widths), colours=("red", "yellow"), relations=("on_top_of",),
                          rays=rays, solid_thresholds=SOLID)
    assert flat(coords) == []
    assert deep(coords) == ["a yellow block on top of a red block"]
    points = deep.points({c: np.array([[coords[c]["red"], coords[c]["yellow"]]]) for c in cams})
    np.testing.assert_allclose(points[0], [lower, upper], atol=1e-6)
    with pytest.raises(ValueError, match="rays of the tilted and left"):
        SpatialLabeler(pixel_thresholds(widths), rays={"front": rays["front"]}, solid_thresholds=SOLID)

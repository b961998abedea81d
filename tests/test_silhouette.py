"""Refining a Grad-CAM point to its object's silhouette (zsrm.grounding.silhouette)."""
import numpy as np
import pytest

from zsrm.grounding.silhouette import Silhouette, calibrate, refine_point, refine_points, region_area

TABLE = (222, 191, 154)  # the tabletop's colour
RED, GREEN, WHITE = (200, 30, 30), (30, 180, 40), (240, 240, 240)


def scene(*squares, size=32):
    """A table-coloured image with filled squares (colour, x0, y0, x1, y1), later ones on top."""
    image = np.empty((size, size, 3), np.float32)
    image[:] = TABLE
    for colour, x0, y0, x1, y1 in squares:
        image[y0:y1, x0:x1] = colour
    return image


def test_point_moves_to_the_centre_of_its_object():
    image = scene((RED, 10, 12, 16, 18))  # centre (12.5, 14.5)
    xy = refine_point(image, (14.0, 16.0), Silhouette(half_window=7))
    np.testing.assert_allclose(xy, [12.5, 14.5])


def test_calibrated_offset_is_taken_off():
    image = scene((RED, 10, 12, 16, 18))
    xy = refine_point(image, (14.0, 16.0), Silhouette(half_window=7, offset=(0.5, -1.0)))
    np.testing.assert_allclose(xy, [12.0, 15.5])


def test_not_found_and_nothing_there_keep_the_point():
    sil = Silhouette(half_window=5)
    assert np.isnan(refine_point(scene(), (np.nan, np.nan), sil)).all()
    np.testing.assert_allclose(refine_point(scene(), (9.0, 9.0), sil), [9.0, 9.0])  # bare table


def test_touching_blocks_of_two_colours_stay_apart():
    image = scene((RED, 8, 10, 14, 16), (GREEN, 14, 10, 20, 16))
    sil = Silhouette(half_window=8, area=36)
    np.testing.assert_allclose(refine_point(image, (12.0, 13.0), sil), [10.5, 12.5])
    np.testing.assert_allclose(refine_point(image, (16.0, 13.0), sil), [16.5, 12.5])


def test_a_partly_hidden_block_keeps_the_region_with_its_occluder():
    # Red shows 2 of its 6 columns (the green one hides the rest): under MIN_VISIBLE of its
    # area, so its point is the whole region's, pulled toward what hides it.
    image = scene((RED, 8, 10, 14, 16), (GREEN, 10, 10, 16, 16))
    xy = refine_point(image, (9.0, 13.0), Silhouette(half_window=8, area=36))
    np.testing.assert_allclose(xy, [11.5, 12.5])


def test_the_box_keeps_the_block_it_holds():
    # A white box with a red block in it: the box's region is both (it is colourless).
    image = scene((WHITE, 6, 6, 18, 18), (RED, 10, 10, 14, 14))
    xy = refine_point(image, (12.0, 16.0), Silhouette(half_window=12, by_colour=False))
    np.testing.assert_allclose(xy, [11.5, 11.5])


def test_region_area_tells_the_box_from_a_block_in_square_metres():
    # 1 cm a pixel: a 10 x 8 pixel white box with a block in it covers 0.008 m2, a lone 6 x 6 block 0.0036
    per_cm = np.diag([0.01, 0.01, 1.0])
    sil = Silhouette(half_window=12, by_colour=False)
    boxed = scene((WHITE, 6, 6, 16, 14), (RED, 9, 8, 13, 12))
    assert region_area(boxed, (11.0, 10.0), sil, per_cm) == pytest.approx(0.008)
    assert region_area(scene((RED, 20, 8, 26, 14)), (23.0, 11.0), sil, per_cm) == pytest.approx(0.0036)
    assert region_area(scene(), (9.0, 9.0), sil, per_cm) == 0.0  # bare table
    assert region_area(boxed, (np.nan, np.nan), sil, per_cm) == 0.0
    # farther from the camera (a homography that shrinks pixels by half) the same pixels cover a quarter
    assert region_area(boxed, (11.0, 10.0), sil, np.diag([0.01, 0.01, 2.0])) == pytest.approx(0.002)


def test_refine_points_keeps_shapes_and_nan():
    images = np.stack([scene((RED, 10, 12, 16, 18))] * 2)
    xy = np.array([[[14.0, 16.0], [np.nan, np.nan]], [[11.0, 13.0], [12.0, 15.0]]])
    out = refine_points(images, xy, Silhouette(half_window=7))
    assert out.shape == (2, 2, 2) and out.dtype == np.float32
    assert np.isnan(out[0, 1]).all()
    np.testing.assert_allclose(out[1], [[12.5, 14.5], [12.5, 14.5]])


def test_silhouette_round_trips_through_json():
    sil = Silhouette(7.0, (0.1, 1.2), 78.0, False)
    assert Silhouette.from_json(sil.to_json()) == sil


def test_calibration_on_the_tabletop_measures_the_box_front_wall():
    import gymnasium as gym

    import zsrm.envs  # noqa: F401
    from zsrm.tasks.catalogue import SCENE_IDS

    env = gym.make(SCENE_IDS["tabletop"], task=None, objects=("red", "box"), cameras=("tilted",), image_size=64).unwrapped
    env.reset(seed=0)
    try:
        block = calibrate(env, "tilted", 64, "red", True, 6.8, grid=(3, 2))
        box = calibrate(env, "tilted", 64, "box", False, 11.3, grid=(3, 2))
    finally:
        env.close()
    # A block's silhouette centre is its projected centre within half a pixel; about 6.8 px
    # square plus the front face it shows.
    assert abs(block.offset[0]) < 0.5 and abs(block.offset[1]) < 0.5
    assert 40 < block.area < 120
    # The box's front wall shows and its back wall does not: its silhouette sits about a pixel
    # toward the camera (down the image) from its centre.
    assert abs(box.offset[0]) < 0.5 and 0.5 < box.offset[1] < 2.0
    assert not box.by_colour and box.area == 0

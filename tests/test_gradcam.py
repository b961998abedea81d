"""Grad-CAM: the batched head-only gradients equal plain Grad-CAM (one full backward per
phrase), it points at the object a phrase names, and a phrase for an absent object gives a
clear "not found" rather than a crash."""
import numpy as np
import pytest
import torch

from zsrm.grounding.gradcam import GradCAM, grid_centres, head_gradcam, locate
from zsrm.testing import ColourVLM

PHRASES = ["red block", "yellow block", "blue block"]


def _scene(rng, size=32):
    image = np.full((size, size, 3), 128, np.uint8)
    image[4:10, 6:12] = (230, 30, 30)  # red
    image[20:26, 18:24] = (250, 245, 5)  # yellow
    image[:] = np.clip(image.astype(int) + rng.integers(0, 6, image.shape), 0, 255).astype(np.uint8)
    return image


def test_batched_head_gradients_equal_reference():
    rng = np.random.default_rng(0)
    vlm = ColourVLM(32)
    images = np.stack([_scene(rng) for _ in range(3)])
    for target in ("contrast", "score"):
        cam = GradCAM(vlm, target=target, contrast=PHRASES, batch_size=2)
        fast_maps, fast_scores = cam.heatmaps(images, PHRASES)
        ref_maps, ref_scores = cam.reference_heatmaps(images, PHRASES)
        assert fast_maps.shape == (3, 3, 8, 8)
        assert fast_maps.abs().max() > 0
        torch.testing.assert_close(fast_maps, ref_maps, atol=1e-4, rtol=1e-4)
        torch.testing.assert_close(fast_scores, ref_scores, atol=1e-4, rtol=1e-4)


def test_per_image_phrases_give_each_image_its_own_maps():
    """The grounded policy's case: each image has its own goal's phrases (weights (N, P, D))."""
    rng = np.random.default_rng(0)
    vlm = ColourVLM(32)
    images = np.stack([_scene(rng) for _ in range(2)])
    cam = GradCAM(vlm, contrast=PHRASES)
    weights = cam.target_vectors(PHRASES)
    with torch.no_grad():
        feats = vlm.image_trunk(vlm.preprocess(images))
    shared_maps, shared_scores = head_gradcam(vlm.image_head, feats, weights)
    # Image 0 asks for (red, yellow), image 1 for (yellow, blue).
    own_maps, own_scores = head_gradcam(vlm.image_head, feats, torch.stack([weights[[0, 1]], weights[[1, 2]]]))
    torch.testing.assert_close(own_maps[0], shared_maps[0, [0, 1]])
    torch.testing.assert_close(own_maps[1], shared_maps[1, [1, 2]])
    torch.testing.assert_close(own_scores, torch.stack([shared_scores[0, [0, 1]], shared_scores[1, [1, 2]]]))


def test_batched_equals_reference_on_a_trained_style_network():
    """A non-linear head (not only a mean): the equality must not depend on ColourVLM's linearity."""
    torch.manual_seed(0)

    class Tiny(ColourVLM):
        def __init__(self):
            super().__init__(32)
            self.mix = torch.nn.Conv2d(5, 5, 3, padding=1)

        def image_head(self, features):
            return torch.tanh(self.mix(features)).mean(dim=(-2, -1)) + features.amax(dim=(-2, -1))

    vlm = Tiny()
    images = np.stack([_scene(np.random.default_rng(i)) for i in range(2)])
    cam = GradCAM(vlm, contrast=PHRASES)
    fast_maps, _ = cam.heatmaps(images, PHRASES)
    ref_maps, _ = cam.reference_heatmaps(images, PHRASES)
    torch.testing.assert_close(fast_maps, ref_maps, atol=1e-4, rtol=1e-4)


def test_points_at_the_named_object():
    vlm = ColourVLM(32)
    cam = GradCAM(vlm, contrast=PHRASES, cell_centres="grid")
    res = cam(_scene(np.random.default_rng(1))[None], ["red block", "yellow block"])
    assert res.found.all()
    red, yellow = res.xy[0]
    assert np.linalg.norm(red - (8.5, 6.5)) < 4  # (x, row) of the red square's centre
    assert np.linalg.norm(yellow - (20.5, 22.5)) < 4


def test_absent_object_is_not_found_not_a_crash():
    vlm = ColourVLM(32)
    cam = GradCAM(vlm, contrast=PHRASES)
    res = cam(_scene(np.random.default_rng(2))[None], ["blue block", "red block"])
    assert not res.found[0, 0] and np.isnan(res.xy[0, 0]).all()
    assert res.score[0, 0] < 0 < res.score[0, 1]
    assert res.found[0, 1]


def test_bad_input_is_a_clear_error():
    cam = GradCAM(ColourVLM(32))
    with pytest.raises(ValueError, match="phrases"):
        cam.heatmaps(np.zeros((1, 32, 32, 3), np.uint8), [""])
    with pytest.raises(ValueError, match="target"):
        GradCAM(ColourVLM(32), target="nope")


def test_locate_argmax_and_centroid():
    maps = np.zeros((1, 1, 4, 4))
    maps[0, 0, 1, 2] = 1.0
    centres = grid_centres((4, 4), (16, 16))
    for method in ("argmax", "peak_centroid"):
        np.testing.assert_allclose(locate(maps, centres, method)[0, 0], centres[1, 2])


def test_receptive_field_centres_of_a_pooled_layer_are_its_cells():
    # Cells that are 4x4 average pools of a linear 1x1 layer see exactly their own 4x4 pixels,
    # so each measured centre must be the cell's geometric centre (no ReLU: no dead pixels).
    from zsrm.grounding.gradcam import receptive_field_centres

    class Linear(ColourVLM):
        def image_trunk(self, pixels):
            return self.pool(self.detect[0](pixels))

    vlm = Linear(32)
    pixels = vlm.preprocess(np.stack([_scene(np.random.default_rng(i)) for i in range(2)]))
    np.testing.assert_allclose(receptive_field_centres(vlm, pixels, (32, 32)), grid_centres((8, 8), (32, 32)),
                               atol=1e-6)


def test_fine_layer_cam_through_its_hook_equals_the_head_path():
    # LayerCAM at the module that outputs the Grad-CAM layer (ColourVLM's pool), read through a
    # hook, must equal LayerCAM computed the plain way on the trunk's output (no fine layer).
    images = np.stack([_scene(np.random.default_rng(i)) for i in range(2)])
    hooked, plain = GradCAM(ColourVLM(32), contrast=PHRASES), GradCAM(ColourVLM(32), contrast=PHRASES)
    hooked.fine_layer, plain.fine_layer = "pool", None
    a, b = hooked.fine_heatmaps(images, PHRASES), plain.fine_heatmaps(images, PHRASES)
    assert a.shape == (2, 3, 8, 8) and a.max() > 0 and (a >= 0).all()
    torch.testing.assert_close(a, b)


def test_fine_locate_is_sub_pixel_where_the_coarse_map_is_not():
    image = _scene(np.random.default_rng(3))
    true = np.array([[8.5, 6.5], [20.5, 22.5]])  # (x, row) of the red and yellow squares' centres
    res = {how: GradCAM(ColourVLM(32), contrast=PHRASES, locate=how, cell_centres="grid")(image[None], PHRASES[:2])
           for how in ("peak_centroid", "fine")}
    fine = np.linalg.norm(res["fine"].xy[0] - true, axis=-1)
    coarse = np.linalg.norm(res["peak_centroid"].xy[0] - true, axis=-1)
    assert (fine < 0.3).all() and fine.sum() < coarse.sum()
    # The heat maps, peaks and scores stay Grad-CAM's.
    np.testing.assert_array_equal(res["fine"].maps, res["peak_centroid"].maps)


def test_fine_locate_undoes_its_mirrored_and_shifted_views():
    # An object against the right edge: a view that lost track of it (shifted out) must not
    # pull the average; the mirrored view must land back on the same side.
    image = np.full((32, 32, 3), 128, np.uint8)
    image[10:16, 26:32] = (230, 30, 30)
    xy = GradCAM(ColourVLM(32), contrast=PHRASES, locate="fine", cell_centres="grid")(image[None], ["red block"]).xy
    assert abs(xy[0, 0, 0] - 28.5) < 0.6 and abs(xy[0, 0, 1] - 12.5) < 0.6


def test_locate_fraction_widens_the_blob():
    maps = np.zeros((1, 1, 4, 4))
    maps[0, 0, 1, 1], maps[0, 0, 1, 2] = 1.0, 0.3
    centres = grid_centres((4, 4), (16, 16))
    np.testing.assert_allclose(locate(maps, centres)[0, 0], centres[1, 1])
    np.testing.assert_allclose(locate(maps, centres, fraction=0.2)[0, 0], (centres[1, 1] + 0.3 * centres[1, 2]) / 1.3)

"""Training pairs of the full reward model (zsrm/fullmodel/pairs.py)."""
import json

import numpy as np
import pytest

from zsrm.fullmodel.pairs import CaptionedImages, caption_camera, caption_relation, complement_captions
from zsrm.tasks.negatives import candidate_texts, negative_texts
from zsrm.testing import synthetic_pairs

FRONT = "a red block on the left of a blue block"
LEFT = "a red block behind a blue block"
TILTED = "a red block close to a blue block"


def three_cameras(n, captions, groups=None, objects=None):
    images = {c: np.full((n, 8, 8, 3), i, np.uint8) for i, c in enumerate(("front", "left", "tilted"))}
    return CaptionedImages(images, captions, groups, objects)


def test_each_caption_pairs_with_the_camera_its_relation_is_read_on():
    data = three_cameras(2, [[FRONT, LEFT, TILTED], [TILTED]])
    assert data.n_pairs == 4
    cams = [int(im[0, 0, 0]) for im in data.pair_images(np.arange(4))]
    assert cams == [0, 1, 2, 2]  # front, left, tilted, tilted
    assert [caption_camera(t) for t in data.pair_texts()] == ["front", "left", "tilted", "tilted"]
    assert data.holds(0) == {FRONT, LEFT, TILTED}


def test_captions_of_a_camera_the_data_lacks_make_no_pair():
    data = CaptionedImages({"front": np.zeros((1, 8, 8, 3), np.uint8)}, [[FRONT, LEFT]])
    assert data.pair_texts() == [FRONT]


def test_split_keeps_whole_episodes_on_one_side():
    data = synthetic_pairs(200, size=16, seed=0)
    train, val = data.split(0.25, seed=3)
    assert len(train) + len(val) == len(data)
    assert not set(train.groups) & set(val.groups)
    assert 0.15 < len(np.unique(val.groups)) / len(np.unique(data.groups)) < 0.35
    same = data.split(0.25, seed=3)[1]
    np.testing.assert_array_equal(same.groups, val.groups)


def test_balanced_sampling_draws_each_relation_equally():
    data = synthetic_pairs(300, size=16, seed=1)
    counts = data.relation_counts()
    assert counts["left_of"] > 3 * counts["on_top_of"]
    w = data.sampling_weights(1.0)
    mass = {}
    for t, p in zip(data.pair_texts(), w):
        mass[caption_relation(t)] = mass.get(caption_relation(t), 0.0) + p
    assert all(abs(m - 1 / len(counts)) < 1e-9 for m in mass.values())
    np.testing.assert_allclose(data.sampling_weights(0.0), 1 / data.n_pairs)


def test_bad_inputs_are_clear_errors():
    with pytest.raises(ValueError, match="caption lists"):
        CaptionedImages({"front": np.zeros((2, 8, 8, 3), np.uint8)}, [[]])
    with pytest.raises(ValueError, match="uint8"):
        CaptionedImages({"front": np.zeros((1, 8, 8, 3), np.float32)}, [[]])
    with pytest.raises(ValueError, match="no image-caption pairs"):
        CaptionedImages({"front": np.zeros((1, 8, 8, 3), np.uint8)}, [[]]).sampling_weights()


def test_reads_a_labelled_dataset_and_only_its_gradcam_captions(tmp_path):
    from zsrm.data.collect import CollectConfig, collect
    from zsrm.grounding.annotate import LabelConfig, label_dataset
    from zsrm.testing import ColourVLM

    folder = tmp_path / "explore"
    collect(CollectConfig(images=8, shard_size=4, episode_steps=4, record_every=2), folder, progress=False)
    label_dataset(folder, LabelConfig(vlm="testing"), vlm=ColourVLM(64), progress=False)
    # Poison the true-coordinate captions: they must never reach training.
    for path in (folder / "labels" / "oracle").glob("*.json"):
        d = json.loads(path.read_text())
        path.write_text(json.dumps({k: [["a green block inside of a blue block"]] * len(v) for k, v in d.items()}))
    data = CaptionedImages.from_dataset(folder)
    from zsrm.data.dataset import ExplorationData

    gradcam = ExplorationData(folder).captions()
    assert len(data) == 8
    for caps, grad in zip(data.captions, gradcam):  # the Grad-CAM captions, then their complements
        assert caps[:len(grad)] == grad and all(" far from " in c for c in caps[len(grad):])
    assert set(data.cameras) == {"front", "left", "tilted"}
    assert "a green block inside of a blue block" not in data.pair_texts()
    # Episodes are numbered per shard; groups stay distinct across shards.
    assert len(np.unique(data.groups[:6])) and not set(data.groups[:6]) & set(data.groups[6:])


def test_complements_say_far_from_where_the_labeler_found_no_close_to():
    caps = ["a red block close to a blue block", "a blue block close to a red block"]
    out = complement_captions(caps, ["red", "blue", "green"], "block")
    assert sorted(out) == sorted(["a red block far from a green block", "a green block far from a red block",
                                  "a blue block far from a green block", "a green block far from a blue block"])
    data = three_cameras(1, [caps], objects=[("block", ["red", "blue", "green"])])
    assert set(data.pair_texts()) == set(caps) | set(out)
    assert all(caption_camera(t) == "tilted" for t in out)


def test_with_the_box_blocks_not_found_inside_it_are_outside_of_it():
    caps = ["a red block inside of a box"]
    out = complement_captions(caps, ["red", "blue", "box"], "block")
    assert sorted(out) == ["a blue block far from a red block", "a blue block outside of a box",
                           "a red block far from a blue block"]
    assert complement_captions(caps, ["red", "blue"], "block") == ["a red block far from a blue block",
                                                                   "a blue block far from a red block"]
    assert caption_camera("a blue block outside of a box") == "tilted"
    # The goal "inside of a box" ranks against its complement, and the complement against the goal.
    assert negative_texts("a red block inside of a box")[-1] == "a red block outside of a box"
    assert candidate_texts("a blue block outside of a box") == ["a blue block outside of a box",
                                                                 "a blue block inside of a box"]

"""The open box in the exploration data and the labeler (``zsrm collect --p-box``): box scenes
with blocks dropped in, the box's true position stored apart from the colours, "inside of"
captions from true coordinates, eval-grounding's support, and training pairs that name the box."""
import numpy as np
import pytest

from zsrm.data.collect import CollectConfig, collect
from zsrm.data.dataset import ExplorationData
from zsrm.evaluation.grounding_quality import evaluate_grounding
from zsrm.fullmodel.pairs import CaptionedImages, caption_camera
from zsrm.grounding.annotate import LabelConfig, label_dataset
from zsrm.grounding.labeler import SpatialLabeler, relation_tuples, world_table
from zsrm.tasks.language import COLOURS, Task
from zsrm.tasks.negatives import candidate_texts
from zsrm.tasks.relations import RELATIONS, holds_in_world
from zsrm.testing import ColourVLM

CFG = dict(images=16, shard_size=8, episode_steps=4, record_every=2, image_size=32, max_objects=3,
           scenes=("tabletop", "pushing"))
OBJECTS = COLOURS + ("box",)
INSIDE = "a red block inside of a box"


@pytest.fixture(scope="module")
def boxes(tmp_path_factory):
    """Every tabletop scene holds the box; labelled with the hand-wired VLM (it does not know
    the box, so only the true-coordinate captions are checked)."""
    folder = tmp_path_factory.mktemp("boxes")
    collect(CollectConfig(**CFG, p_box=1.0), folder, progress=False)
    label_dataset(folder, LabelConfig(vlm="testing", locate="argmax", cell_centres="grid"), vlm=ColourVLM(32),
                  progress=False)
    return ExplorationData(folder)


def _inside(arr) -> np.ndarray:
    """(N,) some block is in the box, by the world oracle."""
    return np.array([bool(b) and any(holds_in_world("inside_of", [p, box]) for p in pos[ok])
                     for b, box, pos, ok in zip(arr["box_present"], arr["box_position"], arr["positions"], arr["present"])])


def test_box_scenes_store_the_box_apart_and_some_hold_a_block(boxes):
    assert boxes.manifest["config"]["p_box"] == 1.0 and boxes.has_box and boxes.objects == OBJECTS
    arr = boxes.load()
    tabletop = arr["scene"] == 0
    assert tabletop.any() and (~tabletop).any()
    np.testing.assert_array_equal(arr["box_present"], tabletop)  # pushing scenes never hold the box
    assert np.isfinite(arr["box_position"][tabletop]).all() and np.isnan(arr["box_position"][~tabletop]).all()
    for cam in boxes.cameras:
        px = arr[f"box_pixels_{cam}"]
        assert np.isfinite(px[tabletop]).all() and np.isnan(px[~tabletop]).all()
        assert arr[f"pixels_{cam}"].shape[1] == len(COLOURS)  # the colours' arrays keep their shape
    assert _inside(arr).any() and not _inside(arr)[tabletop].all()  # some box scenes, not all
    joined = boxes.object_arrays(arr)
    assert joined["present"].shape == (16, 5) and joined["pixels_tilted"].shape == (16, 5, 2)
    np.testing.assert_array_equal(joined["present"][:, 4], arr["box_present"])


def test_without_p_box_the_manifest_and_arrays_are_as_before(tmp_path):
    cfg = CollectConfig(**CFG)
    assert "p_box" not in cfg.to_json()  # folders collected before p_box still resume
    data = collect(cfg, tmp_path, progress=False)
    arr = data.load()
    assert "p_box" not in data.manifest["config"] and not data.has_box and data.objects == COLOURS
    assert not any(k.startswith("box_") for k in arr) and data.box_keys == []
    assert data.object_arrays(arr)["present"] is arr["present"]
    with pytest.raises(ValueError, match="p_box must be a probability"):
        CollectConfig(p_box=2.0)


def test_the_box_takes_part_only_as_what_a_block_is_inside_of():
    labeler = SpatialLabeler.from_block_widths({"front": 6.0, "left": 6.0, "tilted": 6.0}, colours=OBJECTS)
    captions = labeler({"front": {"red": (20, 30), "green": (40, 30), "box": (21, 31)},
                        "tilted": {"red": (20, 20), "green": (40, 20), "box": (21, 20)}})
    assert INSIDE in captions
    assert not any(c.startswith("a box") for c in captions)  # never "a box inside of a red block"
    assert not any("box" in c for c in captions if c != INSIDE)  # no other relation with the box
    assert labeler({"tilted": {"red": (20, 20), "box": (26, 20)}}) == []  # 6 px: close, not inside
    # Inside of is read only with the box as the container; every other relation without the box.
    assert len(relation_tuples("inside_of", COLOURS)) == 0 and len(relation_tuples("inside_of", OBJECTS)) == 4
    assert len(relation_tuples("left_of", COLOURS)) == 12 and len(relation_tuples("left_of", OBJECTS)) == 12
    stacked = labeler({"tilted": {"red": (20, 20), "green": (20.5, 20)}})  # centres 0.5 px apart
    assert not any(" inside of " in c for c in stacked)
    world = world_table(np.array([[[0.0, 0.0, 0.434], [0.2, 0.0, 0.43], [np.nan] * 3, [np.nan] * 3,
                                   [0.01, 0.0, 0.42]]]), np.array([[True, True, False, False, True]]), OBJECTS)
    assert INSIDE in world.captions()[0]


def test_true_captions_say_inside_of_where_the_world_does_and_eval_grounding_counts_them(boxes):
    arr = boxes.load()
    pixel, world = boxes.captions(oracle="pixel"), boxes.captions(oracle="world")
    names_box = np.array([any("inside of a box" in c for c in caps) for caps in world])
    np.testing.assert_array_equal(names_box, _inside(arr))
    # The true projected centres read on the table give the same inside-of captions.
    assert [[c for c in caps if "box" in c] for caps in pixel] == [[c for c in caps if "box" in c] for caps in world]
    report = evaluate_grounding(boxes.folder)
    assert report["support"]["inside_of"] >= names_box.sum() > 0
    assert set(report["median_px_error_box"]) == set(boxes.cameras) and report["box_images"] == (arr["scene"] == 0).sum()
    labels = np.load(boxes.folder / "labels" / "shard_00000.npz")
    assert labels["gradcam_box_xy_tilted"].shape == (8, 2) and labels["gradcam_xy_tilted"].shape == (8, 4, 2)


def test_a_box_caption_pairs_with_the_tilted_frame_and_has_inside_of_negatives():
    images = {c: np.full((1, 8, 8, 3), i, np.uint8) for i, c in enumerate(("front", "left", "tilted"))}
    data = CaptionedImages(images, [[INSIDE]], objects=[("block", ["red"])])
    assert data.pair_texts() == [INSIDE] and caption_camera(INSIDE) == RELATIONS["inside_of"].camera
    negatives = candidate_texts(INSIDE)[1:]
    assert negatives and all(t.endswith(" a box") for t in negatives)
    assert Task("on_top_of", ("red", "box")).text in negatives and INSIDE not in negatives
    assert set(candidate_texts(INSIDE)) <= set(data.vocabulary())


def test_labels_refine_on_the_tilted_camera_with_calibrated_silhouettes(boxes, tmp_path):
    import json

    manifest = json.loads((boxes.folder / "labels" / "manifest.json").read_text())
    sils = manifest["silhouettes"]
    assert set(sils) == {"tabletop", "pushing"} and set(sils["tabletop"]) == {"tilted"}
    assert set(sils["tabletop"]["tilted"]) == {"object", "box"} and set(sils["pushing"]["tilted"]) == {"object"}
    assert sils["tabletop"]["tilted"]["object"]["area"] > 0 and not sils["tabletop"]["tilted"]["box"]["by_colour"]
    # Without refinement the Grad-CAM points are kept as they are, and no calibration is made.
    label_dataset(boxes.folder, LabelConfig(vlm="testing", locate="argmax", cell_centres="grid", refine="none"),
                  out=tmp_path / "plain", vlm=ColourVLM(32), progress=False)
    plain = json.loads((tmp_path / "plain" / "manifest.json").read_text())
    assert "silhouettes" not in plain
    refined, kept = (np.load(f / "shard_00000.npz")["gradcam_xy_front"] for f in (boxes.folder / "labels", tmp_path / "plain"))
    np.testing.assert_array_equal(refined, kept)  # the front camera is never refined

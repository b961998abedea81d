"""Teaching the scene VLM the box: box renders (zsrm/data/box_renders.py), captions that name
"a box" (zsrm/vlm/presence.py), and pretraining that mixes them in, from a saved VLM with its
image trunk frozen (zsrm/vlm/pretrain.py)."""
import json
import re

import numpy as np
import pytest
import torch

import zsrm.data.box_renders as box_renders
from zsrm.cli import main
from zsrm.data.box_renders import box_plan, load_box_renders, render_box_scenes
from zsrm.tasks.language import COLOURS, RELATION_WORDS
from zsrm.vlm.presence import (BOX_PHRASE, all_box_captions, all_presence_captions, box_visible, min_visible_pixels,
                               presence_caption, probe_text, join_phrases)
from zsrm.vlm.pretrain import PretrainConfig, check_config, make_batch
from zsrm.vlm.scene import SHIPPED_SCENE_DIR, SceneVLM, create_scene_vlm

SIZE = 32


@pytest.fixture(scope="module")
def renders():
    return render_box_scenes(range(9), seed=0, size=SIZE)


@pytest.fixture(scope="module")
def tiny_init(tmp_path_factory):
    """A tiny scene VLM at 32 px to start from."""
    folder = tmp_path_factory.mktemp("init") / "vlm"
    create_scene_vlm("tiny", seed=1, image_size=SIZE).save(folder)
    return folder


# --- renders -----------------------------------------------------------------------------------
def test_renders_are_seeded_per_index_and_cached(renders, tmp_path, monkeypatch):
    again = render_box_scenes([4, 5], seed=0, size=SIZE)
    assert all(np.array_equal(renders[k][12:18], again[k]) for k in renders)
    assert list(again["scene_index"]) == [4, 4, 4, 5, 5, 5] and list(again["camera"]) == [0, 1, 2, 0, 1, 2]

    first = load_box_renders(tmp_path, scenes=4, shard_size=3, seed=0, image_size=SIZE, progress=False)
    assert sorted(p.name for p in tmp_path.glob("shard-*")) == ["shard-0000.npz", "shard-0001.npz"]
    assert all(np.array_equal(first[k], renders[k][:12]) for k in renders)
    monkeypatch.setattr(box_renders, "render_box_scenes", lambda *a, **k: pytest.fail("re-rendered"))
    cached = load_box_renders(tmp_path, scenes=4, shard_size=3, seed=0, image_size=SIZE, progress=False)
    assert all(np.array_equal(first[k], cached[k]) for k in first)
    with pytest.raises(ValueError, match="other settings"):
        load_box_renders(tmp_path, scenes=4, shard_size=3, seed=1, image_size=SIZE, progress=False)


def test_the_box_shows_and_some_scenes_have_a_block_in_it(renders):
    assert renders["images"].shape == (27, SIZE, SIZE, 3) and renders["box_visible"].shape == (27,)
    shown = renders["box_visible"] >= min_visible_pixels(SIZE)
    assert shown.mean() > 0.5  # the box is on the table in every scene; a block or the arm may hide it
    inside = renders["inside"][::3]
    assert 0 < inside.sum() < len(inside)
    plans = [box_plan(i, 0) for i in range(9)]
    for i, plan in enumerate(plans):  # only the scene's blocks show
        absent = [c not in plan["colours"] for c in COLOURS]
        assert not renders["visible"][3 * i:3 * i + 3][:, absent].any()
    # A block put in the box mostly stays there through the few random actions.
    assert sum(bool(p["into_box"]) and bool(inside[i]) for i, p in enumerate(plans)) >= 1


def test_docstring_examples():
    import doctest

    result = doctest.testmod(box_renders, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0


# --- captions ----------------------------------------------------------------------------------
def caption_before_the_box(colours, shape, rng):
    """presence_caption as it was before the box (the shipped VLM was trained on its captions)."""
    colours = list(colours)
    k = int(rng.integers(1, len(colours) + 1))
    chosen = rng.permutation(len(colours))[:k]
    return join_phrases([probe_text(colours[i], shape) for i in chosen])


def test_captions_name_the_box_only_when_it_shows_and_old_captions_are_unchanged():
    new, old = np.random.default_rng(5), np.random.default_rng(5)
    for n in range(1, 5):
        for shape in ("block", "puck"):
            for _ in range(50):
                assert presence_caption(COLOURS[:n], shape, new) == caption_before_the_box(COLOURS[:n], shape, old)
    assert all("box" not in c for s in ("block", "puck") for c in all_presence_captions(s))

    rng = np.random.default_rng(0)
    with_box = [presence_caption(["red", "blue"], "block", rng, box=True) for _ in range(200)]
    assert "a box" in with_box and any(BOX_PHRASE in c and "red" in c for c in with_box)
    assert any(BOX_PHRASE not in c for c in with_box)  # a caption never has to name everything
    assert set(with_box) <= set(all_box_captions()) | set(all_presence_captions("block"))
    assert presence_caption([], "block", rng, box=True) == "a box"
    assert len(set(all_box_captions())) == 261 and all(BOX_PHRASE in c for c in all_box_captions())
    words = {w for ws in RELATION_WORDS.values() for w in ws}
    assert not [c for c in all_box_captions() if set(re.findall(r"[a-z]+", c)) & words]  # "in" never appears
    with pytest.raises(ValueError, match="tabletop"):
        presence_caption(["red"], "puck", rng, box=True)
    assert box_visible(5, 64) and not box_visible(4, 64) and box_visible(2, SIZE)


def test_mixed_batches_caption_box_renders():
    n = 6
    data = {"images": np.zeros((n, 8, 8, 3), np.uint8), "visible": np.full((n, 4), 50, np.int32),
            "shape": np.zeros(n, np.uint8)}
    # Box rows 0-2 show only the box, rows 3-5 a red block and no box; each row's image is its mark.
    box = {"images": np.repeat(np.arange(101, 101 + n, dtype=np.uint8), 8 * 8 * 3).reshape(n, 8, 8, 3),
           "visible": np.array([[0, 0, 0, 0]] * 3 + [[50, 0, 0, 0]] * 3, np.int32),
           "box_visible": np.array([50] * 3 + [0] * 3, np.int32)}
    pendulum = {"images": np.full((n, 8, 8, 3), 255, np.uint8), "pose": np.zeros(n, np.uint8)}
    cfg = PretrainConfig(batch_size=12, image_size=8)
    kinds = set()
    for step in range(4):
        for extra in ({"box": box}, {"box": box, "pendulum": pendulum}):
            images, captions = make_batch(data, np.arange(n), step, cfg, **extra)
            again = make_batch(data, np.arange(n), step, cfg, **extra)
            assert np.array_equal(images, again[0]) and captions == again[1]  # a function of (seed, step)
            for image, caption in zip(images, captions):
                mark = int(image[0, 0, 0])
                if 101 <= mark < 101 + n:
                    assert caption == ("a box" if mark - 101 < 3 else "a red block"), (mark, caption)
                    kinds.add("box")
                elif mark == 255:
                    assert "pendulum" in caption
                    kinds.add("pendulum")
                else:
                    assert "block" in caption and "box" not in caption
                    kinds.add("presence")
    assert kinds == {"box", "pendulum", "presence"}


# --- pretraining -------------------------------------------------------------------------------
def test_the_box_settings_keep_the_shipped_vlm_identity():
    shipped = json.loads((SHIPPED_SCENE_DIR / "config.json").read_text())["meta"]["config"]
    assert PretrainConfig().identity() == shipped
    assert PretrainConfig(box_scenes=8, init="x", freeze_trunk=True).identity() == {
        **shipped, "box_scenes": 8, "init": "x", "freeze_trunk": True}


def test_refusals(tmp_path, tiny_init, capsys):
    out = str(tmp_path / "out")
    tiny = dict(arch="tiny", image_size=SIZE, out=out)
    other_kind = tmp_path / "toy"
    other_kind.mkdir()
    (other_kind / "config.json").write_text(json.dumps({"backend": "toy"}))
    refused = {
        "--box-scenes must be >= 0": PretrainConfig(box_scenes=-1, out=out),
        "--box-scenes trains another VLM .*--out": PretrainConfig(box_scenes=4),
        "--init trains another VLM .*--out": PretrainConfig(init=str(tiny_init), arch="tiny", image_size=SIZE),
        "--freeze-trunk keeps the trunk .*--init": PretrainConfig(freeze_trunk=True, out=out),
        "--init: no config.json": PretrainConfig(init=str(tmp_path / "nothing"), **tiny),
        "--init: .*'toy' model, not a 'scene' model": PretrainConfig(init=str(other_kind), **tiny),
        "another architecture .*image_size: 32 there, 64 here": PretrainConfig(init=str(tiny_init), arch="tiny", out=out),
    }
    for message, cfg in refused.items():
        with pytest.raises(ValueError, match=message):
            check_config(cfg)
    check_config(PretrainConfig(init=str(tiny_init), freeze_trunk=True, box_scenes=2, **tiny))  # a valid run
    assert main(["pretrain-vlm", "--box-scenes", "4", "--workdir", str(tmp_path / "w"), "--quiet"]) == 2
    assert "--out" in capsys.readouterr().err and not (tmp_path / "w").exists()
    with pytest.raises(SystemExit):
        main(["pretrain-vlm", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "--box-scenes" in help_text and '(captioned "a box" where it shows)' in help_text
    assert "--init INIT start from this scene VLM folder" in help_text and "--freeze-trunk --init's image trunk" in help_text


def test_a_frozen_trunk_stays_bit_identical_while_the_head_learns_the_box(tmp_path, tiny_init):
    from zsrm.data.renders import load_renders
    from zsrm.vlm.pretrain import pretrain

    out, work = tmp_path / "vlm", tmp_path / "work"
    args = ["pretrain-vlm", "--out", str(out), "--workdir", str(work), "--arch", "tiny", "--image-size", str(SIZE),
            "--scenes", "2", "--shard-size", "2", "--steps", "3", "--batch-size", "8", "--checkpoint-every", "3",
            "--warmup-steps", "1", "--box-scenes", "3", "--init", str(tiny_init), "--freeze-trunk", "--quiet"]
    assert main(args) == 0
    before, after = SceneVLM.from_folder(tiny_init), SceneVLM.from_folder(out)
    for p, q in zip(before.visual.trunk_parameters(), after.visual.trunk_parameters()):
        assert torch.equal(p, q)
    assert not torch.equal(before.visual.proj.weight, after.visual.proj.weight)
    assert not torch.equal(before.text_proj.weight, after.text_proj.weight)
    meta = json.loads((out / "config.json").read_text())["meta"]
    assert meta["config"]["box_scenes"] == 3 and meta["config"]["freeze_trunk"] is True
    assert meta["init"] == str(tiny_init) and meta["freeze_trunk"] is True
    box = load_box_renders(work / "box-renders", 3, 2, 0, SIZE, progress=False)
    named = [bool(v[v >= min_visible_pixels(SIZE)].size) or box_visible(b, SIZE)
             for v, b in zip(box["visible"], box["box_visible"])]
    assert meta["box_images"] == sum(named) > 0

    # Without --freeze-trunk the same start moves the trunk: the check above can fail.
    cfg = PretrainConfig(out=str(tmp_path / "unfrozen"), workdir=str(tmp_path / "w2"), arch="tiny", image_size=SIZE,
                         scenes=2, shard_size=2, steps=2, batch_size=8, warmup_steps=1, box_scenes=3,
                         init=str(tiny_init))
    unfrozen = pretrain(cfg, load_renders(work / "renders", 2, 2, 0, SIZE, progress=False), progress=False, box=box)
    assert not all(torch.equal(p, q) for p, q in zip(before.visual.trunk_parameters(),
                                                     unfrozen.visual.trunk_parameters()))

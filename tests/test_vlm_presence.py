"""Presence renders (zsrm/data/renders.py) and captions (zsrm/vlm/presence.py): what the scene VLM learns from."""
import re

import numpy as np
import pytest

from zsrm.tasks.language import COLOURS, RELATION_WORDS
from zsrm.data.renders import render_presence_scenes, scene_plan
from zsrm.vlm.presence import all_presence_captions, join_phrases, presence_caption, probe_text, visible_colours

RELATION_WORDINGS = sorted({w for words in RELATION_WORDS.values() for w in words}, key=len, reverse=True)


def has_relation_word(caption: str) -> str | None:
    text = f" {re.sub(r'[^a-z ]', ' ', caption.lower())} "
    return next((w for w in RELATION_WORDINGS if f" {w} " in text), None)


def test_no_caption_contains_a_relation_word():
    rng = np.random.default_rng(0)
    captions = all_presence_captions("block") + all_presence_captions("puck")
    captions += [presence_caption(rng.permutation(COLOURS)[: rng.integers(1, 5)], shape, rng)
                 for shape in ("block", "puck") for _ in range(500)]
    assert len(set(all_presence_captions("block"))) == 64  # ordered non-empty subsets of 4 colours
    offenders = {c: has_relation_word(c) for c in captions if has_relation_word(c)}
    assert not offenders, offenders
    assert has_relation_word("a red block on top of a blue block") == "on top of"  # the checker works


def test_captions_name_a_non_empty_subset_of_what_is_visible_in_random_order():
    rng = np.random.default_rng(1)
    seen = set()
    for _ in range(300):
        cap = presence_caption(["red", "yellow", "blue"], "block", rng)
        named = re.findall(r"a (\w+) block", cap)
        assert named and set(named) <= {"red", "yellow", "blue"} and len(set(named)) == len(named)
        seen.add(tuple(named))
    # Every size and order occurs: naming one object does not deny the others.
    assert {len(s) for s in seen} == {1, 2, 3} and ("blue", "red") in seen and ("red", "blue") in seen
    assert join_phrases(["a red puck", "a green puck", "a blue puck"]) == "a red puck, a green puck and a blue puck"
    assert probe_text("yellow", "puck") == "a yellow puck"
    with pytest.raises(ValueError):
        presence_caption([], "block", rng)


def test_renders_are_seeded_labelled_by_visibility_and_streams_differ():
    data = render_presence_scenes([0, 1], seed=0, size=32)
    assert data["images"].shape == (6, 32, 32, 3) and data["images"].dtype == np.uint8
    assert list(data["camera"]) == [0, 1, 2, 0, 1, 2] and list(data["scene_index"]) == [0, 0, 0, 1, 1, 1]
    # Only objects in the scene can show pixels; each scene shows something somewhere.
    assert not (data["visible"] > 0)[~data["in_scene"]].any()
    for s in (0, 1):
        plan = scene_plan(s, 0)
        assert [c for c, inside in zip(COLOURS, data["in_scene"][3 * s]) if inside] == list(plan["colours"])
        assert data["visible"][3 * s:3 * s + 3].max() > 0
    again = render_presence_scenes([1], seed=0, size=32)
    assert np.array_equal(again["images"], data["images"][3:]) and np.array_equal(again["visible"], data["visible"][3:])
    train = [scene_plan(i, 0, "train")["env_seed"] for i in range(50)]
    held_out = [scene_plan(i, 0, "eval")["env_seed"] for i in range(50)]
    assert not set(train) & set(held_out)
    assert visible_colours(np.array([0, 4, 5, 100]), 64) == ["yellow", "blue"]
    assert visible_colours(np.array([0, 1, 2, 3]), 32) == ["green", "yellow", "blue"]  # threshold scales with area

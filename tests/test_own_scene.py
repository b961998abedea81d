"""A scene zsrm was not built for: the adapter contract (one clear line for each bad adapter), the
example scene of examples/own_scene (gymnasium's checks, a render per camera role), a tiny
collect from it that resumes, goals over its objects, the oracle on it, a tiny zsrm train on it,
and zsrm's code that knows nothing of it."""
from __future__ import annotations

import ast
import doctest
import importlib
import json
import shutil
import sys
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the example lives beside zsrm, as a user's code would
    sys.path.insert(0, str(ROOT))

from examples.own_scene.adapter import BODIES, OwnScene, OwnSceneFromXml  # noqa: E402
from examples.own_scene.env import CYLINDER_REST_Z, REST_Z, OwnSceneEnv  # noqa: E402
from zsrm.cli import main  # noqa: E402
from zsrm.data.collect import CollectConfig, collect  # noqa: E402
from zsrm.data.dataset import ExplorationData  # noqa: E402
from zsrm.envs.adapter import (ROLES, SceneAdapter, SceneAdapterError, check_env, check_phrases_known,  # noqa: E402
                               load_adapter, register_scene)
from zsrm.envs.scene_task import SceneTask, role_axes  # noqa: E402
from zsrm.rl.goals import scene_goal  # noqa: E402
from zsrm.tasks.language import GoalError, parse_goal  # noqa: E402
from zsrm.tasks.negatives import candidate_texts  # noqa: E402
from zsrm.tasks.scene_goals import parse_scene_goal  # noqa: E402

SPEC = "examples.own_scene.adapter:OwnScene"


def _adapter(**attrs) -> type[SceneAdapter]:
    return type("Changed", (OwnScene,), attrs)


def _one_line(err: Exception) -> str:
    text = str(err)
    assert text and "\n" not in text
    return text


# --- the contract ---------------------------------------------------------------------------
@pytest.mark.parametrize("attrs, words", [
    ({"cameras": {"front": "cam_front", "left": "cam_side", "top": "cam_high"}}, "unknown camera role 'top'"),
    ({"cameras": {"front": "cam_front", "left": "cam_side"}}, "no camera plays the 'tilted' role"),
    ({"cameras": {"front": "cam_front", "left": "cam_front", "tilted": "cam_high"}}, "are both camera 'cam_front'"),
    ({"cameras": {"front": "cam_front", "left": "cam_side", "tilted": "cam_top"}},
     "camera 'cam_top' is not a camera of the model; its cameras: cam_front, cam_side, cam_high"),
    ({"objects": ()}, "objects must be a tuple of noun phrases"),
    ({"objects": "red cylinder"}, "objects must be a tuple of noun phrases"),
    ({"objects": ("red cylinder", "Red  Cylinder!")}, "is not a noun phrase"),
    ({"objects": ("red cylinder", "red cylinder")}, "'red cylinder' is named more than once"),
    ({"object_width": 0}, "object_width must be a positive number"),
    ({"xml": "/no/such/scene.xml"}, "cannot load xml /no/such/scene.xml"),
    ({"bodies": {"red cylinder": "red_cylinder"}}, "bodies must name a body for each object and only those"),
    ({"bodies": {**BODIES, "wooden bowl": "pot"}}, "the body 'pot' of 'wooden bowl' is not a body of the model"),
])
def test_a_bad_adapter_is_one_line(attrs, words):
    with pytest.raises(SceneAdapterError) as err:
        load_adapter(_adapter(**attrs))
    assert words in _one_line(err.value)


def test_a_camera_the_model_lacks_is_caught_from_the_env_without_an_xml():
    adapter = load_adapter(_adapter(xml=None, cameras={"front": "cam_front", "left": "cam_side", "tilted": "cam_top"}))
    env = OwnSceneEnv(cameras=("cam_front", "cam_side"), image_size=16)
    with pytest.raises(SceneAdapterError, match="'tilted' role's camera 'cam_top' is not a camera of the model"):
        check_env(adapter, env)


class _StateEnv(OwnSceneEnv):
    """The example scene observed as numbers (its pusher's position): no camera images."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float64)

    def _observation(self):
        return self.data.qpos[:2].copy()


def test_an_env_without_image_observations_is_one_line():
    adapter = load_adapter(OwnScene)
    with pytest.raises(SceneAdapterError) as err:
        check_env(adapter, _StateEnv())
    assert "not camera images; zsrm reads pixels only" in _one_line(err.value)


def test_an_env_that_does_not_observe_a_role_is_one_line():
    adapter = load_adapter(OwnScene)
    with pytest.raises(SceneAdapterError) as err:
        check_env(adapter, OwnSceneEnv(cameras=("cam_front", "cam_side"), image_size=16))
    assert "observes nothing for camera 'cam_high' (the 'tilted' role)" in _one_line(err.value)


def test_an_adapter_with_no_env_is_one_line():
    adapter = load_adapter(_adapter(env_id=None, xml=None))
    with pytest.raises(SceneAdapterError) as err:
        adapter.make_env(("cam_front",))
    assert "give env_id (a gymnasium id) or xml, or override make_env" in _one_line(err.value)


def test_actions_that_are_not_a_bounded_box_need_their_own_exploration():
    adapter = load_adapter(SPEC)
    env = adapter.make_env(("cam_front",), 16)
    env.unwrapped.action_space = gym.spaces.Discrete(4)
    with pytest.raises(SceneAdapterError) as err:
        adapter.exploration_action(env, np.random.default_rng(0))
    assert "not a bounded Box: write exploration_action(env, rng)" in _one_line(err.value)


def test_unknown_phrases_are_one_line():
    adapter = load_adapter(SPEC)
    assert check_phrases_known(adapter, ("wooden bowl",)) == ("wooden bowl",)
    with pytest.raises(SceneAdapterError) as err:
        check_phrases_known(adapter, ("green cube",))
    assert "unknown object 'green cube'; this scene's objects: red cylinder" in _one_line(err.value)
    with pytest.raises(ValueError, match="unknown object 'green cube' to exclude"):
        CollectConfig(scene=SPEC, exclude=("green cube",))


@pytest.mark.parametrize("spec, words", [
    ("nowhere_at_all.scenes:Mugs", "cannot import 'nowhere_at_all.scenes'"),
    ("examples.own_scene.adapter:NoSuchAdapter", "has no 'NoSuchAdapter'"),
    ("examples.own_scene.adapter:BODIES", "is not a zsrm.envs.SceneAdapter"),
    ("justaname", "give module:Class"),
])
def test_a_scene_that_does_not_load_is_one_line(spec, words):
    with pytest.raises(SceneAdapterError) as err:
        load_adapter(spec)
    assert words in _one_line(err.value)


def test_a_registered_id_names_an_adapter():
    register_scene("test-own-scene", SPEC)
    assert isinstance(load_adapter("test-own-scene"), OwnScene)
    with pytest.raises(SceneAdapterError, match="without ':'"):
        register_scene("a:b", SPEC)


def test_an_installed_package_names_an_adapter_by_entry_point(monkeypatch):
    from importlib.metadata import EntryPoint

    import zsrm.envs.adapter as adapter_mod

    points = [EntryPoint("lab-pusher", SPEC, adapter_mod.ENTRY_POINT_GROUP)]
    monkeypatch.setattr(adapter_mod, "entry_points", lambda group: points if group == "zsrm.scenes" else [])
    assert isinstance(load_adapter("lab-pusher"), OwnScene)
    with pytest.raises(SceneAdapterError, match="registered id .*lab-pusher"):
        load_adapter("lab-pushr")


def test_the_command_line_prints_a_bad_scene_as_one_line(tmp_path, capsys):
    assert main(["collect", "--scene", "nowhere_at_all.scenes:Mugs", "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("zsrm collect: error: scene 'nowhere_at_all.scenes:Mugs'")
    assert main(["collect", "--scene", SPEC, "--scenes", "pushing", "--out", str(tmp_path / "d")]) == 2
    assert "not both" in capsys.readouterr().err


@pytest.mark.parametrize("module", ["zsrm.envs.adapter", "zsrm.tasks.scene_goals", "zsrm.envs.scene_task"])
def test_the_docstrings_run(module):
    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0


# --- the example scene ----------------------------------------------------------------------
def test_the_example_env_passes_gymnasiums_and_sb3s_checks():
    from gymnasium.utils.env_checker import check_env as gym_check
    from stable_baselines3.common.env_checker import check_env as sb3_check

    adapter = load_adapter(SPEC)
    env = adapter.make_env(tuple(adapter.roles.values()), 64)
    gym_check(env.unwrapped)
    sb3_check(env.unwrapped)
    assert check_env(adapter, env) is env


def test_the_example_renders_each_role_at_64_px():
    adapter = load_adapter(SPEC)
    env = adapter.make_env(tuple(adapter.roles.values()), 64, ("red cylinder", "wooden bowl"))
    obs, info = env.reset(seed=3)
    assert info == {}  # the env tells the agent nothing of where things are
    images = adapter.observe(obs)
    assert list(images) == list(ROLES)
    for role, image in images.items():
        assert image.shape == (64, 64, 3) and image.dtype == np.uint8 and image.std() > 10, role
    assert not np.array_equal(images["front"], images["left"])
    assert not np.array_equal(images["front"], images["tilted"])
    # red shows where the red cylinder is, in the front camera
    red = (images["front"][..., 0] > 150) & (images["front"][..., 1] < 60) & (images["front"][..., 2] < 60)
    assert red.sum() > 5
    positions = adapter.object_positions(env)
    assert sorted(positions) == ["red cylinder", "wooden bowl"]
    env.close()


def test_the_example_moves_only_with_its_pusher():
    adapter = load_adapter(SPEC)
    env = adapter.make_env(("cam_front",), 32)
    env.reset(seed=0)
    start = env.unwrapped.data.qpos[:2].copy()
    for _ in range(5):
        env.step(np.array([1.0, 1.0], np.float32))
    assert np.all(env.unwrapped.data.qpos[:2] > start + 0.05)  # the pusher followed the actions


# --- collect --------------------------------------------------------------------------------
def _tiny(**kw) -> CollectConfig:
    return CollectConfig(scene=SPEC, images=6, shard_size=3, episode_steps=4, record_every=2, **kw)


def test_a_tiny_collect_from_the_example_scene_resumes(tmp_path):
    cfg = _tiny()
    data = collect(cfg, tmp_path / "a", progress=False)
    arrays = data.load()
    assert len(data) == 6 and data.colours == tuple(BODIES) and data.scenes == (SPEC,)
    assert set(data.block_width_px[SPEC]) == set(ROLES) and all(3 < w < 12 for w in data.block_width_px[SPEC].values())
    assert arrays["images_tilted"].shape == (6, 64, 64, 3) and arrays["positions"].shape == (6, 4, 3)
    present = arrays["present"]
    assert present.sum(axis=1).min() >= 2
    assert np.isnan(arrays["positions"][~present]).all() and np.isfinite(arrays["positions"][present]).all()
    for role in ROLES:  # true pixels (evaluation only) fall inside the image
        xy = arrays[f"pixels_{role}"][present]
        assert ((xy > 0) & (xy < 63)).all(), role
    manifest = json.loads((tmp_path / "a" / "manifest.json").read_text())
    assert manifest["scene_adapter"]["cameras"] == {"front": "cam_front", "left": "cam_side", "tilted": "cam_high"}
    # a run killed after its first shard resumes with the same data
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    (tmp_path / "b" / "shard_00001.npz").unlink()
    manifest["shards"].pop("shard_00001")
    manifest["complete"] = False
    (tmp_path / "b" / "manifest.json").write_text(json.dumps(manifest))
    resumed = collect(cfg, tmp_path / "b", progress=False).load()
    assert all(np.array_equal(resumed[k], arrays[k], equal_nan=True) for k in arrays)
    with pytest.raises(ValueError, match="made with other options"):
        collect(_tiny(seed=1), tmp_path / "a", progress=False)


def test_an_accessor_that_names_an_unknown_object_is_one_line(tmp_path):
    class Misnamed(OwnScene):
        def object_positions(self, env):
            return {"red cylindre": np.zeros(3)}

    with pytest.raises(ValueError, match="scene must be module:Class or a registered id, got Misnamed"):
        CollectConfig(scene=Misnamed())
    register_scene("test-misnamed", Misnamed)
    with pytest.raises(SceneAdapterError, match="unknown object 'red cylindre'; this scene's objects"):
        collect(CollectConfig(scene="test-misnamed", images=1, shard_size=1, episode_steps=1, record_every=1),
                tmp_path / "d", progress=False)


def test_collect_from_the_command_line(tmp_path, capsys):
    out = tmp_path / "own"
    assert main(["collect", "--scene", SPEC, "--out", str(out), "--images", "2", "--shard-size", "2",
                 "--episode-steps", "2", "--record-every", "1", "--cameras", "front", "tilted", "--quiet"]) == 0
    assert "2 images x 2 cameras" in capsys.readouterr().out
    assert sorted(k for k in ExplorationData(out).load() if k.startswith("images_")) == ["images_front", "images_tilted"]


def test_a_scene_from_its_xml_alone(tmp_path):
    """No env of the user's: zsrm builds one from the MJCF; positions from the bodies named."""
    from gymnasium.utils.env_checker import check_env as gym_check

    adapter = load_adapter(OwnSceneFromXml)
    assert adapter.env_id is None and adapter.holds_subsets  # bodies named: zsrm parks the absent ones
    env = adapter.make_env(tuple(adapter.roles.values()), 32)
    gym_check(env.unwrapped)
    check_env(adapter, env)
    assert env.action_space.low.tolist() == [-1, -1]  # normalised over the actuators' ctrlrange
    spec = "examples.own_scene.adapter:OwnSceneFromXml"
    data = collect(CollectConfig(scene=spec, images=8, shard_size=8, episode_steps=4, record_every=2,
                                 image_size=32), tmp_path / "xml", progress=False).load()
    present = data["present"]
    assert not present.all() and (present.sum(axis=1) >= 2).all()  # scenes of two to four of its objects
    starts = data["positions"][::2, :, :2]  # the reset moved them (jitter 0.1 m), within the table
    assert not np.allclose(starts[0], starts[1]) and (np.abs(starts[present[::2]]) < 0.3).all()
    for role in ROLES:
        px = data[f"pixels_{role}"][present]
        assert ((px > 0) & (px < 31)).all()


def test_zsrms_own_collect_config_is_unchanged():
    """A dataset of zsrm's scenes keeps the manifest config it always had (it resumes)."""
    assert "scene" not in CollectConfig().to_json() and CollectConfig().adapter is None


# --- zsrm knows nothing of the example ------------------------------------------------------
def _zsrm_sources() -> list[Path]:
    return sorted(p for p in (ROOT / "zsrm").rglob("*.py") if "__pycache__" not in p.parts)


def test_no_zsrm_module_imports_the_example():
    bad = []
    for path in _zsrm_sources():
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            bad += [f"{path.relative_to(ROOT)}:{node.lineno}" for n in names if n.split(".")[0] == "examples"]
    assert not bad


def test_no_zsrm_source_names_the_examples_objects():
    # the phrases, the env's own names ("bowl" alone is a word zsrm's goal paraphrases may use)
    from examples.slate_scene.adapter import BODIES as SLATE_BODIES

    words = [*BODIES, *(b for b in BODIES.values() if "_" in b), "examples.own_scene", "OwnScene", "cam_front",
             "cam_side", "cam_high", *SLATE_BODIES, *SLATE_BODIES.values(), "examples.slate_scene", "SlateScene",
             "view_front", "view_left", "view_oblique"]
    files = [p for p in (ROOT / "zsrm").rglob("*") if p.is_file() and p.suffix in (".py", ".json", ".xml", ".md")]
    bad = [f"{p.relative_to(ROOT)}: {w!r}" for p in files for w in words if w in p.read_text(errors="ignore")]
    assert not bad, bad


# --- the scene VLM learns the scene's object names --------------------------------------------
def test_own_renders_count_each_objects_visible_pixels():
    from zsrm.data.own_renders import render_own_scenes

    data = render_own_scenes(load_adapter(SPEC), range(6), seed=0, size=32)
    assert data["images"].shape == (18, 32, 32, 3) and data["visible"].shape == (18, 4)
    assert (data["visible"][~data["in_scene"]] == 0).all()  # what is not in the scene shows nothing
    assert (data["visible"][data["in_scene"]] > 0).mean() > 0.9  # what is, shows (unless hidden behind another)
    again = render_own_scenes(load_adapter(SPEC), [3], seed=0, size=32)
    assert np.array_equal(again["images"], data["images"][9:12])  # scene 3 is the same scene on its own


def test_captions_name_only_visible_objects_by_their_phrases():
    from zsrm.vlm.pretrain import PretrainConfig, make_batch

    objects = tuple(BODIES)
    visible = np.array([[50, 0, 3, 40], [0, 30, 0, 0]])
    data = {"images": np.zeros((2, 8, 8, 3), np.uint8), "visible": visible}
    cfg = PretrainConfig(out="unused", scene=SPEC, batch_size=2, image_size=64)
    seen = set()
    for step in range(20):
        _, captions = make_batch(data, np.arange(2), step, cfg, objects=objects)
        seen.update(captions)
    assert seen <= {"a red cylinder", "a wooden bowl", "a red cylinder and a wooden bowl",
                    "a wooden bowl and a red cylinder", "a purple cylinder"}
    assert "a purple cylinder" in seen and len(seen) >= 4


def test_pretrain_vlm_on_the_example_scene_names_its_objects(tmp_path, capsys):
    out, work = tmp_path / "vlm", tmp_path / "work"
    args = ["pretrain-vlm", "--scene", SPEC, "--out", str(out), "--workdir", str(work), "--arch", "tiny",
            "--scenes", "4", "--shard-size", "2", "--steps", "4", "--batch-size", "8", "--checkpoint-every", "2",
            "--warmup-steps", "2", "--quiet"]
    assert main(args) == 0
    meta = json.loads((out / "config.json").read_text())["meta"]
    assert meta["objects"] == list(BODIES) and meta["scene"] == SPEC and "colours" not in meta
    assert meta["config"]["scene"] == SPEC and meta["train_scenes"] == 4
    assert sorted(p.name for p in (work / "own-renders").glob("shard-*.npz")) == ["shard-0000.npz", "shard-0001.npz"]
    capsys.readouterr()
    assert main(["eval-vlm", "--vlm", str(out), "--scene", SPEC, "--images", "30", "--min-auroc", "0",
                 "--out", str(tmp_path / "presence.json"), "--quiet"]) == 0
    result = json.loads((tmp_path / "presence.json").read_text())
    assert sorted(k for k in result if k.startswith("auroc.")) == sorted(f"auroc.{p}" for p in BODIES)
    assert (tmp_path / "presence.png").exists()


@pytest.mark.parametrize("extra, words", [
    (["--box-scenes", "2", "--out", "x"], "--pendulum-scenes and --box-scenes are zsrm's scenes"),
    ([], "--scene trains another VLM than the shipped one: name its folder with --out"),
])
def test_pretrain_vlm_scene_refuses_what_does_not_fit(extra, words, capsys):
    assert main(["pretrain-vlm", "--scene", SPEC, *extra]) == 2
    assert words in capsys.readouterr().err


# --- goals over the scene's objects -----------------------------------------------------------
PHRASES = tuple(BODIES)


@pytest.mark.parametrize("text, relation, objects", [
    ("a red cylinder on the right of a purple cylinder", "right_of", ("red cylinder", "purple cylinder")),
    ("a red cylinder close to an orange cylinder", "close_to", ("red cylinder", "orange cylinder")),
    ("Put the red cylinder into the wooden bowl.", "inside_of", ("red cylinder", "wooden bowl")),
    ("a red cylinder inside of a wooden bowl", "inside_of", ("red cylinder", "wooden bowl")),
    ("push the purple cylinder to the orange cylinder's left", "left_of", ("purple cylinder", "orange cylinder")),
    ("the red cylinder and the orange cylinder next to each other", "close_to", ("red cylinder", "orange cylinder")),
    ("a red cylinder in between a purple cylinder and an orange cylinder", "in_between",
     ("red cylinder", "purple cylinder", "orange cylinder")),
])
def test_goals_name_the_scenes_objects_by_their_phrases(text, relation, objects):
    goal = scene_goal(text, SPEC)
    assert (goal.relation, goal.objects) == (relation, objects)
    assert parse_scene_goal(goal.text, PHRASES) == goal  # the canonical sentence reads back


@pytest.mark.parametrize("text, words", [
    ("a green cube on the right of a red cylinder", "unknown object 'green cube'"),
    ("a red cylinder on the rihgt of a purple cylinder",
     "no relation between the red cylinder and the purple cylinder ('on the rihgt of' is not one); known relations: "
     "on the left of, on the right of, on top of, below, in between, in front of, behind, close to, inside of; "
     "did you mean 'a red cylinder on the right of a purple cylinder'?"),
    ("a red cylinder floats over a purple cylinder", "('floats over' is not one); known relations: on the left of"),
    ("a red cylinder close to a red cylinder", "must name different objects, got the red cylinder twice"),
    ("a red cylinder", "only one object (red cylinder)"),
    ("a red cylinder not close to a purple cylinder", "the goal says 'not'"),
    ("a red cylinder close to a purple cylinder quickly", "words zsrm cannot read: 'quickly'"),
    ("", "empty goal"),
])
def test_a_goal_the_scene_cannot_read_is_one_line_listing_its_objects(text, words):
    with pytest.raises(ValueError) as err:
        scene_goal(text, SPEC)
    line = _one_line(err.value)
    assert words in line
    assert line.endswith(f"{SPEC}'s objects: red cylinder, purple cylinder, orange cylinder, wooden bowl")


def test_a_caption_over_an_own_scenes_phrases_reads_without_its_object_list():
    """Training reads captions with no adapter at hand: the canonical sentence is enough."""
    from zsrm.fullmodel.text import noun_phrases
    from zsrm.tasks.negatives import caption_candidates, caption_relation_camera, complement_of
    from zsrm.tasks.scene_goals import read_canonical

    text = "an orange cylinder close to a wooden bowl"
    assert read_canonical(text) == parse_scene_goal(text, PHRASES)
    assert caption_candidates(text) == candidate_texts(parse_scene_goal(text, PHRASES))
    assert caption_relation_camera("a red cylinder far from an orange cylinder") == ("far_from", "tilted")
    assert complement_of("a red cylinder far from an orange cylinder").objects == ("red cylinder", "orange cylinder")
    assert noun_phrases("a red cylinder on the right of a purple cylinder") == ("red cylinder", "purple cylinder")
    with pytest.raises(GoalError, match="2 readings"):
        read_canonical("a cup on top of a mug on top of a plate")
    zsrms = "a yellow block on top of a red block"
    assert caption_candidates(zsrms) == candidate_texts(zsrms) and complement_of("a red block far from a box").objects == ("red", "box")
    with pytest.raises(GoalError, match="purple"):  # a goal a user writes stays strict
        candidate_texts("a purple block on top of a red block")


def test_zsrms_goals_and_the_scenes_goals_do_not_mix():
    with pytest.raises(GoalError, match="unknown colour 'orange'"):
        parse_goal("a red cylinder close to an orange cylinder")
    with pytest.raises(GoalError, match="unknown object"):
        scene_goal("a yellow block on top of a red block", SPEC)


def test_a_scene_goals_negatives_are_its_other_relations_and_the_swap_over_its_phrases():
    goal = scene_goal("a red cylinder on the right of a purple cylinder", SPEC)
    texts = candidate_texts(goal)
    assert texts[0] == goal.text and len(set(texts)) == len(texts) == 9  # 7 other two-object relations and the swap
    assert "a red cylinder on the left of a purple cylinder" in texts
    assert texts[-1] == "a purple cylinder on the right of a red cylinder"
    for text in texts:  # every caption names the scene's objects and reads back
        assert parse_scene_goal(text, PHRASES).text == text
    close = candidate_texts(scene_goal("the red cylinder next to the orange cylinder", SPEC))
    assert close[0] == "a red cylinder close to an orange cylinder"
    assert close[-1] == "a red cylinder far from an orange cylinder"  # symmetric: no swap, the complement instead
    assert "an orange cylinder close to a red cylinder" not in close


# --- the oracle on the example scene ----------------------------------------------------------
def _judge(goal: str, layout: dict, adapter=OwnScene) -> bool:
    """The oracle's verdict with the objects set by hand at ``layout`` (phrase -> x, y[, z])."""
    adapter = load_adapter(adapter)
    task = parse_scene_goal(goal, adapter.objects)
    role = {"right_of": "front", "on_top_of": "front", "in_front_of": "left"}.get(task.relation, "tilted")
    env = SceneTask(adapter.make_env((adapter.roles[role],), 16), adapter, task)
    env.reset(seed=0)
    base = env.unwrapped
    parked = [(-0.2, -0.15), (0.2, -0.15), (-0.2, 0.15), (0.2, 0.15)]
    for phrase, body in BODIES.items():
        xyz = layout.get(phrase, parked.pop())
        z = xyz[2] if len(xyz) == 3 else REST_Z.get(body, CYLINDER_REST_Z)
        base._place(body, (xyz[0], xyz[1], z))
    mujoco.mj_forward(base.model, base.data)
    verdict = env.oracle_success()
    env.close()
    return verdict


@pytest.mark.parametrize("goal, layout, holds", [
    ("a red cylinder on the right of a purple cylinder", {"red cylinder": (0.10, 0.0), "purple cylinder": (-0.05, 0.0)}, True),
    ("a red cylinder on the right of a purple cylinder", {"red cylinder": (-0.05, 0.0), "purple cylinder": (0.10, 0.0)}, False),
    # within the gap (Table 1's margin, 5/6 cm for 5 cm objects): neither side
    ("a red cylinder on the right of a purple cylinder", {"red cylinder": (0.005, 0.1), "purple cylinder": (0.0, -0.1)}, False),
    ("a red cylinder close to an orange cylinder", {"red cylinder": (0.0, 0.0), "orange cylinder": (0.06, 0.0)}, True),
    ("a red cylinder close to an orange cylinder", {"red cylinder": (0.0, 0.0), "orange cylinder": (0.0, 0.12)}, False),
    # 9 cm apart: close for zsrm's 6 cm blocks (10 cm), not for the example's 5 cm cylinders (8.3 cm)
    ("a red cylinder close to an orange cylinder", {"red cylinder": (0.0, 0.0), "orange cylinder": (0.09, 0.0)}, False),
    ("a red cylinder inside of a wooden bowl",
     {"wooden bowl": (0.05, 0.0), "red cylinder": (0.06, 0.005, REST_Z["bowl"] + 0.038)}, True),
    ("a red cylinder inside of a wooden bowl", {"wooden bowl": (0.05, 0.0), "red cylinder": (0.12, 0.0)}, False),
    ("a red cylinder on top of a purple cylinder",
     {"purple cylinder": (0.0, 0.0), "red cylinder": (0.005, 0.0, CYLINDER_REST_Z + 0.06)}, True),
    ("a red cylinder on top of a purple cylinder", {"purple cylinder": (0.0, 0.0), "red cylinder": (0.08, 0.0)}, False),
    ("a red cylinder in front of a purple cylinder", {"red cylinder": (0.0, -0.1), "purple cylinder": (0.0, 0.05)}, True),
    ("a red cylinder in front of a purple cylinder", {"red cylinder": (0.0, 0.1), "purple cylinder": (0.0, -0.05)}, False),
])
def test_the_oracle_on_hand_placed_states(goal, layout, holds):
    assert _judge(goal, layout) is holds


def test_the_oracle_reads_the_object_width_and_the_cameras_own_frame():
    nine_cm = {"red cylinder": (0.0, 0.0), "orange cylinder": (0.09, 0.0)}
    assert _judge("a red cylinder close to an orange cylinder", nine_cm, _adapter(object_width=0.06))
    # red nearer the front camera, in line with purple: not right of it for the front camera; with the
    # side camera playing the front role, its image x axis points toward the front: right of it.
    in_line = {"red cylinder": (0.0, -0.1), "purple cylinder": (0.0, 0.1)}
    assert not _judge("a red cylinder on the right of a purple cylinder", in_line)
    swapped = _adapter(cameras={"front": "cam_side", "left": "cam_front", "tilted": "cam_high"})
    assert _judge("a red cylinder on the right of a purple cylinder", in_line, swapped)


def test_for_zsrms_own_cameras_the_planes_are_camera_plane():
    from zsrm.envs.base import load_model
    from zsrm.tasks.relations import camera_plane

    points = np.random.default_rng(0).uniform(-0.3, 0.6, (5, 3))
    for asset in ("tabletop.xml", "pushing.xml"):
        model = load_model(asset)
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        for role in ROLES:
            assert np.allclose(points @ role_axes(model, data, role, role).T, camera_plane(points, role)), (asset, role)


def test_the_task_wrapper_observes_by_role_and_writes_the_oracle_into_info():
    adapter = load_adapter(SPEC)
    goal = scene_goal("a red cylinder close to an orange cylinder", SPEC)
    env = SceneTask(adapter.make_env(("cam_high",), 16), adapter, goal, action_repeat=4)
    obs, info = env.reset(seed=1)
    assert list(obs) == ["tilted"] and obs["tilted"].shape == (16, 16, 3)
    assert set(info) == {"oracle_reward", "is_success", "oracle_steps"}  # the user's env's info is empty
    obs, reward, terminated, truncated, info = env.step(np.zeros(2, np.float32))
    assert reward == 0.0 and 0 <= info["oracle_steps"] <= 4 and info["oracle_reward"] == float(info["is_success"])
    assert env.unwrapped.data.time == pytest.approx(4 * 10 * 0.004 + 5 * 10 * 0.004)  # 4 control steps after the reset's 5
    env.close()


def test_an_episode_never_starts_in_the_goal_and_a_seed_gives_its_start():
    adapter = load_adapter(SPEC)
    goal = scene_goal("a red cylinder on the right of a purple cylinder", SPEC)  # about half the env's resets hold it
    env = SceneTask(adapter.make_env(("cam_front",), 16), adapter, goal)
    starts = []
    for seed in range(20):
        _, info = env.reset(seed=seed)
        assert not info["is_success"] and info["oracle_steps"] == 0
        starts.append(adapter.object_positions(env)["red cylinder"])
    env.reset(seed=7)
    assert np.array_equal(adapter.object_positions(env)["red cylinder"], starts[7])
    env.close()


def test_a_goals_scenes_are_the_task_env_holding_the_goals_objects_alone():
    """Training scenes: the task env (task_env_kwargs: objects close together, the pusher in
    front of one, finer steps) with the goal's objects alone, seen by the goal's camera."""
    from zsrm.rl import TrainConfig
    from zsrm.rl.envs import make_vec

    goal = "a red cylinder behind a purple cylinder"
    cfg = TrainConfig(goal=goal, scene=SPEC, reward="random", image_size=16, n_envs=2)
    venv = make_vec(cfg, 2, seed=0)
    obs = venv.reset()
    assert list(obs) == ["left"] and obs["left"].shape == (2, 16, 16, 3)
    base = venv.envs[0].unwrapped
    assert base.objects == ("red_cylinder", "purple_cylinder") and (base.start, base.step_size) == ("compact", 0.01)
    xy = [base.body_position(b)[:2] for b in base.objects]
    assert all(abs(x) <= 0.085 and abs(y) <= 0.065 for x, y in xy)  # the compact patch, settled
    venv.close()
    explore = load_adapter(SPEC).make_env(("cam_high",), 16)  # exploration: every object, anywhere
    assert (explore.unwrapped.start, explore.unwrapped.step_size) == ("anywhere", 0.02)
    assert len(explore.unwrapped.objects) == 4
    explore.close()


def test_the_example_envs_start_is_checked():
    with pytest.raises(ValueError, match="start must be one of 'anywhere', 'compact', 'column'"):
        OwnSceneEnv(start="near")


def test_the_sideways_scenes_start_in_a_column_with_the_pusher_beside_the_moved_object():
    """OwnSceneSideways' task scenes: the goal's objects one behind the other (neither left nor
    right of the other), the pusher level with the object the goal moves, on the side it is
    pushed from (the adapter's task_reset_options, passed by SceneTask to the env's reset)."""
    spec = "examples.own_scene.adapter:OwnSceneSideways"
    adapter = load_adapter(spec)
    for goal_text, side in (("a red cylinder on the right of a purple cylinder", -1),
                            ("a purple cylinder on the left of a red cylinder", 1)):
        goal = scene_goal(goal_text, spec)
        env = SceneTask(adapter.make_env(("cam_front",), 16, goal.objects, task=True), adapter, goal)
        for seed in range(4):
            _, info = env.reset(seed=seed)
            base = env.unwrapped
            assert (base.start, base.step_size) == ("column", 0.01) and not info["is_success"]
            (x1, y1), (x2, y2) = (base.body_position(b)[:2] for b in base.objects)
            assert abs(x1 - x2) < 0.0083 and abs(y1 - y2) > 0.05  # no sideways relation: the margin is 0.83 cm
            mover, pusher = base.body_position(BODIES[goal.objects[0]])[:2], base.data.qpos[:2]
            assert abs(pusher[1] - mover[1]) < 0.015 and 0.095 < side * (pusher[0] - mover[0]) < 0.115  # 6 cm reach
        env.close()
    env = OwnSceneEnv(objects=("red_cylinder", "purple_cylinder"), start="column", image_size=16)
    sides = {bool(env.reset(seed=s)[0] is not None and env.data.qpos[0] > min(
        (env.body_position(b) for b in env.objects), key=lambda p: p[1])[0]) for s in range(8)}
    assert sides == {False, True}  # without options: beside the front object, either side
    with pytest.raises(ValueError, match="beside: 'bowl' is not on the table"):
        env.reset(seed=0, options={"beside": "bowl"})
    with pytest.raises(ValueError, match="side must be 'left' or 'right', got 'up'"):
        env.reset(seed=0, options={"side": "up"})
    env.close()


def test_parse_goal_reads_a_goal_over_the_scenes_objects(capsys):
    assert main(["parse-goal", "--scene", SPEC, "--json", "the red cylinder inside of the wooden bowl"]) == 0
    reading = json.loads(capsys.readouterr().out)
    assert reading["objects"] == ["red cylinder", "wooden bowl"] and reading["relation"] == "inside_of"
    assert reading["canonical"] == "a red cylinder inside of a wooden bowl" and reading["camera"] == "tilted"
    assert main(["parse-goal", "--scene", SPEC, "a red mug behind a purple cylinder"]) == 2
    assert "unknown object 'red mug'" in _one_line(capsys.readouterr().err.strip().removeprefix("zsrm parse-goal: error: "))


def test_rollout_random_on_the_scene(tmp_path, capsys):
    out = tmp_path / "random.json"
    assert main(["rollout", "random:a red cylinder behind a purple cylinder", "--scene", SPEC, "--episodes", "2",
                 "--out", str(out)]) == 0
    rewards = json.loads(out.read_text())["episode_rewards"]
    assert len(rewards) == 2 and all(0 <= r <= 100 for r in rewards)
    capsys.readouterr()
    assert main(["rollout", str(tmp_path), "--scene", SPEC]) == 2
    assert "--scene is for random:GOAL" in capsys.readouterr().err


# --- zsrm train on the example scene ----------------------------------------------------------
class _SideBySide(gym.Wrapper):
    """The example env with the red and orange cylinders set side by side at the back, out of the
    pusher's first reach, at the first step of each episode: the goal 'close to' holds from the
    first control step on (SceneTask makes the reset's own scene one that does not hold it)."""

    LAYOUT = {"red_cylinder": (-0.03, 0.15), "orange_cylinder": (0.03, 0.15), "purple_cylinder": (-0.15, -0.02),
              "bowl": (0.15, -0.02)}

    def reset(self, **kwargs):
        self.first = True
        return self.env.reset(**kwargs)

    def step(self, action):
        if self.first:
            base = self.env.unwrapped
            for body, xy in self.LAYOUT.items():
                base._place(body, (*xy, REST_Z.get(body, CYLINDER_REST_Z)))
            base.data.qvel[:] = 0.0  # nothing keeps the speed it had where the reset put it
            mujoco.mj_forward(base.model, base.data)
            self.first = False
        return self.env.step(action)


class _InGoalFromTheFirstStep(OwnScene):
    def make_env(self, cameras, image_size=64, objects=None, task=False):
        return _SideBySide(super().make_env(cameras, image_size, objects, task))


TINY_RL = ["--n-envs", "4", "--n-steps", "128", "--batch-size", "64", "--n-epochs", "1", "--eval-episodes", "2",
           "--keypoints", "4", "--image-size", "32"]


def test_train_on_the_example_scene_with_the_oracle_and_roll_out_its_policy(tmp_path, capsys):
    out = tmp_path / "run"
    goal = "a red cylinder close to an orange cylinder"
    assert main(["train", "--scene", SPEC, "--goal", goal, "--reward", "oracle", "--steps", "2048",
                 "--eval-every", "2048", "--checkpoint-every", "2048", *TINY_RL, "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["config"]["scene"] == SPEC and summary["config"]["goal"] == goal
    assert summary["env_steps"] == 2048 and [row["env_steps"] for row in summary["curve"]] == [2048]
    rewards = summary["final_episode_rewards"]
    assert len(rewards) == 30 and all(0 <= r <= 100 and r == int(r) for r in rewards)
    assert json.loads((out / "config.json").read_text())["scene"] == SPEC
    assert json.loads((out / "policy" / "config.json").read_text())["config"]["scene"] == SPEC
    capsys.readouterr()
    assert main(["rollout", str(out / "policy"), "--episodes", "2", "--out", str(tmp_path / "rollout.json")]) == 0
    result = json.loads((tmp_path / "rollout.json").read_text())
    assert len(result["episode_rewards"]) == 2 and all(0 <= r <= 100 for r in result["episode_rewards"])


def test_the_evaluation_sums_the_oracles_control_steps_in_the_goal(tmp_path):
    """A scene in the goal from its first step: each episode's oracle reward counts its 100 control
    steps in the relation (oracle_steps), not its 25 decisions."""
    from zsrm.rl import TrainConfig, train

    register_scene("test-in-goal-from-the-first-step", _InGoalFromTheFirstStep)
    cfg = TrainConfig(goal="a red cylinder close to an orange cylinder", scene="test-in-goal-from-the-first-step",
                      reward="random", image_size=16)
    rewards = train(cfg, tmp_path, progress=False)["final_episode_rewards"]
    assert len(rewards) == 30 and min(rewards) > 25 and max(rewards) == 100


def test_train_on_the_example_scene_with_the_base_reward(tmp_path):
    from zsrm.rl import TrainConfig, train

    cfg = TrainConfig(goal="a red cylinder on the right of a purple cylinder", scene=SPEC, reward="base", steps=256,
                      eval_every=256, checkpoint_every=256, n_envs=2, n_steps=32, batch_size=32, n_epochs=1,
                      eval_episodes=2, keypoints=4, image_size=32)
    summary = train(cfg, tmp_path, progress=False)
    assert summary["env_steps"] == 256 and summary["config"]["reward"] == "base" and summary["final_episodes"] == 30


@pytest.mark.parametrize("reward, words", [
    ("zsrm", f"the zsrm reward on your own scene ({SPEC}) reads a reward model trained on that scene's labelled"),
    ("vice", "the vice reward fits its goal classifier on zsrm's scripted episodes"),
])
def test_train_refuses_a_reward_not_built_for_an_own_scene_in_one_line(reward, words, tmp_path, capsys):
    goal = "a red cylinder on the right of a purple cylinder"
    assert main(["train", "--scene", SPEC, "--goal", goal, "--reward", reward, "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and not (tmp_path / "r").exists()


def test_train_with_a_goal_the_scene_cannot_read_is_one_line(capsys):
    assert main(["train", "--scene", SPEC, "--goal", "a red block on top of a wooden bowl"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown object 'red block'" in err[0] and "wooden bowl" in err[0]


def test_sweep_passes_the_scene_to_every_trial():
    from zsrm.pipeline.learn import Sweep

    goal = "a red cylinder close to an orange cylinder"
    sweep = Sweep(tasks=(goal,), rewards=("oracle", "random"), seeds=(0, 1), scene=SPEC, steps=2048)
    trials = sweep.trials()
    assert [t["name"] for t in trials][:2] == [f"{goal.replace(' ', '_')}-oracle-0", f"{goal.replace(' ', '_')}-random-0"]
    assert all(t["config"]["scene"] == SPEC for t in trials) and "--scene " + SPEC in sweep.meta(0, 4)["command"]
    with pytest.raises(ValueError, match="the zsrm reward on your own scene"):
        Sweep(tasks=(goal,), rewards=("zsrm",), seeds=(0,), scene=SPEC).trials()


def test_zsrms_own_train_config_is_unchanged():
    from zsrm.rl import TrainConfig

    assert "scene" not in TrainConfig().to_dict() and TrainConfig().scene is None


# --- labelling an own scene's data (zsrm label, zsrm eval-grounding) ---------------------------
def _own_vlm(folder: Path) -> Path:
    """A tiny untrained scene VLM that says it was taught the example's objects (as zsrm
    pretrain-vlm --scene records them): what labelling reads of it, at no training cost."""
    from zsrm.vlm.scene import create_scene_vlm

    vlm = create_scene_vlm("tiny", seed=0)
    vlm.meta = {"scene": SPEC, "objects": list(BODIES)}
    vlm.save(folder)
    return folder


def test_label_an_own_scene_captions_its_phrases_and_its_oracle_is_the_scene_tasks(tmp_path, capsys):
    from zsrm.envs.scene_task import holds_in_scene, scene_thresholds

    data = collect(_tiny(), tmp_path / "own", progress=False)
    assert list(data.table_homography[SPEC]) == ["tilted"]  # the adapter gives its table_height
    assert set(data.pixel_rays[SPEC]) == set(OwnScene.cameras)  # so the labeler reads on top of in 3-D
    vlm = _own_vlm(tmp_path / "vlm")
    assert main(["label", str(tmp_path / "own"), "--vlm", str(vlm), "--quiet"]) == 0
    captions, world = data.captions(), data.captions(oracle="world")
    assert len(captions) == len(world) == 6 and any(captions)
    for caption in {c for caps in captions + world + data.captions(oracle="pixel") for c in caps}:
        assert parse_scene_goal(caption, PHRASES).text == caption  # the goal grammar over the adapter's phrases
    manifest = json.loads((tmp_path / "own" / "labels" / "manifest.json").read_text())
    own = manifest["own_scene"]
    assert own["object_width"] == 0.05 and any("silhouette refinement uncalibrated" in n for n in own["notes"])
    assert manifest["silhouettes"][SPEC]["tilted"]["object"]["offset"] == [0.0, 0.0]
    # the oracle's captions are SceneTask's verdicts: true positions along the role cameras' own axes
    arrays = data.load(["positions", "present"])
    env = load_adapter(SPEC).make_env(tuple(OwnScene.cameras.values()), 64)
    env.reset(seed=0)
    for text in ("a red cylinder on the right of a purple cylinder", "a red cylinder close to an orange cylinder",
                 "a red cylinder on top of an orange cylinder"):
        goal = parse_scene_goal(text, PHRASES)
        role = {"right_of": "front", "close_to": "tilted", "on_top_of": "front"}[goal.relation]
        axes = role_axes(env.unwrapped.model, env.unwrapped.data, OwnScene.cameras[role], role)
        idx = [PHRASES.index(p) for p in goal.objects]
        for i in range(6):
            holds = arrays["present"][i, idx].all() and holds_in_scene(
                goal.relation, arrays["positions"][i, idx], axes, scene_thresholds(OwnScene.object_width))
            assert (text in world[i]) == holds, (text, i)
    env.close()
    capsys.readouterr()
    out = tmp_path / "grounding.json"
    assert main(["eval-grounding", str(tmp_path / "own"), "--out", str(out)]) == 0
    report = json.loads(out.read_text())
    for rel in ("right_of", "left_of", "close_to", "inside_of"):
        assert f"f1_vs_world.{rel}" in report and f"support_world.{rel}" in report
    assert report["meta"]["own_scene"]["adapter"] == SPEC
    located = {k.rsplit(".", 1)[-1] for k in report if k.startswith("median_px_error_by_colour.front.")}
    assert located and located <= set(PHRASES)


def test_the_full_model_on_the_example_scene_end_to_end(tmp_path, capsys):
    """reward data (collect + label), the student finetuned on its Grad-CAM captions, its
    binarised reward against the scene's oracle, and PPO with it: the chain on a tiny scale."""
    from zsrm.fullmodel.pairs import CaptionedImages
    from zsrm.rl import TrainConfig, train
    from zsrm.tasks.negatives import complement_of

    own, vlm, student = tmp_path / "own", _own_vlm(tmp_path / "vlm"), tmp_path / "student"
    data = collect(_tiny(), own, progress=False)
    assert main(["label", str(own), "--vlm", str(vlm), "--quiet"]) == 0
    pairs = CaptionedImages.from_dataset(own)
    assert pairs.n_pairs > 0
    for text in pairs.pair_texts():  # the adapter's phrases, with "far from" complements of close to
        denied = complement_of(text)
        assert (denied.objects if denied else parse_scene_goal(text, PHRASES).objects)[0] in PHRASES
    assert main(["finetune", "--data", str(own), "--student", "--student-arch", "tiny", "--vlm", str(vlm),
                 "--out", str(student), "--steps", "4", "--batch-size", "8", "--eval-every", "4",
                 "--checkpoint-every", "4", "--quiet"]) == 0
    goals = ["a red cylinder on the right of a purple cylinder", "an orange cylinder on the left of a red cylinder"]
    out = tmp_path / "reward_eval.json"
    assert main(["eval-reward", "--scene", SPEC, "--data", str(own), "--zsrm", str(student), "--base", str(vlm),
                 "--tasks", *goals, "--out", str(out), "--curves", "", "--quiet"]) == 0
    report, world = json.loads(out.read_text()), data.captions(oracle="world")
    present = data.load(["present"])["present"]
    for goal in goals:  # the frames that hold the goal's objects, labelled by the scene's oracle
        holds = present[:, [PHRASES.index(p) for p in parse_scene_goal(goal, PHRASES).objects]].all(axis=1)
        for name in ("zsrm", "base"):
            cell = report[name][goal]
            assert cell["frames"] == holds.sum() and cell["positives"] == sum(goal in caps for caps in world)
    assert report["meta"]["frames"][goals[0]]["camera"] == "front"
    cfg = TrainConfig(goal=goals[0], scene=SPEC, reward="zsrm", reward_model=str(student), vlm=str(vlm), steps=128,
                      eval_every=128, checkpoint_every=128, n_envs=2, n_steps=16, batch_size=16, n_epochs=1,
                      eval_episodes=2, keypoints=4)
    summary = train(cfg, tmp_path / "run", progress=False)
    assert summary["env_steps"] == 128 and summary["config"]["reward_model"] == str(student)


def test_eval_reward_on_an_own_scene_needs_its_goals_and_data_in_one_line(capsys):
    assert main(["eval-reward", "--scene", SPEC, "--out", "/dev/null"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "give --tasks (goal sentences over its objects) and --data" in err[0]


def test_label_refuses_a_vlm_not_taught_the_scenes_objects_in_one_line(tmp_path, capsys):
    collect(CollectConfig(scene=SPEC, images=2, shard_size=2, episode_steps=2, record_every=1), tmp_path / "own",
            progress=False)
    assert main(["label", str(tmp_path / "own"), "--vlm", "scene", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the VLM scene was never taught 'red cylinder' (it learnt red block" in err[0]
    assert f"zsrm pretrain-vlm --scene {SPEC} --out FOLDER" in err[0]
    assert not (tmp_path / "own" / "labels" / "manifest.json").exists()  # nothing labelled


def test_label_refuses_data_whose_adapter_renamed_its_objects_in_one_line(tmp_path, capsys, monkeypatch):
    collect(CollectConfig(scene=SPEC, images=2, shard_size=2, episode_steps=2, record_every=1), tmp_path / "own",
            progress=False)
    monkeypatch.setattr(OwnScene, "objects", ("red cylinder", "violet cylinder", "orange cylinder", "wooden bowl"))
    assert main(["label", str(tmp_path / "own"), "--vlm", str(_own_vlm(tmp_path / "vlm")), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "objects are now red cylinder, violet cylinder" in err[0] and "collect the data again" in err[0]


def test_without_a_table_height_the_tilted_camera_is_read_in_pixels(tmp_path, monkeypatch):
    from zsrm.grounding.annotate import LabelConfig, label_dataset, labelers
    from zsrm.vlm import load_vlm

    monkeypatch.setattr(OwnScene, "table_height", None)
    data = collect(CollectConfig(scene=SPEC, images=2, shard_size=2, episode_steps=2, record_every=1), tmp_path / "own",
                   progress=False)
    assert data.table_homography == {SPEC: {}}
    vlm = _own_vlm(tmp_path / "vlm")
    label_dataset(tmp_path / "own", LabelConfig(vlm=str(vlm)), vlm=load_vlm(str(vlm)), progress=False)
    notes = json.loads((tmp_path / "own" / "labels" / "manifest.json").read_text())["own_scene"]["notes"]
    assert any("tilted camera (close_to, inside_of) is read in pixels" in n for n in notes)
    # pixel thresholds: the world ones scaled to the object width (5 cm) and its width in pixels there
    tilted = labelers(data, LabelConfig())[SPEC].thresholds["tilted"]
    width_px = data.block_width_px[SPEC]["tilted"]
    assert tilted.close == pytest.approx(0.10 * (0.05 / 0.06) * width_px / 0.05)


class TwoObjects(OwnScene):
    objects = ("red cylinder", "purple cylinder")


def test_a_scene_of_two_objects_collects_with_the_default_object_counts(tmp_path):
    # The defaults ask for 2 to 4 objects a scene; a two-object scene (robosuite's Stack) holds
    # up to both, where it once stopped the chain's reward-data stage.
    register_scene("test-two-objects", TwoObjects)
    cfg = CollectConfig(scene="test-two-objects", images=4, shard_size=4, episode_steps=2, record_every=1)
    assert (cfg.min_objects, cfg.max_objects) == (2, 2)
    data = collect(cfg, tmp_path / "two", progress=False)
    assert data.load()["present"].all()
    with pytest.raises(ValueError, match="min_objects"):  # zsrm's own scenes still refuse a count they cannot hold
        CollectConfig(max_objects=5)

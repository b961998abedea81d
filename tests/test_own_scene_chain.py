"""A scene from its XML alone, and the one command that runs the own-scene chain on any adapter:
the bare-XML env (subsets, normalised actions, steps, the start beside an object, one-line
refusals), the gates that speak up (captions that never vary, an object present in every render,
an object not localised), the masking check and zoomed views of the stand-in VLM, the README's
first example without MUJOCO_GL, and ``zsrm own-scene`` end to end at a tiny scale."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # the examples live beside zsrm, as a user's code would
    sys.path.insert(0, str(ROOT))

from examples.slate_scene.adapter import BODIES, SlateScene  # noqa: E402
from zsrm.cli import main  # noqa: E402
from zsrm.envs.adapter import SceneAdapterError, check_env, load_adapter  # noqa: E402
from zsrm.envs.xml_scene import XmlSceneEnv, XmlSceneError  # noqa: E402

SPEC = "examples.slate_scene.adapter:SlateScene"
XML = SlateScene.xml
CAMS = ("view_front", "view_left", "view_oblique")


class AllObjectsAlways(SlateScene):
    """The issue's first try: the bare XML holding every object in every scene."""

    subsets = False


# --- the bare-XML env -------------------------------------------------------------------------
def test_a_bare_xml_scene_passes_gymnasiums_and_sb3s_checks():
    from gymnasium.utils.env_checker import check_env as gym_check
    from stable_baselines3.common.env_checker import check_env as sb3_check

    env = XmlSceneEnv(XML, cameras=("view_front",), image_size=32, objects=("white_sphere", "black_box"),
                      start="beside", step_size=0.01)
    gym_check(env)
    sb3_check(env, warn=False)


def test_a_bare_xml_scene_holds_the_objects_asked_and_parks_the_others_unseen():
    adapter = load_adapter(SlateScene)
    assert adapter.holds_subsets  # bodies are named: zsrm can leave objects out
    env = adapter.make_env(CAMS, 48, objects=("white sphere", "yellow ellipsoid"))
    check_env(adapter, env)
    obs, _ = env.reset(seed=0)
    assert sorted(adapter.object_positions(env)) == ["white sphere", "yellow ellipsoid"]
    full = adapter.make_env(CAMS, 48)
    full_obs, _ = full.reset(seed=0)
    assert sorted(adapter.object_positions(full)) == sorted(BODIES)
    # the black box (near black on a grey table) shows in the full scene only
    dark = lambda img: int((img.max(axis=-1) < 15).sum())  # noqa: E731
    assert dark(obs["view_oblique"]) == 0 < dark(full_obs["view_oblique"])
    parked = env.unwrapped.body_position("black_box")
    env.step(env.action_space.sample())
    assert np.linalg.norm(parked[:2]) > 10 and np.allclose(parked, env.unwrapped.body_position("black_box"))


def test_actions_are_normalised_over_the_ctrlrange_and_raw_is_kept_by_name():
    env = XmlSceneEnv(XML, cameras=("view_front",), image_size=16)
    assert env.action_space.low.tolist() == [-1, -1] and env.action_space.high.tolist() == [1, 1]
    env.reset(seed=0)
    env.step(np.array([1.0, -1.0]))
    assert np.allclose(env.data.ctrl, [0.25, -0.1])  # the ends of the XML's ctrlranges
    env.step(np.array([0.0, 0.0]))
    assert np.allclose(env.data.ctrl, [0.0, 0.1])  # the middles
    raw = XmlSceneEnv(XML, cameras=("view_front",), image_size=16, actions="raw")
    assert np.allclose(raw.action_space.low, [-0.25, -0.1]) and np.allclose(raw.action_space.high, [0.25, 0.3])


def test_a_step_size_moves_the_target_by_at_most_that_much():
    env = XmlSceneEnv(XML, cameras=("view_front",), image_size=16, step_size=0.01)
    env.reset(seed=0)
    start = env.data.ctrl.copy()
    env.step(np.array([1.0, -0.5]))
    assert np.allclose(env.data.ctrl - start, [0.01, -0.005])
    for _ in range(60):  # the target stops at the ctrlrange
        env.step(np.array([1.0, 0.0]))
    assert np.isclose(env.data.ctrl[0], 0.25)


def test_the_beside_start_puts_the_paddle_next_to_an_object():
    env = XmlSceneEnv(XML, cameras=("view_front",), image_size=16, objects=("white_sphere", "teal_capsule"),
                      start="beside", step_size=0.01, jitter=0.05)
    for seed in range(8):
        env.reset(seed=seed)
        paddle, reach = env.body_position("paddle")[:2], env._radius(env.model.body("paddle").id)
        gaps = [np.linalg.norm(paddle - env.body_position(b)[:2]) - reach - env._radius(env.model.body(b).id)
                for b in ("white_sphere", "teal_capsule")]
        assert -0.01 < min(gaps) < 0.02  # beside one (bounding circles, a few mm apart; the scene settled)
        assert np.allclose(env.data.ctrl, env.data.qpos[:2], atol=1e-6)  # the actuators hold it there
    first = env.reset(seed=3)[0]["view_front"]
    assert (env.reset(seed=3)[0]["view_front"] == first).all()  # a seed gives its start


@pytest.mark.parametrize("xml_text, kwargs, words", [
    ('<mujoco><worldbody><camera name="c"/><body name="b"><freejoint/><geom size="0.1"/></body></worldbody></mujoco>',
     {}, "has no actuators"),
    ('<mujoco><worldbody><camera name="c"/><body name="arm"><joint name="h" type="hinge"/><geom size="0.1"/></body>'
     '</worldbody><actuator><motor joint="h"/></actuator></mujoco>', {"start": "beside"},
     "does not drive a slide joint"),
    ('<mujoco><worldbody><camera name="c"/><body name="arm"><joint name="s" type="slide"/><geom size="0.1"/></body>'
     '</worldbody><actuator><position joint="s" kp="10"/></actuator></mujoco>', {"objects": ("arm",)},
     "'arm' is not a body with a free joint"),
])
def test_what_an_xml_alone_cannot_do_is_one_line(tmp_path, xml_text, kwargs, words):
    path = tmp_path / "scene.xml"
    path.write_text(xml_text)
    with pytest.raises(XmlSceneError) as err:
        XmlSceneEnv(path, cameras=("c",), image_size=16, **kwargs)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_the_adapter_says_what_the_xml_cannot_do_in_one_line():
    class Hinged(SlateScene):
        task_env_kwargs = {"start": "sideways"}

    with pytest.raises(SceneAdapterError, match="start must be 'keyframe' or 'beside'"):
        load_adapter(Hinged).make_env(CAMS, 16, task=True)


# --- gates ------------------------------------------------------------------------------------
def test_captions_that_never_vary_are_refused_before_training(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], "AllObjectsAlways", AllObjectsAlways)
    spec = f"{__name__}:AllObjectsAlways"
    work = tmp_path / "work"
    assert main(["pretrain-vlm", "--scene", spec, "--out", str(tmp_path / "vlm"), "--workdir", str(work),
                 "--arch", "tiny", "--scenes", "4", "--shard-size", "4", "--steps", "2", "--batch-size", "4",
                 "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "the presence captions never vary" in err and "shown in every render" in err
    assert "let its scenes hold subsets" in err
    assert not (work / "checkpoint").exists() and not (tmp_path / "vlm" / "model.safetensors").exists()  # nothing trained


def test_eval_vlm_says_present_in_every_render_not_nan(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], "AllObjectsAlways", AllObjectsAlways)
    out = tmp_path / "presence.json"
    code = main(["eval-vlm", "--vlm", "scene", "--scene", f"{__name__}:AllObjectsAlways", "--images", "30",
                 "--out", str(out), "--quiet"])
    result, err = json.loads(out.read_text()), capsys.readouterr().err
    always = [o for o, c in result["meta"]["counts"].items() if c["absent"] == 0]
    assert always and code == 1  # at 16 px no object hides behind another in 10 scenes
    for obj in always:
        assert result[f"auroc.{obj}"] is None and result["meta"]["unmeasured"][obj] == "present in every render"
        assert f"{obj}: present in every render" in err
    assert "nan" not in out.read_text().lower()


def test_an_object_not_localised_is_named_by_the_gate(tmp_path):
    from zsrm.pipeline.own_scene import labeler_gates, localisation_gates, object_localisation, reward_gates

    grounding = {"meta": {"own_scene": {"adapter": SPEC}}, "block_width_px.front": 6.0, "block_width_px.left": 6.0,
                 "median_px_error_by_colour.front.white sphere": 9.5,
                 "median_px_error_by_colour.front.black box": 1.0,
                 "median_px_error_by_colour.left.white sphere": 1.0}
    loc = object_localisation(tmp_path, grounding)  # no renders: the adapter's one width
    assert loc["white sphere"]["front"] == {"median_error_px": 9.5, "half_width_px": 3.0}
    gates = localisation_gates(loc, {"white sphere": {"front", "left"}, "black box": {"front"},
                                     "teal capsule": {"left"}})
    failed = [g.line for g in gates if not g.ok]
    assert any("'white sphere' not localised on the front camera: median error 9.5 px > half its width 3.0 px" in line
               for line in failed)
    assert any("'teal capsule' was never located on the left camera" in line for line in failed)
    assert not any("black box" in line for line in failed) and len(failed) == 2
    ok = localisation_gates(loc, {"black box": {"front"}})
    assert [g.ok for g in ok] == [True]
    report = {"relations": {"vs_world": {"left_of": {"f1": 0.7}, "behind": {"f1": 0.95}}}}
    assert [g.ok for g in labeler_gates(report, ["behind", "left_of"], 0.85)] == [False]
    reward = {"zsrm": {"g1": {"f1": 0.9}, "g2": {"f1": 0.5}}, "base": {"g1": {"f1": 0.95}, "g2": {"f1": 0.1}}}
    lines = [g.line for g in reward_gates(reward, ["g1", "g2"], 0.85)]
    assert len(lines) == 2 and "not above the base reward" in lines[0] and "0.5 < 0.85 on 'g2'" in lines[1]


# --- the stand-in VLM: the masking check and zoomed views --------------------------------------
class _ChannelVLM:
    """Scores phrase j by how much of colour channel j an image holds: a VLM whose evidence for
    each phrase sits where that phrase's object is."""

    def encode_texts(self, texts):
        import torch

        return torch.eye(3)[: len(texts)]

    def encode_images(self, images):
        import torch

        return torch.as_tensor(np.asarray(images, np.float32).sum(axis=(1, 2)))


class _FixedCAM:
    def __init__(self, xy):
        self.xy = xy

    def __call__(self, images, phrases):
        return type("R", (), {"xy": self.xy[: len(images)]})()


def test_the_masking_check_agrees_with_true_points_and_not_with_swapped_ones():
    from zsrm.grounding.selfcheck import masking_agreement

    images = np.zeros((4, 16, 16, 3), np.uint8)
    images[:, 3:6, 3:6, 0] = 255  # object 0, red, at (4, 4)
    images[:, 10:13, 10:13, 1] = 255  # object 1, green, at (11, 11)
    present = np.array([[True, True, False]] * 4)
    phrases = ("red thing", "green thing", "blue thing")
    truth = np.tile(np.array([[[4.0, 4.0], [11.0, 11.0], [np.nan, np.nan]]]), (4, 1, 1))
    right = masking_agreement(_ChannelVLM(), _FixedCAM(truth), images, present, phrases, radius=2.0)
    assert right["agreement"]["red thing"] == right["agreement"]["green thing"] == 1.0 and right["min"] == 1.0
    assert right["agreement"]["blue thing"] is None and right["cases"]["red thing"] == 4
    swapped = truth[:, [1, 0, 2]]
    wrong = masking_agreement(_ChannelVLM(), _FixedCAM(swapped), images, present, phrases, radius=2.0)
    assert wrong["min"] == 0.0


def test_a_zoomed_view_names_what_its_window_shows_and_never_cuts_an_object():
    from zsrm.vlm.pretrain import zoomed_view

    image = np.zeros((32, 32, 3), np.uint8)
    mask = np.zeros((32, 32), np.uint8)
    mask[2:6, 2:6], mask[24:30, 24:30] = 1, 2
    image[mask == 1], image[mask == 2] = 200, 100
    rng = np.random.default_rng(0)
    for _ in range(40):
        view = zoomed_view(image, mask, rng, threshold=4)
        if view is None:
            continue
        img, shown = view
        assert img.shape == image.shape and len(shown) >= 1
        values = set(np.unique(img).tolist())
        for j in (0, 1):  # an object named is seen, one not named is not seen at all
            assert ((200 if j == 0 else 100) in values) == (j in shown)


def test_pretrain_with_zoomed_views_renders_masks_and_records_the_setting(tmp_path):
    out, work = tmp_path / "vlm", tmp_path / "work"
    assert main(["pretrain-vlm", "--scene", SPEC, "--out", str(out), "--workdir", str(work), "--arch", "tiny",
                 "--scenes", "4", "--shard-size", "4", "--steps", "3", "--batch-size", "8", "--zoom", "0.5",
                 "--warmup-steps", "1", "--quiet"]) == 0
    with np.load(next((work / "own-renders").glob("shard-*.npz"))) as shard:
        masks, visible = shard["masks"], shard["visible"]
    assert masks.shape[0] == visible.shape[0] == 12
    counts = np.stack([np.bincount(m.ravel(), minlength=5)[1:] for m in masks])
    assert (counts == visible).all()  # the masks are the counts, pixel by pixel
    assert json.loads((out / "config.json").read_text())["meta"]["config"]["zoom"] == 0.5


def test_zoom_without_an_own_scene_is_one_line(capsys):
    assert main(["pretrain-vlm", "--zoom", "0.5", "--out", "x"]) == 2
    assert "--zoom is for your own scene's renders" in capsys.readouterr().err


# --- the README's first example without MUJOCO_GL ------------------------------------------------
def test_the_readmes_python_example_runs_without_mujoco_gl_in_the_environment():
    code = ('import gymnasium as gym\nimport zsrm.envs\n'
            'env = gym.make("zsrm/Tabletop-v0", task="a yellow block on top of a red block", cameras=("front",), '
            'image_size=32)\nobs, info = env.reset(seed=0)\nprint(obs["front"].shape)\n')
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip() == "(32, 32, 3)"


# --- the one command --------------------------------------------------------------------------
TINY = ["--vlm-seeds", "0", "1", "--pretrain-scenes", "6", "--pretrain-steps", "3", "--images", "8",
        "--eval-images", "8", "--finetune-steps", "2", "--quiet"]
GOALS = ["a white sphere on the left of a black box", "a teal capsule behind a yellow ellipsoid"]


def test_the_one_command_runs_the_chain_end_to_end_and_its_gates_speak_up(tmp_path, capsys, monkeypatch):
    """Tiny scales: the chain runs every stage, writes its report, and at this scale the gates
    say it is not usable (exit 1), naming what failed; a rerun skips every finished stage."""
    import zsrm.pipeline.own_scene as chain
    from zsrm.pipeline.build import Finetune

    tiny_student = Finetune.__init__

    def init(self, *args, **kwargs):  # the tiny student architecture, few pairs a step
        tiny_student(self, *args, **kwargs)
        self.student_arch, self.batch_size, self.eval_every, self.checkpoint_every = "tiny", 8, 2, 2

    monkeypatch.setattr(Finetune, "__init__", init)
    monkeypatch.setattr(chain, "CHECK_IMAGES", 12)
    out, results = tmp_path / "chain", tmp_path / "results" / "slate.json"
    args = ["own-scene", "--scene", SPEC, "--goals", *GOALS, "--out", str(out), "--results", str(results),
            "--keep-going", *TINY]
    assert main(args) == 1  # a VLM of 3 steps localises nothing
    text = capsys.readouterr()
    assert "[1/6] vlm ..." in text.out and "[6/6] eval-reward: done" in text.out
    assert "FAILED [eval-grounding]" in text.err
    summary = json.loads(results.read_text())
    assert summary == json.loads((out / "summary.json").read_text())
    assert set(summary["labeler_f1"]) == {"left_of", "behind"}
    assert set(summary["reward_f1"]) == set(GOALS) and set(summary["reward_f1"][GOALS[0]]) == {"zsrm", "base"}
    for obj in BODIES:
        for role in ("front", "left", "tilted"):
            cell = summary["localisation"][obj][role]
            assert set(cell) == {"median_error_px", "half_width_px"} and cell["half_width_px"] > 0
    assert summary["meta"]["bare_xml"] is True and summary["meta"]["wall_s"] > 0
    assert summary["meta"]["command"].startswith("zsrm own-scene --scene " + SPEC)
    assert summary["usable"] is False and any(not g["ok"] for g in summary["gates"])
    assert summary["vlm"]["seed"] in (0, 1)
    assert summary["meta"]["students"] == 3 and summary["meta"]["reward_model"] == "students"  # the default
    reward_eval = json.loads((out / "reward_eval.json").read_text())
    assert reward_eval["meta"]["models"]["zsrm"] == str(out / "students")
    assert list(reward_eval["meta"]["training"]["zsrm"]["members"]) == ["../student", "../student-seed1",
                                                                         "../student-seed2"]
    report = (out / "report.md").read_text()
    assert "Usable: **no**" in report and "## Localisation" in report and (out / "localisation.png").is_file()
    assert main(args) == 1  # resumed: every stage is done
    assert capsys.readouterr().out.count(": done (") == 6


def test_the_one_command_stops_at_the_first_failed_gate(tmp_path, capsys, monkeypatch):
    import zsrm.pipeline.own_scene as chain

    monkeypatch.setattr(chain, "CHECK_IMAGES", 12)
    monkeypatch.setattr(chain, "PRESENCE_FLOOR", 1.01)  # no VLM reaches it
    out = tmp_path / "chain"
    assert main(["own-scene", "--scene", SPEC, "--goals", *GOALS, "--out", str(out), *TINY]) == 1
    text = capsys.readouterr()
    assert "FAILED [vlm]" in text.err and "presence AUROC" in text.err
    assert not (out / "train-data").exists()  # stopped before the next stage
    assert json.loads((out / "summary.json").read_text())["usable"] is False


def test_the_one_command_refuses_goals_the_scene_cannot_read(tmp_path, capsys):
    assert main(["own-scene", "--scene", SPEC, "--goals", "a red mug on the left of a black box",
                 "--out", str(tmp_path / "x")]) == 2
    assert "unknown object 'red mug'" in capsys.readouterr().err


def test_a_rerun_with_other_data_settings_in_the_same_folder_is_one_line(tmp_path, capsys):
    from zsrm.pipeline.own_scene import SceneChain

    out = tmp_path / "chain"
    SceneChain(scene=SPEC, goals=tuple(GOALS), out=str(out), dry_run=True).check_settings(out)
    assert not (out / "chain.json").exists()  # a dry run writes nothing
    SceneChain(scene=SPEC, goals=tuple(GOALS), out=str(out)).check_settings(out)
    assert main(["own-scene", "--scene", SPEC, "--goals", *GOALS, "--out", str(out), "--images", "10",
                 "--dry-run"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "holds a chain run with other settings (images: 4000 there, 10 here)" in err


def test_the_recorded_command_reruns_the_same_chain():
    from zsrm.cli import build_parser
    from zsrm.cli.options import from_namespace
    from zsrm.pipeline.own_scene import SceneChain

    chain = SceneChain(scene=SPEC, goals=tuple(GOALS), out="runs/x", results="r.json", vlm_seeds=(0, 1), zoom=0.5)
    words = chain.command().split(" ", 1)[1]
    import shlex

    again = from_namespace(SceneChain, build_parser().parse_args(shlex.split(words)))
    assert again.command() == chain.command() and again.goals == chain.goals and again.zoom == 0.5
    assert chain.command().startswith(f"zsrm own-scene --scene {SPEC} --goals ")


def test_a_goals_ppo_cells_keep_each_reward_and_the_ratio():
    from zsrm.pipeline.own_scene import ppo_cells

    cell = lambda m: {"final_mean": m, "final_se": 1.0, "seeds": 3, "final_per_seed": [m] * 3, "steps": 300}  # noqa: E731
    learning = {"g": {"oracle": cell(40.0), "zsrm": cell(36.0), "random": cell(4.0), "base": cell(9.0)}}
    got = ppo_cells(learning, "g")
    assert set(got) == {"goal", "oracle", "zsrm", "random", "zsrm_over_oracle"}
    assert got["zsrm_over_oracle"] == pytest.approx(0.9)
    assert got["oracle"] == {"mean": 40.0, "se": 1.0, "seeds": 3, "final_per_seed": [40.0] * 3, "steps": 300}


def test_the_sideways_benchmark_needs_the_chains_student(tmp_path):
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import own_scene
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    with pytest.raises(SystemExit, match="has no student: run the chain there first"):
        own_scene.main(["--sideways", "--work", str(tmp_path), "--out", str(tmp_path / "r.json")])
    assert not (tmp_path / "r.json").exists()


# --- several students: one reward of their mean score ------------------------------------------
class _Recorder:
    """Stands in for a stage's command: records how it was called; a student it trains is a
    folder with a student's config and training.json."""

    calls: list = []

    def __init__(self, **kwargs):
        self.kwargs = kwargs

    def run(self):
        _Recorder.calls.append(self.kwargs)
        if self.kwargs.get("student"):
            folder = Path(self.kwargs["out"])
            folder.mkdir(parents=True)
            (folder / "config.json").write_text(json.dumps({"backend": "zsrm-student"}))
            (folder / "training.json").write_text("{}")
        return 0


@pytest.fixture
def recorded(monkeypatch):
    import zsrm.pipeline.build as build
    import zsrm.pipeline.learn as learn
    import zsrm.pipeline.measure as measure

    for module, name in ((build, "Finetune"), (measure, "EvalReward"), (learn, "Sweep")):
        monkeypatch.setattr(module, name, _Recorder)
    monkeypatch.setattr(_Recorder, "calls", [])
    return _Recorder.calls


def _stages(out, students):
    from zsrm.pipeline.own_scene import SceneChain

    chain = SceneChain(scene=SPEC, goals=tuple(GOALS), out=str(out), students=students, ppo_goal=GOALS[0])
    out.mkdir(exist_ok=True)
    (out / "vlm.json").write_text(json.dumps({"chosen": str(out / "vlm-seed0")}))
    return {name: (run, done) for name, run, done in chain.stages(out)}


def test_three_students_train_seeds_0_to_2_and_the_rewards_read_their_ensemble(tmp_path, recorded):
    out = tmp_path / "chain"
    stages = _stages(out, 3)
    run, done = stages["finetune"]
    assert done == out / "students" / "config.json"
    (out / "student-seed1").mkdir()  # a killed run finished seed 1: it is kept, not trained again
    (out / "student-seed1" / "config.json").write_text(json.dumps({"backend": "zsrm-student"}))
    (out / "student-seed1" / "training.json").write_text("{}")
    run()
    assert [(c["seed"], c["out"]) for c in recorded] == [(0, str(out / "student")), (2, str(out / "student-seed2"))]
    assert all(c["student"] and c["data"] == str(out / "train-data") and c["vlm"] == str(out / "vlm-seed0")
               for c in recorded)
    assert json.loads(done.read_text())["members"] == ["../student", "../student-seed1", "../student-seed2"]
    recorded.clear()
    stages["eval-reward"][0]()
    stages["sweep"][0]()
    assert recorded[0]["zsrm"] == recorded[1]["reward_model"] == str(out / "students")


def test_one_student_is_the_chain_as_before(tmp_path, recorded):
    out = tmp_path / "chain"
    stages = _stages(out, 1)
    run, done = stages["finetune"]
    assert done == out / "student" / "training.json"
    run()
    assert [(c["seed"], c["out"]) for c in recorded] == [(0, str(out / "student"))]
    assert not (out / "students").exists()
    recorded.clear()
    stages["eval-reward"][0]()
    stages["sweep"][0]()
    assert recorded[0]["zsrm"] == recorded[1]["reward_model"] == str(out / "student")


def test_a_folder_from_before_students_is_refused_with_more_and_kept_with_one(tmp_path, capsys):
    from zsrm.pipeline.own_scene import SceneChain

    out = tmp_path / "chain"
    SceneChain(scene=SPEC, goals=tuple(GOALS), out=str(out), students=1).check_settings(out)
    old = {k: v for k, v in json.loads((out / "chain.json").read_text()).items() if k != "students"}
    (out / "chain.json").write_text(json.dumps(old))  # as written before --students
    SceneChain(scene=SPEC, goals=tuple(GOALS), out=str(out), students=1).check_settings(out)  # the old chain
    assert main(["own-scene", "--scene", SPEC, "--goals", *GOALS, "--out", str(out), "--dry-run"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "(students: 1 there, 3 here): give --students 1, another --out" in err
    assert main(["own-scene", "--scene", SPEC, "--goals", *GOALS, "--out", str(out), "--students", "0"]) == 2
    assert "--students must be >= 1" in capsys.readouterr().err


def test_the_report_says_which_reward_model_it_read(tmp_path):
    from zsrm.pipeline.own_scene import write_report

    meta = {"command": "zsrm own-scene", "wall_s": 1.0, "machine": "m", "numbers": "n"}
    summary = {"scene": "s", "usable": True, "gates": [], "meta": {**meta, "students": 3}}
    assert "Reward model: the mean image-text score of 3 students, seeds 0-2 (`students/`)." in \
        write_report(tmp_path, summary).read_text()
    summary["meta"] = meta  # a summary from before --students
    assert "Reward model: one student, seed 0 (`student/`)." in write_report(tmp_path, summary).read_text()

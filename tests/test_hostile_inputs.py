"""Hostile inputs (issue 16): every bad file and bad path gets one clear line naming it, before
the work starts; nothing read from a file ever runs code; a full disk leaves the last complete
file or shard, and a rerun resumes.

The damaged inputs are made here, small, from zsrm.testing.hostile (benchmarks/robustness.py
counts the same cases at the command line).
"""
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from zsrm.cli import COMMANDS, main
from zsrm.common.checkpoints import adamw, load_optimizer, read_checkpoint_state, save_checkpoint
from zsrm.common.files import ZsrmFileError, atomic_path, check_writable, write_json
from zsrm.common.registry import save_folder, save_weights
from zsrm.data.collect import CollectConfig, collect
from zsrm.data.dataset import ExplorationData
from zsrm.data.shards import load_npz, read_manifest
from zsrm.testing import hostile as H

KINDS = ["scene", "student", "adapted", "open_clip", "policy"]
TINY_DATA = dict(images=4, shard_size=2, episode_steps=2, record_every=1, image_size=32)


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    return H.saved_models(tmp_path_factory.mktemp("models"))


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    folder = tmp_path_factory.mktemp("data")
    collect(CollectConfig(**TINY_DATA), folder, progress=False)
    return folder


def one_line(err) -> str:
    text = str(err.value if hasattr(err, "value") else err)
    assert "\n" not in text.strip(), text
    return text


# --- saved models: weights ---------------------------------------------------------------------
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("damage", [*H.WEIGHT_DAMAGE, "pickle"])
def test_damaged_weights_are_one_line_naming_the_file(models, kind, damage, tmp_path):
    model = models[kind]
    folder = H.broken_copy(model, f"weights-{damage}")
    marker = tmp_path / "code-ran"
    if damage == "pickle":
        H.write_pickle_bomb(folder / model.weights, marker)
    else:
        H.WEIGHT_DAMAGE[damage](folder / model.weights)
    with pytest.raises(ZsrmFileError) as err:
        model.load(folder)
    assert str(folder / model.weights) in one_line(err)
    assert not marker.exists()


# --- saved models: config.json -----------------------------------------------------------------
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("damage", ["a_list", "missing", "string_for_number", "unknown_key", "sizes_not_the_weights"])
def test_bad_configs_are_one_line_naming_the_file(models, kind, damage):
    model = models[kind]
    folder = H.broken_copy(model, f"config-{damage}")
    damages = H.config_damage(model.resize, model.required)
    change = damages[f"missing_{model.required}" if damage == "missing" else damage]
    (folder / "config.json").write_text(json.dumps(change(json.loads((folder / "config.json").read_text()))))
    with pytest.raises(ZsrmFileError) as err:
        model.load(folder)
    named = folder / (model.weights if damage == "sizes_not_the_weights" else "config.json")
    assert str(named) in one_line(err)


def test_config_errors_say_what_is_wrong(models):
    model = models["student"]
    folder = H.broken_copy(model, "config-says")
    config = json.loads((folder / "config.json").read_text())
    config["config"]["widths"] = [8, 8, 8]
    (folder / "config.json").write_text(json.dumps(config))
    with pytest.raises(ZsrmFileError, match=r"config\.widths must be a list of 4 values, got 3|widths.*4"):
        model.load(folder)


# --- checkpoints -------------------------------------------------------------------------------
@pytest.fixture
def checkpoint(tmp_path):
    torch.manual_seed(0)
    model = torch.nn.Sequential(torch.nn.Linear(3, 4), torch.nn.Linear(4, 2))
    opt = adamw(model, 1e-3, 0.0)
    model(torch.ones(1, 3)).sum().backward()
    opt.step()
    folder = tmp_path / "checkpoint"
    save_checkpoint(folder, lambda tmp: save_weights(model, tmp), opt, {"step": 1, "config": {"a": 1}, "log": []})
    return folder, model, opt


def test_a_pickled_optimizer_state_is_refused_and_never_run(checkpoint, tmp_path):
    folder, model, opt = checkpoint
    for name in ("optimizer.json", "optimizer.safetensors"):
        (folder / name).unlink()
    marker = tmp_path / "code-ran"
    H.write_pickle_bomb(folder / "optimizer.pt", marker, torch_format=True)
    with pytest.raises(ZsrmFileError, match="not plain tensors") as err:
        load_optimizer(folder, opt)
    assert str(folder / "optimizer.pt") in one_line(err)
    assert not marker.exists()


@pytest.mark.parametrize("damage", ["truncated_tensors", "json_list", "json_missing_state", "bad_key",
                                    "other_model", "state_list", "state_missing_step", "state_string_step"])
def test_damaged_checkpoints_are_one_line(checkpoint, damage):
    folder, model, opt = checkpoint
    if damage == "truncated_tensors":
        H.WEIGHT_DAMAGE["truncated"](folder / "optimizer.safetensors")
    elif damage.startswith("json"):
        saved = json.loads((folder / "optimizer.json").read_text())
        write_json(folder / "optimizer.json", [saved] if damage == "json_list" else {"param_groups": []})
    elif damage == "bad_key":
        saved = json.loads((folder / "optimizer.json").read_text())
        write_json(folder / "optimizer.json", {**saved, "state": {"nonsense": 1}})
    elif damage == "other_model":
        opt = adamw(torch.nn.Linear(3, 4), 1e-3, 0.0)
    else:
        state = {"step": "1", "config": {"a": 1}, "log": []} if damage == "state_string_step" else \
            [1] if damage == "state_list" else {"config": {"a": 1}, "log": []}
        write_json(folder / "state.json", state)
        with pytest.raises(ZsrmFileError) as err:
            read_checkpoint_state(folder, {"a": 1})
        assert str(folder / "state.json") in one_line(err)
        return
    with pytest.raises(ZsrmFileError) as err:
        load_optimizer(folder, opt)
    assert str(folder) in one_line(err)


def test_an_rl_checkpoint_with_a_bad_optimizer_fails_before_training(models, tmp_path):
    from zsrm.rl.policy import PolicyBundle, load_checkpoint

    bundle = PolicyBundle.load(models["policy"].folder)
    folder = tmp_path / "checkpoint"
    shutil.copytree(models["policy"].folder, folder)
    write_json(folder / "state.json", {"config": bundle.cfg.identity(), "env_steps": 64, "rows": []})
    H.write_pickle_bomb(folder / "optimizer.pt", tmp_path / "code-ran", torch_format=True)
    with pytest.raises(ZsrmFileError, match="optimizer.pt"):
        load_checkpoint(folder, bundle.cfg)
    assert not (tmp_path / "code-ran").exists()


# --- data folders ------------------------------------------------------------------------------
@pytest.mark.parametrize("damage", ["not_json", "a_list", "missing_shards", "string_n_shards"])
def test_damaged_manifests_are_one_line(dataset, tmp_path, damage):
    folder = tmp_path / "data"
    shutil.copytree(dataset, folder)
    manifest = json.loads((folder / "manifest.json").read_text())
    text = {"not_json": "{oops", "a_list": json.dumps([manifest]),
            "missing_shards": json.dumps({k: v for k, v in manifest.items() if k != "shards"}),
            "string_n_shards": json.dumps({**manifest, "n_shards": "2"})}[damage]
    (folder / "manifest.json").write_text(text)
    with pytest.raises(ZsrmFileError) as err:
        ExplorationData(folder)
    assert str(folder / "manifest.json") in one_line(err)


@pytest.mark.parametrize("damage", ["empty", "truncated", "random_bytes", "pickle"])
def test_damaged_shards_are_one_line_and_never_unpickled(dataset, tmp_path, damage):
    path = tmp_path / "shard_00000.npz"
    shutil.copy(dataset / "shard_00000.npz", path)
    if damage == "pickle":
        np.save(path.with_suffix(".npy"), np.array([H._Bomb(tmp_path / "code-ran")], dtype=object),
                allow_pickle=True)
        path.write_bytes(path.with_suffix(".npy").read_bytes())
    else:
        H.WEIGHT_DAMAGE[damage](path)
    with pytest.raises(ZsrmFileError) as err:
        load_npz(path)
    assert str(path) in one_line(err)
    assert not (tmp_path / "code-ran").exists()


# --- outputs: unwritable places ----------------------------------------------------------------
def writer_commands(tmp_path, out, dataset) -> dict[str, list[str]]:
    """Each command that writes, with its output (or output folder) at ``out``."""
    return {
        "collect": ["collect", "--out", str(out), "--images", "2"],
        "render": ["render", "stack", "--out", str(out / "x.png")],
        "scripted-eval": ["scripted-eval", "--episodes", "1", "--out", str(out / "x.json")],
        "reward-curve": ["reward-curve", "--out", str(out / "fig")],
        "eval-reward": ["eval-reward", "--zsrm", "student", "--out", str(out / "x.json")],
        "label": ["label", str(dataset), "--labels", str(out)],
        "finetune": ["finetune", "--data", str(dataset), "--out", str(out)],
        "eval-grounding": ["eval-grounding", str(dataset), "--out", str(out / "x.json")],
        "reward-data": ["reward-data", "--out", str(out)],
        "pretrain-vlm": ["pretrain-vlm", "--out", str(out), "--workdir", str(tmp_path / "work")],
        "eval-vlm": ["eval-vlm", "--out", str(out / "x.json")],
        "eval-pose": ["eval-pose", "--vlm", "scene", "--out", str(out / "x.json")],
        "demo": ["demo", "--out", str(out)],
        "train": ["train", "--out", str(out), "--steps", "64"],
        "rollout": ["rollout", "random:stack", "--episodes", "1", "--out", str(out / "x.json")],
        "sweep": ["sweep", "--root", str(out), "--out", str(tmp_path / "sweep.json")],
        "plot": ["plot", "--summary", str(tmp_path / "learning.json"), "--figure6", str(out / "figure6.png")],
        "reproduce": ["reproduce", "--workdir", str(out), "--report", str(tmp_path / "report")],
        "multitask-policies": ["multitask-policies", "--root", str(out), "--out", str(tmp_path / "p.json")],
        "multitask-rollouts": ["multitask-rollouts", "--out", str(out)],
        "distill": ["distill", "--out", str(out)],
        "eval-multitask": ["eval-multitask", "--out", str(out / "table2.json")],
        "eval-goals": ["eval-goals", "--out", str(out / "goals.json")],
        "results-page": ["results-page", "--results", str(out), "--readme", str(out / "README.md")],
        "own-scene": ["own-scene", "--scene", "examples.slate_scene.adapter:SlateScene", "--goals",
                      "a white sphere on the left of a black box", "--out", str(out)],
    }


def test_every_writing_command_is_listed():
    # zsrm reward and parse-goal print what they find.
    writes = set(COMMANDS) - {"reward", "parse-goal"}
    assert writes <= set(writer_commands(Path("."), Path("."), Path(".")))


@pytest.mark.parametrize("command", ["collect", "render", "scripted-eval", "reward-curve", "eval-reward", "label",
                                     "finetune", "eval-grounding", "reward-data", "pretrain-vlm", "eval-vlm",
                                     "eval-pose", "demo", "train", "rollout", "sweep", "plot", "reproduce",
                                     "multitask-policies", "multitask-rollouts", "distill", "eval-multitask",
                                     "eval-goals", "results-page", "own-scene"])
def test_an_unwritable_output_is_one_line_before_any_work(command, dataset, tmp_path, capsys, monkeypatch):
    def no_work(*args, **kwargs):
        raise AssertionError("work started before the output was checked")

    for target in ("zsrm.data.collect.collect", "zsrm.vlm.factory.load_vlm", "zsrm.rl.ppo.train",
                   "zsrm.rl.evaluate.rollout", "zsrm.rl.sweep.sweep", "zsrm.fullmodel.training.finetune",
                   "zsrm.evaluation.scripted_success.scripted_success", "zsrm.pipeline.demo.write_reward_curves",
                   "zsrm.pipeline.reproduce.run_stages", "zsrm.evaluation.goal_parsing.score_goals"):
        monkeypatch.setattr(target, no_work)
    for where, out in H.unwritable_paths(tmp_path).items():
        assert main(writer_commands(tmp_path, out, dataset)[command]) == 2, where
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"zsrm {command}: error: cannot write") and "\n" not in err, err


def test_check_writable_names_the_path(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(ZsrmFileError, match="cannot write"):
        check_writable(tmp_path / "f" / "out.json")
    with pytest.raises(ZsrmFileError, match="is a folder"):
        check_writable(tmp_path)
    assert check_writable(tmp_path / "new" / "out.json").parent.is_dir()


# --- outputs: a full disk ----------------------------------------------------------------------
def test_a_full_disk_keeps_the_previous_file(tmp_path):
    path = write_json(tmp_path / "a.json", {"v": 1})
    with H.full_disk(), pytest.raises(ZsrmFileError, match="no space left") as err:
        write_json(path, {"v": 2})
    assert str(path) in one_line(err)
    assert json.loads(path.read_text()) == {"v": 1} and [p.name for p in tmp_path.iterdir()] == ["a.json"]
    with H.full_disk(), pytest.raises(ZsrmFileError), atomic_path(tmp_path / "b.png") as tmp:
        tmp.write_bytes(b"png")
    assert not (tmp_path / "b.png").exists()


def test_a_full_disk_during_collect_keeps_the_finished_shards_and_a_rerun_resumes(dataset, tmp_path):
    with H.full_disk(after=3), pytest.raises(ZsrmFileError, match="no space left"):
        collect(CollectConfig(**TINY_DATA), tmp_path, progress=False)  # manifest, shard 0, manifest: then full
    assert list(read_manifest(tmp_path)["shards"]) == ["shard_00000"]
    collect(CollectConfig(**TINY_DATA), tmp_path, progress=False)
    for name in ("shard_00000.npz", "shard_00001.npz"):
        a, b = load_npz(tmp_path / name), load_npz(dataset / name)
        for k in a:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)  # NaN (absent objects) equal to NaN


def test_a_full_disk_during_a_checkpoint_keeps_the_previous_one(checkpoint):
    folder, model, opt = checkpoint
    with H.full_disk(after=1), pytest.raises(ZsrmFileError, match="no space left"):
        save_checkpoint(folder, lambda tmp: save_weights(model, tmp), opt, {"step": 2, "config": {"a": 1}, "log": []})
    assert read_checkpoint_state(folder, {"a": 1})["step"] == 1
    assert sorted(p.name for p in folder.parent.iterdir()) == ["checkpoint"]
    load_optimizer(folder, opt)


def test_a_full_disk_while_saving_a_model_is_one_line(tmp_path):
    with H.full_disk(), pytest.raises(ZsrmFileError, match="no space left"):
        save_folder(tmp_path / "m", {"backend": "x"}, {"model.safetensors": torch.nn.Linear(2, 2)})


def test_the_cli_prints_a_full_disk_as_one_line(tmp_path, capsys):
    with H.full_disk():
        assert main(["render", "stack", "--size", "32", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("zsrm render: error: no space left") and "\n" not in err
    assert not list(tmp_path.iterdir())

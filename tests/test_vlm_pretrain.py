"""Pretraining (zsrm/vlm/pretrain.py on renders of zsrm/data/renders.py), its resume after a kill,
and the presence evaluation."""
import json
from pathlib import Path

import numpy as np
import pytest
import torch

import zsrm.data.renders as renders_mod
import zsrm.vlm.pretrain as pretrain_mod
from zsrm.cli import main
from zsrm.data.renders import load_renders
from zsrm.pipeline.build import pretrain_scene_vlm
from zsrm.vlm import load_vlm
from zsrm.evaluation.vlm_presence import presence_eval, write_presence_results
from zsrm.vlm.pretrain import PretrainConfig, learning_rate, make_batch

TINY = dict(arch="tiny", scenes=4, shard_size=2, steps=6, batch_size=8, checkpoint_every=2, warmup_steps=2)


def cli_args(out, work):
    return ["pretrain-vlm", "--out", str(out), "--workdir", str(work), "--arch", "tiny", "--scenes", "4",
            "--shard-size", "2", "--steps", "6", "--batch-size", "8", "--checkpoint-every", "2", "--warmup-steps", "2",
            "--quiet"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """An uninterrupted tiny run through the CLI."""
    root = tmp_path_factory.mktemp("pretrain")
    assert main(cli_args(root / "out", root / "work")) == 0
    return root


def test_a_run_writes_model_checkpoint_log_and_render_cache(trained):
    out, work = trained / "out", trained / "work"
    assert {p.name for p in out.iterdir()} == {"model.safetensors", "config.json"}
    meta = json.loads((out / "config.json").read_text())["meta"]
    assert meta["trained_by"] == "zsrm pretrain-vlm" and meta["config"]["steps"] == 6
    assert sorted(p.name for p in (work / "renders").glob("shard-*.npz")) == ["shard-0000.npz", "shard-0001.npz"]
    assert {p.name for p in (work / "checkpoint").iterdir()} >= {"model.safetensors", "optimizer.safetensors",
                                                                  "optimizer.json", "state.json"}
    state = json.loads((work / "checkpoint" / "state.json").read_text())
    assert state["step"] == 6
    # The optimizer state is safetensors + JSON: nothing is unpickled to resume.
    assert "param_groups" in json.loads((work / "checkpoint" / "optimizer.json").read_text())
    assert (work / "log.csv").read_text().startswith("step,loss,seconds")


def test_resume_after_a_kill_matches_an_uninterrupted_run_without_re_rendering(trained, tmp_path, monkeypatch):
    cfg = PretrainConfig(out=str(tmp_path / "out"), workdir=str(tmp_path / "work"), **TINY)
    real_make_batch = make_batch

    def dies_at_step_3(data, rows, step, c):
        if step == 3:
            raise KeyboardInterrupt  # the kill
        return real_make_batch(data, rows, step, c)

    monkeypatch.setattr(pretrain_mod, "make_batch", dies_at_step_3)
    with pytest.raises(KeyboardInterrupt):
        pretrain_scene_vlm(cfg, progress=False)
    assert json.loads((tmp_path / "work" / "checkpoint" / "state.json").read_text())["step"] == 2
    assert not (tmp_path / "out").exists()

    monkeypatch.setattr(pretrain_mod, "make_batch", real_make_batch)
    monkeypatch.setattr(renders_mod, "render_presence_scenes", lambda *a, **k: pytest.fail("re-rendered"))
    resumed = pretrain_scene_vlm(cfg, progress=False)
    reference = load_vlm(str(trained / "out"))
    for (name, a), (_, b) in zip(resumed.state_dict().items(), reference.state_dict().items()):
        assert torch.allclose(a, b, atol=1e-6), name


def test_changed_settings_refuse_to_resume(trained, tmp_path):
    import shutil

    shutil.copytree(trained / "work", tmp_path / "work")
    cfg = PretrainConfig(out=str(tmp_path / "out"), workdir=str(tmp_path / "work"), **{**TINY, "lr": 1e-3})
    with pytest.raises(ValueError, match="other settings.*lr"):
        pretrain_scene_vlm(cfg, progress=False)


def test_batches_are_a_function_of_seed_and_step(trained):
    cfg = PretrainConfig(workdir=str(trained / "work"), **TINY)
    data = load_renders(Path(cfg.workdir) / "renders", cfg.scenes, cfg.shard_size, cfg.seed, progress=False)
    rows = np.arange(len(data["images"]))
    a, b = make_batch(data, rows, 5, cfg), make_batch(data, rows, 5, cfg)
    assert np.array_equal(a[0], b[0]) and a[1] == b[1]
    assert a[1] != make_batch(data, rows, 6, cfg)[1] or not np.array_equal(a[0], make_batch(data, rows, 6, cfg)[0])
    assert learning_rate(0, cfg) < learning_rate(1, cfg) == cfg.lr  # warmup
    assert learning_rate(cfg.steps, cfg) == pytest.approx(0.0)


def test_presence_eval_reports_flat_auroc_keys_and_a_plot(trained, tmp_path):
    vlm = load_vlm(str(trained / "out"))
    result, arrays = presence_eval(vlm, n_images=12, seed=0, progress=False)
    assert [k for k in result if k.startswith("auroc.")] == ["auroc.red", "auroc.green", "auroc.yellow", "auroc.blue"]
    assert result["meta"]["n_images"] == 12 and arrays["scores"].shape == (12, 4)
    json_path, png = write_presence_results(result, arrays, tmp_path / "r" / "p.json")
    assert json.loads(json_path.read_text())["meta"]["n_images"] == 12 and png.stat().st_size > 1000


def test_eval_cli_writes_json_and_png(trained, tmp_path, capsys):
    out = tmp_path / "p.json"
    code = main(["eval-vlm", "--vlm", str(trained / "out"), "--images", "12", "--out", str(out), "--quiet",
                 "--min-auroc", "0"])
    assert code == 0 and out.exists() and out.with_suffix(".png").exists()
    meta = json.loads(out.read_text())["meta"]
    assert meta["command"].startswith("zsrm eval-vlm --vlm") and meta["n_images"] == 12
    assert main(["pretrain-vlm", "--resume", "--workdir", str(tmp_path / "none"), "--quiet"]) == 2
    assert "no checkpoint" in capsys.readouterr().err

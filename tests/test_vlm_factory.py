"""load_vlm specs (zsrm/vlm/factory.py, zsrm/common/registry.py) and the torchvision import guard
(zsrm/vlm/compat.py)."""
import json
from pathlib import Path

import pytest

from zsrm.cli import main
from zsrm.common.registry import SHIPPED
from zsrm.vlm import SHIPPED_SCENE_DIR, SceneVLM, create_scene_vlm, load_vlm


def test_shipped_scene_model_missing_says_how_to_build_it(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(SHIPPED, "scene", tmp_path / "nowhere")
    with pytest.raises(FileNotFoundError, match="zsrm pretrain-vlm"):
        load_vlm("scene")
    assert main(["eval-vlm", "--vlm", "scene", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "zsrm pretrain-vlm" in err[0]


def test_a_pinned_shipped_model_loads_only_as_that_version(tmp_path, monkeypatch):
    """student@DIGEST (what a training run records) loads while the shipped weights are that
    version; once they are retrained, it says so instead of scoring with other weights."""
    import shutil

    from zsrm.fullmodel import SHIPPED_STUDENT_DIR, load_reward_backbone
    from zsrm.vlm.factory import pinned

    spec = pinned("student")
    assert spec.startswith("student@") and len(spec) == len("student@") + 12
    assert pinned(spec) == spec and pinned("scene").startswith("scene@") and pinned("/some/folder") == "/some/folder"
    load_reward_backbone(spec)
    retrained = tmp_path / "student"
    shutil.copytree(SHIPPED_STUDENT_DIR, retrained)
    (retrained / "model.safetensors").write_bytes((retrained / "model.safetensors").read_bytes() + b" ")
    monkeypatch.setitem(SHIPPED, "student", retrained)
    with pytest.raises(ValueError, match="retrained since"):
        load_reward_backbone(spec)
    assert pinned("student") != spec
    # A version kept beside it under retired/ still loads by its pin.
    kept = tmp_path / "retired" / spec
    shutil.copytree(SHIPPED_STUDENT_DIR, kept)
    load_reward_backbone(spec)
    (kept / "model.safetensors").write_bytes(b"not those weights")
    with pytest.raises(ValueError, match="retrained since"):
        load_reward_backbone(spec)


def test_the_student_that_trained_the_learning_runs_is_kept():
    """results/rl's zsrm trials pin the student they trained with: the v1 trials (results/rl/v1/) the
    one trained before the box, which ships under retired/; the others the shipped one."""
    from zsrm.fullmodel import load_reward_backbone

    results = Path(__file__).parent.parent / "results" / "rl"
    pins = {json.loads(p.read_text())["config"]["reward_model"]
            for folder in (results / "trials", results / "v1" / "trials") for p in folder.glob("*-zsrm-*.json")}
    assert pins and all(p.startswith("student@") for p in pins)
    for pin in pins:
        load_reward_backbone(pin)


def test_saved_folders_load_by_path(tmp_path):
    create_scene_vlm("tiny", seed=0).save(tmp_path / "m")
    assert isinstance(load_vlm(str(tmp_path / "m")), SceneVLM)
    assert isinstance(load_vlm(tmp_path / "m"), SceneVLM)


@pytest.mark.parametrize("spec, error, message", [
    ("", ValueError, "give a VLM spec"),
    ("clip", ValueError, "unknown VLM spec 'clip'"),
    ("runs/missing-folder", ValueError, "does not exist"),
])
def test_bad_specs(spec, error, message):
    with pytest.raises(error, match=message):
        load_vlm(spec)


def test_broken_folders(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="no config.json"):
        load_vlm(str(tmp_path / "empty"))
    (tmp_path / "odd").mkdir()
    (tmp_path / "odd" / "config.json").write_text(json.dumps({"backend": "blip"}))
    with pytest.raises(ValueError, match="unknown model kind 'blip'"):
        load_vlm(str(tmp_path / "odd"))
    (tmp_path / "noweights").mkdir()
    create_scene_vlm("tiny").save(tmp_path / "noweights")
    (tmp_path / "noweights" / "model.safetensors").unlink()
    with pytest.raises(FileNotFoundError, match="no model.safetensors"):
        load_vlm(str(tmp_path / "noweights"))


def test_shipped_scene_model_loads_when_present():
    if not (SHIPPED_SCENE_DIR / "model.safetensors").exists():
        pytest.fail("the shipped scene VLM is missing: run `zsrm pretrain-vlm`")
    vlm = load_vlm("scene")
    assert vlm.config.image_size == 64 and vlm.gradcam_layer == "visual.final"
    assert vlm.meta["trained_by"] == "zsrm pretrain-vlm"


def test_torchvision_imports_on_this_machine():
    from zsrm.vlm.compat import import_torchvision

    tv = import_torchvision()
    assert tv.models.resnet18(weights=None).fc.in_features == 512

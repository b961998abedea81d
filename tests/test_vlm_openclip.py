"""The open_clip backend (zsrm/vlm/openclip.py): loading, offline errors, the Grad-CAM split.

Tiny open_clip architectures registered from JSON keep these tests fast; RN50 itself is
built once with random weights to check the paper's Grad-CAM layer.
"""
import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

from zsrm.vlm import OpenClipVLM, WeightsUnavailableError, create_open_clip_vlm, load_vlm
from zsrm.vlm.compat import import_open_clip

TINY_TEXT = {"context_length": 77, "vocab_size": 49408, "width": 32, "heads": 2, "layers": 1}
TINY_CONFIGS = {
    "zsrm-test-tiny-rn": {"embed_dim": 32, "vision_cfg": {"image_size": 64, "layers": [1, 1, 1, 1], "width": 8},
                          "text_cfg": TINY_TEXT},
    "zsrm-test-tiny-vit": {"embed_dim": 32, "vision_cfg": {"image_size": 64, "layers": 1, "width": 32,
                                                           "head_width": 16, "patch_size": 16},
                           "text_cfg": TINY_TEXT},
}


@pytest.fixture(scope="module", autouse=True)
def tiny_configs(tmp_path_factory):
    open_clip = import_open_clip()
    folder = tmp_path_factory.mktemp("open_clip_configs")
    for name, cfg in TINY_CONFIGS.items():
        (folder / f"{name}.json").write_text(json.dumps(cfg))
    open_clip.add_model_config(folder)


def frames(n=2, size=64):
    return np.random.default_rng(0).integers(0, 256, (n, size, size, 3), dtype=np.uint8)


def test_offline_download_fails_fast_with_one_line_that_says_how_to_pass_a_file():
    assert os.environ.get("HF_HUB_OFFLINE") == "1"
    start = time.time()
    with pytest.raises(WeightsUnavailableError) as err:
        load_vlm("open_clip:RN50")  # default tag: openai
    assert time.time() - start < 30
    msg = str(err.value)
    assert isinstance(err.value, FileNotFoundError) and "\n" not in msg
    assert "'openai'" in msg and "open_clip:RN50-quickgelu:/path/to/open_clip_model.safetensors" in msg
    assert "huggingface.co/timm/resnet50_clip.openai" in msg


def test_cli_prints_the_offline_error_as_one_line(tmp_path):
    env = {**os.environ, "HF_HUB_OFFLINE": "1"}
    env.pop("ZSRM_DEBUG", None)
    proc = subprocess.run([sys.executable, "-m", "zsrm.cli", "eval-vlm", "--vlm", "open_clip:RN50:openai",
                           "--out", str(tmp_path / "x.json")], capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 2
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in proc.stderr
    assert lines[0].startswith("zsrm eval-vlm: error: open_clip RN50 weights 'openai'")


def test_unknown_models_and_tags_are_clear_errors():
    with pytest.raises(ValueError, match="unknown open_clip model 'RN51'"):
        load_vlm("open_clip:RN51:none")
    with pytest.raises(ValueError, match="no weights 'laion9b' for RN50; known: openai"):
        load_vlm("open_clip:RN50:laion9b")
    with pytest.raises(FileNotFoundError, match="no such checkpoint file"):
        load_vlm("open_clip:RN50:/nowhere/weights.safetensors")


def test_rn50_splits_at_layer4_for_gradcam():
    vlm = load_vlm("open_clip:RN50:none")
    assert isinstance(vlm, OpenClipVLM) and vlm.gradcam_layer == "visual.layer4" and vlm.image_size == 224
    x = vlm.preprocess(frames(1))
    assert x.shape == (1, 3, 224, 224)
    with torch.no_grad():
        feats = vlm.image_trunk(x)
        assert feats.shape == (1, 2048, 7, 7) and (feats >= 0).all()
        # trunk + head is exactly open_clip's own image encoder
        assert torch.allclose(vlm.image_head(feats), vlm.clip.encode_image(x), atol=1e-5)
        assert vlm.encode_texts(["a red block"]).shape == (1, 1024)


@pytest.mark.filterwarnings("ignore::DeprecationWarning", "ignore::UserWarning")
def test_local_checkpoints_load_without_running_code(tmp_path):
    torch.manual_seed(0)
    src = create_open_clip_vlm("zsrm-test-tiny-rn", "none")
    state = src.clip.state_dict()
    from safetensors.torch import save_model

    save_model(src.clip, str(tmp_path / "w.safetensors"))
    torch.save(state, tmp_path / "w.pt")
    torch.save({"state_dict": {f"module.{k}": v for k, v in state.items()}}, tmp_path / "w_wrapped.bin")
    x, texts = frames(), ["a red block", "a blue puck"]
    ref_i, ref_t = src.encode_images(x), src.encode_texts(texts)
    for name in ("w.safetensors", "w.pt", "w_wrapped.bin"):
        vlm = load_vlm(f"open_clip:zsrm-test-tiny-rn:{tmp_path / name}")
        assert torch.equal(vlm.encode_images(x), ref_i) and torch.equal(vlm.encode_texts(texts), ref_t)
    # A pickle with code in it is refused (weights_only), as is a TorchScript archive.
    torch.save({"weights": state, "evil": Exception("not a tensor")}, tmp_path / "evil.pt")
    with pytest.raises(ValueError, match="weights only|does not fit"):
        load_vlm(f"open_clip:zsrm-test-tiny-rn:{tmp_path / 'evil.pt'}")
    torch.jit.save(torch.jit.script(torch.nn.Linear(2, 2)), tmp_path / "scripted.pt")
    with pytest.raises(ValueError, match="TorchScript"):
        load_vlm(f"open_clip:zsrm-test-tiny-rn:{tmp_path / 'scripted.pt'}")
    # Weights of another architecture: a clear error, not a traceback from load_state_dict.
    other = {k: v for k, v in state.items() if not k.startswith("visual.layer4")}
    save_model_dict = tmp_path / "partial.safetensors"
    from safetensors.torch import save_file

    save_file({k: v.contiguous() for k, v in other.items()}, str(save_model_dict))
    with pytest.raises(ValueError, match="does not fit"):
        load_vlm(f"open_clip:zsrm-test-tiny-rn:{save_model_dict}")


def test_save_load_round_trip_is_identical(tmp_path):
    torch.manual_seed(1)
    vlm = create_open_clip_vlm("zsrm-test-tiny-rn", "none")
    vlm.save(tmp_path / "m")
    again = load_vlm(str(tmp_path / "m"))
    assert isinstance(again, OpenClipVLM) and again.model_name == "zsrm-test-tiny-rn"
    x, texts = frames(3), ["a yellow block", "a green block and a red block"]
    assert torch.equal(again.encode_images(x), vlm.encode_images(x))
    assert torch.equal(again.encode_texts(texts), vlm.encode_texts(texts))
    # The weights file is open_clip's own state dict: open_clip specs read it directly.
    direct = load_vlm(f"open_clip:zsrm-test-tiny-rn:{tmp_path / 'm' / 'model.safetensors'}")
    assert torch.equal(direct.encode_images(x), vlm.encode_images(x))


def test_vision_transformers_encode_but_refuse_the_gradcam_split():
    vit = create_open_clip_vlm("zsrm-test-tiny-vit", "none")
    assert vit.gradcam_layer is None
    assert vit.encode_images(frames(2)).shape == (2, 32)
    with pytest.raises(NotImplementedError, match="no last convolutional ReLU"):
        vit.image_trunk(vit.preprocess(frames(1)))

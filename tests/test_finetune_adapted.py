"""The image and text adapters added to a VLM for fine-tuning (zsrm/fullmodel/adapted.py)."""
import json

import numpy as np
import pytest
import torch

from zsrm.fullmodel.adapted import AdaptedVLM
from zsrm.fullmodel import load_reward_backbone
from zsrm.fullmodel.training import FinetuneConfig, initial_model
from zsrm.vlm import create_scene_vlm


def tiny():
    return create_scene_vlm("tiny", seed=0, image_size=32)


def adapted(vlm=None, **kw):
    return AdaptedVLM(vlm or tiny(), reference=tiny(), reference_spec="unused", **kw)


def frames(n=3, size=32, seed=0):
    return np.random.default_rng(seed).integers(0, 256, (n, size, size, 3), dtype=np.uint8)


def test_starts_as_the_vlm_and_reads_positions_once_trained(tmp_path):
    vlm = tiny()
    model = adapted(vlm, grid=4)
    x = frames()
    torch.testing.assert_close(model.encode_images(x), vlm.encode_images(x))
    texts = ["a red block on the left of a blue block", "a red block on the right of a blue block"]
    torch.testing.assert_close(model.encode_texts(texts), vlm.encode_texts(texts))
    assert model.logit_scale is vlm.logit_scale
    # The same object in another place: the pooled head barely moves, the read-out does.
    im = np.full((2, 32, 32, 3), 120, np.uint8)
    im[0, 12:18, 2:8] = (220, 30, 30)
    im[1, 12:18, 24:30] = (220, 30, 30)
    torch.nn.init.normal_(model.spatial[-1].weight, std=0.1)
    base = vlm.encode_images(im, normalize=False)
    full = model.encode_images(im, normalize=False)
    assert (full[0] - full[1]).norm() > 2 * (base[0] - base[1]).norm()


def test_text_adapter_separates_what_the_text_tower_blurs():
    from zsrm.tasks.negatives import candidate_texts

    vlm = tiny()
    model = adapted(vlm, grid=0)
    vocab = list(dict.fromkeys(t for g in ("a red block on the left of a blue block",
                                           "a green block on top of a yellow block",
                                           "a blue block behind a green block") for t in candidate_texts(g)))
    model.fit_text_statistics(vocab)
    assert bool(model.text_norm.whiten.fitted)
    z = model.text_norm.whiten(model.reference_texts(vocab))
    # The adapter reads the frozen reference, which is no parameter of the model.
    assert not any(n.startswith("reference") for n, _ in model.named_parameters())
    assert all(not p.requires_grad for p in model.reference.parameters())
    torch.testing.assert_close(z.mean(dim=0), torch.zeros(z.shape[1]), atol=1e-4, rtol=0)
    # Whitened, "left of" and "right of" are far apart even where the raw embeddings are not.
    raw = torch.nn.functional.normalize(vlm.encode_text_tokens(vocab[:2]).detach(), dim=-1)
    white = torch.nn.functional.normalize(z[:2].detach(), dim=-1)
    assert float(white[0] @ white[1]) < float(raw[0] @ raw[1])


def test_saves_and_loads_with_its_base_and_reference(tmp_path):
    tiny().save(tmp_path / "models" / "reference")
    reference = load_reward_backbone(str(tmp_path / "models" / "reference"))
    model = AdaptedVLM(tiny(), grid=2, reference=reference, reference_spec=str(tmp_path / "models" / "reference"))
    model.fit_text_statistics(["a red block on top of a blue block", "a blue block on top of a red block",
                               "a red block close to a green block"])
    torch.nn.init.normal_(model.spatial[-1].weight)
    torch.nn.init.normal_(model.text_adapter[-1].weight)
    model.save(tmp_path / "models" / "m")
    assert (tmp_path / "models" / "m" / "base" / "config.json").is_file()
    (tmp_path / "models").rename(tmp_path / "moved")  # the reference is found relative to the model
    loaded = load_reward_backbone(str(tmp_path / "moved" / "m"))
    assert isinstance(loaded, AdaptedVLM) and loaded.grid == 2
    x = frames()
    torch.testing.assert_close(loaded.encode_images(x), model.encode_images(x))
    text = ["a red block on the left of a blue block"]
    torch.testing.assert_close(loaded.encode_texts(text), model.encode_texts(text))


def test_finetune_wraps_the_vlm_unless_told_not_to(tmp_path):
    folder = tmp_path / "vlm"
    create_scene_vlm("tiny", seed=0, image_size=32).save(folder)
    assert isinstance(initial_model(FinetuneConfig(vlm=str(folder))), AdaptedVLM)
    assert initial_model(FinetuneConfig(vlm=str(folder), spatial_grid=0)).spatial is None
    assert not isinstance(initial_model(FinetuneConfig(vlm=str(folder), spatial_grid=0, text_adapter=0)), AdaptedVLM)
    adapted().save(tmp_path / "ft")
    (tmp_path / "ft" / "config.json").write_text(
        (tmp_path / "ft" / "config.json").read_text().replace('"unused"', json.dumps(str(folder))))
    again = initial_model(FinetuneConfig(vlm=str(tmp_path / "ft")))  # continuing: not wrapped twice
    assert isinstance(again, AdaptedVLM) and not isinstance(again.base, AdaptedVLM)


def test_a_vlm_without_a_feature_map_is_a_clear_error():
    vlm = create_scene_vlm("tiny", seed=0, image_size=32)

    def no_trunk(pixels):
        raise NotImplementedError("no split")

    vlm.image_trunk = no_trunk
    with pytest.raises(ValueError, match="--spatial-grid 0"):
        adapted(vlm)
    assert adapted(vlm, grid=0).spatial is None  # the text adapter alone works

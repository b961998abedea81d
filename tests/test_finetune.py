"""Contrastive fine-tuning of the full reward model (zsrm/fullmodel/training.py)."""
import json

import numpy as np
import pytest
import torch

from zsrm.fullmodel import training as ft
from zsrm.fullmodel.training import FinetuneConfig, batch_loss, finetune, reward_logits, shift_images
from zsrm.tasks.negatives import candidate_texts
from zsrm.testing import synthetic_pairs
from zsrm.vlm.base import VisionLanguageModel
from zsrm.vlm.losses import multi_positive_contrastive_loss

A = "a yellow block on top of a red block"
B = "a red block on the left of a green block"


class FixedVLM(VisionLanguageModel):
    """Image k (frames filled with value k) embeds to ``images[k]``; a text to ``texts[text]``."""

    backend = "fixed"
    gradcam_layer = "none"

    def __init__(self, images, texts, scale=100.0):
        super().__init__()
        self.images = torch.tensor(images, dtype=torch.float32)
        self.texts = {t: torch.tensor(v, dtype=torch.float32) for t, v in texts.items()}
        self.image_size = 8
        self.logit_scale = torch.nn.Parameter(torch.tensor(float(np.log(scale))))

    def preprocess(self, images):
        return torch.as_tensor(np.asarray(images)[:, 0, 0, 0].astype(np.int64))

    def image_trunk(self, pixels):
        return pixels

    def image_head(self, features):
        return self.images[features]

    def encode_text_tokens(self, texts):
        return torch.stack([self.texts.get(t, torch.tensor([0.0, 0.0, 1.0])) for t in texts])

    def save(self, folder):
        raise NotImplementedError


def frames(values):
    return np.stack([np.full((8, 8, 3), v, np.uint8) for v in values])


def test_duplicate_captions_in_a_batch_are_positives_not_negatives():
    # Three images, two of them captioned A: each embeds exactly onto its caption.
    vlm = FixedVLM([[1, 0, 0], [1, 0, 0], [0, 1, 0]], {A: [1, 0, 0], B: [0, 1, 0]})
    loss, parts = batch_loss(vlm, frames([0, 1, 2]), [A, A, B], None, 0.0)
    # The fine-tuning loss is the shared multi-positive loss of zsrm.vlm.losses, captions as labels.
    emb = torch.tensor([[1.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    assert torch.isclose(loss, multi_positive_contrastive_loss(emb, emb, [A, A, B], 100.0), atol=1e-6)
    # Its floor is the entropy of the targets (uniform over the positives): 2 of 3 rows have two.
    assert parts["clip"] == pytest.approx(2 * np.log(2) / 3, abs=1e-4)


def test_aligned_duplicates_are_a_minimum_of_the_loss():
    # Two images captioned A sit on A's embedding, one captioned B on B's: no gradient moves
    # either duplicate away from its caption (a negative-treated duplicate would).
    img = torch.tensor([[1.0, 0, 0], [1, 0, 0], [0, 1, 0]], requires_grad=True)
    txt = torch.tensor([[1.0, 0, 0], [1, 0, 0], [0, 1, 0]], requires_grad=True)
    loss = multi_positive_contrastive_loss(img, txt, [A, A, B], 30.0)
    loss.backward()
    assert img.grad.abs().max() < 1e-6 and txt.grad.abs().max() < 1e-6
    # Off the minimum, a duplicate is pulled toward its caption: one gradient step raises its cosine.
    img2 = torch.nn.functional.normalize(torch.tensor([[1.0, 0, 0], [0.6, 0.8, 0], [0, 1, 0]]), dim=-1)
    img2.requires_grad_(True)
    multi_positive_contrastive_loss(img2, txt.detach(), [A, A, B], 30.0).backward()
    stepped = torch.nn.functional.normalize(img2.detach() - 0.01 * img2.grad, dim=-1)
    assert stepped[1, 0] > img2[1, 0]


def test_hard_negatives_skip_texts_that_hold_for_the_image():
    texts = candidate_texts(A)
    index = {t: i for i, t in enumerate(texts)}
    emb_t = torch.eye(len(texts))
    img = emb_t[[0]]
    also_true = texts[1]  # the labeler found this negative true for the image as well
    logits, target = reward_logits(img, emb_t, [A], index, [{A, also_true}])
    assert target.tolist() == [0]
    assert torch.isinf(logits[0, 1]) and logits[0, 1] < 0
    assert torch.isfinite(logits[0, [0] + list(range(2, len(texts)))]).all()
    # The hard-negative term of the loss is small for an image on its caption, large for one on a negative.
    vlm = FixedVLM([emb_t[0].tolist(), emb_t[2].tolist()], {t: emb_t[i].tolist() for t, i in index.items()})
    _, parts = batch_loss(vlm, frames([0, 1]), [A, A], [set(), set()], 1.0)
    assert parts["hard"] > 10  # the second image sits on a negative, at scale 100


def test_shift_keeps_shape_and_moves_content():
    rng = np.random.default_rng(0)
    x = np.zeros((16, 12, 12, 3), np.uint8)
    x[:, 6, 6] = 255
    y = shift_images(x, 2, rng)
    assert y.shape == x.shape and y.dtype == np.uint8
    pos = [tuple(np.argwhere(im[..., 0] == 255)[0]) for im in y]
    assert len(set(pos)) > 1 and all(abs(r - 6) <= 2 and abs(c - 6) <= 2 for r, c in pos)


@pytest.fixture(autouse=True)
def one_thread():
    # Tiny models run fastest on one thread (and do not fight other work for the cores).
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def tiny_scene_vlm():
    from zsrm.vlm import create_scene_vlm

    return create_scene_vlm("tiny", seed=0, image_size=32)


def _cfg(tmp_path, name, **kw):
    base = dict(out=str(tmp_path / name / "model"), steps=6, batch_size=16, lr=1e-3, warmup_steps=2,
                checkpoint_every=3, eval_every=3, val_fraction=0.2, val_pairs=40, seed=0)
    base.update(kw)
    return FinetuneConfig(**base)


def _weights(model):
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


def test_finetune_resumes_after_a_kill_to_the_same_weights(tmp_path, monkeypatch):
    data = synthetic_pairs(60, size=32, seed=1)
    straight = finetune(_cfg(tmp_path, "straight"), data=data, model=tiny_scene_vlm(), progress=False)

    # Kill the second run right after its first checkpoint (step 3).
    real_save = ft._save_checkpoint

    def save_then_die(folder, model, opt, step, cfg, log):
        real_save(folder, model, opt, step, cfg, log)
        raise KeyboardInterrupt

    monkeypatch.setattr(ft, "_save_checkpoint", save_then_die)
    cfg = _cfg(tmp_path, "killed")
    with pytest.raises(KeyboardInterrupt):
        finetune(cfg, data=data, model=tiny_scene_vlm(), progress=False)
    state = json.loads((tmp_path / "killed" / "model.work" / "checkpoint" / "state.json").read_text())
    assert state["step"] == 3
    assert not (tmp_path / "killed" / "model" / "model.safetensors").exists()
    monkeypatch.setattr(ft, "_save_checkpoint", real_save)
    resumed = finetune(cfg, data=data, model=tiny_scene_vlm(), progress=False)

    a, b = _weights(straight), _weights(resumed)
    assert a.keys() == b.keys()
    for k in a:
        torch.testing.assert_close(a[k], b[k], rtol=1e-5, atol=1e-6, msg=k)
    # The weights changed from the initial model, and the saved folder loads back.
    init = _weights(tiny_scene_vlm())
    assert any(not torch.equal(init[k], a[k]) for k in a)
    from zsrm.fullmodel import load_reward_backbone

    reloaded = load_reward_backbone(cfg.out)
    x = data.pair_images(np.arange(4))
    torch.testing.assert_close(reloaded.encode_images(x), resumed.encode_images(x))
    summary = json.loads((tmp_path / "killed" / "model" / "training.json").read_text())
    assert summary["validation"]["pairs"] > 0 and summary["train_pairs"] > 0


def test_resuming_with_other_settings_is_refused(tmp_path):
    data = synthetic_pairs(30, size=32, seed=2)
    finetune(_cfg(tmp_path, "a", steps=3), data=data, model=tiny_scene_vlm(), progress=False)
    with pytest.raises(ValueError, match="other settings"):
        finetune(_cfg(tmp_path, "a", steps=3, lr=5e-4), data=data, model=tiny_scene_vlm(), progress=False)
    # --fresh starts over.
    finetune(_cfg(tmp_path, "a", steps=3, lr=5e-4), data=data, model=tiny_scene_vlm(), fresh=True, progress=False)


def test_finetunes_an_open_clip_model_too(tmp_path):
    from zsrm.vlm import create_open_clip_vlm
    from zsrm.vlm.compat import import_open_clip

    open_clip = import_open_clip()
    cfg_dir = tmp_path / "configs"
    cfg_dir.mkdir()
    (cfg_dir / "zsrm-test-ft-rn.json").write_text(json.dumps({
        "embed_dim": 16, "vision_cfg": {"image_size": 32, "layers": [1, 1, 1, 1], "width": 8},
        "text_cfg": {"context_length": 77, "vocab_size": 49408, "width": 16, "heads": 2, "layers": 1}}))
    open_clip.add_model_config(cfg_dir)
    torch.manual_seed(0)
    vlm = create_open_clip_vlm("zsrm-test-ft-rn", "none")
    data = synthetic_pairs(20, size=32, seed=3)
    before = _weights(vlm)
    model = finetune(_cfg(tmp_path, "oc", steps=2, batch_size=8, checkpoint_every=2, eval_every=2), data=data,
                     model=vlm, progress=False)
    after = _weights(model)
    assert any(not torch.equal(before[k], after[k]) for k in before if "visual" in k)
    assert any(not torch.equal(before[k], after[k]) for k in before if "transformer" in k)
    from zsrm.fullmodel import load_reward_backbone

    reloaded = load_reward_backbone(str(tmp_path / "oc" / "model"))
    assert reloaded.backend == "open_clip"
    torch.testing.assert_close(reloaded.encode_texts([A]), model.encode_texts([A]))


def test_bad_settings_are_one_line_errors():
    with pytest.raises(ValueError, match="batch_size"):
        FinetuneConfig(batch_size=1)
    with pytest.raises(ValueError, match="student architecture"):
        FinetuneConfig(student=True, student_arch="huge")
    with pytest.raises(ValueError, match="lr must be > 0"):
        FinetuneConfig(lr=0.0)
    with pytest.raises(ValueError, match=">= 0"):
        FinetuneConfig(shift=-1)
    assert FinetuneConfig(out="runs/x/vlm").workdir.endswith("vlm.work")

"""The multi-positive contrastive loss (zsrm/vlm/losses.py)."""
import pytest
import torch
from torch import nn

from zsrm.vlm.losses import label_ids, multi_positive_contrastive_loss


def clip_loss(img, txt, scale):
    """CLIP's loss as the paper's reference (Radford et al. 2021): every other pair is a negative."""
    logits = scale * img @ txt.T
    target = torch.arange(len(img))
    return (nn.functional.cross_entropy(logits, target) + nn.functional.cross_entropy(logits.T, target)) / 2


def features(n, d=8, seed=0):
    g = torch.Generator().manual_seed(seed)
    return (nn.functional.normalize(torch.randn(n, d, generator=g), dim=-1),
            nn.functional.normalize(torch.randn(n, d, generator=g), dim=-1))


def test_equals_clip_loss_when_captions_are_unique():
    img, txt = features(6)
    labels = [f"caption {i}" for i in range(6)]
    for scale in (1.0, 14.3, 100.0):
        assert torch.allclose(multi_positive_contrastive_loss(img, txt, labels, scale), clip_loss(img, txt, scale),
                              atol=1e-6)


def _logit_grads(loss_fn, logits, labels):
    logits = logits.detach().clone().requires_grad_(True)
    loss_fn(logits, labels).backward()
    return logits.grad


def _mp_from_logits(logits, labels):
    # The library loss with unit features is a function of the logits: feed them through an identity.
    n = len(logits)
    eye = torch.eye(n)
    return multi_positive_contrastive_loss(eye, logits.T, labels, 1.0)


def _clip_from_logits(logits, labels):
    target = torch.arange(len(logits))
    return (nn.functional.cross_entropy(logits, target) + nn.functional.cross_entropy(logits.T, target)) / 2


def test_identical_captions_are_pulled_together_not_pushed_apart():
    # Items 0 and 1 share a caption. Read the gradient on every image-text logit.
    g = torch.Generator().manual_seed(3)
    logits = torch.randn(4, 4, generator=g)
    labels = ["a red block", "a red block", "a blue block", "a green block"]
    mp = _logit_grads(_mp_from_logits, logits, labels)
    clip = _logit_grads(_clip_from_logits, logits, labels)
    # Gradient descent raises a logit whose gradient is negative.
    assert clip[0, 1] > 0 and clip[1, 0] > 0  # CLIP's loss pushes image 0 away from its twin caption
    assert mp[0, 1] < 0 and mp[1, 0] < 0  # the multi-positive loss pulls them together
    assert mp[0, 2] > 0 and mp[2, 0] > 0  # a different caption is still a negative


def test_perfect_model_reaches_the_floor_and_duplicates_share_the_mass():
    # Image i matches its caption's text exactly; items 0 and 1 share a caption (and embedding).
    img = nn.functional.normalize(torch.eye(3)[[0, 0, 1, 2]], dim=-1)
    labels = ["a red block", "a red block", "a blue block", "a green block"]
    loss = multi_positive_contrastive_loss(img, img.clone(), labels, 100.0)
    # The soft target of rows 0 and 1 is (1/2, 1/2): the floor is its entropy, reached here.
    floor = torch.log(torch.tensor(2.0)) * 2 / 4
    assert torch.isclose(loss, floor, atol=1e-5)
    # Moving image 0 off its caption costs loss: duplicates are targets, not competitors.
    worse = img.clone()
    worse[0] = nn.functional.normalize(torch.tensor([1.0, 1.0, 0.0]), dim=0)
    assert multi_positive_contrastive_loss(worse, img.clone(), labels, 100.0) > loss + 0.1


def test_labels_may_be_ids_and_errors_are_clear():
    img, txt = features(3)
    a = multi_positive_contrastive_loss(img, txt, torch.tensor([5, 5, 7]), 10.0)
    b = multi_positive_contrastive_loss(img, txt, ["x", "x", "y"], 10.0)
    assert torch.isclose(a, b)
    with pytest.raises(ValueError, match="one label per pair"):
        multi_positive_contrastive_loss(img, txt, ["x", "y"], 10.0)
    with pytest.raises(ValueError, match=r"\(N, D\)"):
        multi_positive_contrastive_loss(img, txt[:2], ["x", "y", "z"], 10.0)

"""The student reward network (zsrm/fullmodel/student.py), trained from scratch."""
import json

import numpy as np
import pytest
import torch

from zsrm.fullmodel import load_reward_backbone
from zsrm.fullmodel.student import StudentConfig, StudentRewardNet, is_student_folder
from zsrm.testing import TaskTextVLM, synthetic_pairs
from zsrm.fullmodel.training import FinetuneConfig, evaluate_pairs, finetune
from zsrm.rewards.binarised import ZSRMReward


def small_student(text_vlm=None, spec="testing"):
    torch.manual_seed(0)
    return StudentRewardNet(StudentConfig(image_size=32, widths=(8, 16, 16, 32), embed_dim=32, text_hidden=64),
                            text_vlm or TaskTextVLM(), spec)


@pytest.fixture
def one_thread():
    # Tiny convolutions run fastest on one thread (and do not fight other work for the cores).
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def test_student_learns_spatial_relations_from_scratch(tmp_path, one_thread):
    data = synthetic_pairs(1000, size=32, seed=0)
    train, val = data.split(0.2, seed=0)
    net = small_student()
    before = evaluate_pairs(net, val, 600)["argmax_accuracy"]
    cfg = FinetuneConfig(out=str(tmp_path / "student"), student=True, steps=300, batch_size=48, lr=3e-3,
                         warmup_steps=10, eval_every=300, checkpoint_every=300, val_fraction=0.2, shift=1)
    finetune(cfg, data=data, model=net, progress=False)
    after = evaluate_pairs(net, val, 600)
    # Chance is about 1 in 9 candidates; the captions are the labeler's on true coordinates.
    assert before < 0.2
    assert after["argmax_accuracy"] > 0.5, after
    assert after["argmax_accuracy_by_relation"]["on_top_of"] > 0.6
    # As a reward: a stacked frame gets 1 for its stacking caption more often than not.
    reward = ZSRMReward(net)
    rows = [i for i in range(val.n_pairs) if "on top of" in val.pair_texts([i])[0]][:20]
    hits = [reward({"front": val.pair_images([i])}, val.pair_texts([i])[0])[0] for i in rows]
    assert np.mean(hits) > 0.5


def test_student_text_side_is_frozen_and_embedded_once():
    vlm = TaskTextVLM()
    net = small_student(vlm)
    texts = ["a red block on the left of a green block", "a green block below a red block"]
    net.encode_texts(texts)
    calls = vlm.text_calls
    for _ in range(3):
        net.encode_texts(texts)
    assert vlm.text_calls == calls  # the sentences and their object phrases came from the cache
    assert all(not p.requires_grad for p in vlm.parameters())
    assert not any(n.startswith("text_vlm") for n, _ in net.named_parameters())


def test_student_saves_and_loads_with_its_text_vlm_folder(tmp_path):
    from zsrm.vlm import create_scene_vlm

    text_dir = tmp_path / "models" / "vlm"
    create_scene_vlm("tiny", seed=0, image_size=32).save(text_dir)
    text_vlm = load_reward_backbone(str(text_dir))
    net = small_student(text_vlm, spec=str(text_dir))
    net.save(tmp_path / "models" / "student")
    cfg = json.loads((tmp_path / "models" / "student" / "config.json").read_text())
    assert cfg["text_vlm"] == "../vlm"  # relative: the two folders move together
    assert is_student_folder(tmp_path / "models" / "student") and not is_student_folder(text_dir)
    moved = tmp_path / "elsewhere"
    (tmp_path / "models").rename(moved)
    loaded = load_reward_backbone(str(moved / "student"))
    assert isinstance(loaded, StudentRewardNet)
    x = np.random.default_rng(0).integers(0, 255, (3, 32, 32, 3), dtype=np.uint8)
    torch.testing.assert_close(loaded.encode_images(x), net.encode_images(x))
    text = ["a red block on top of a blue block"]
    torch.testing.assert_close(loaded.encode_texts(text), net.encode_texts(text))


def test_missing_text_vlm_is_a_clear_error(tmp_path):
    from zsrm.vlm import create_scene_vlm

    create_scene_vlm("tiny", seed=0, image_size=32).save(tmp_path / "vlm")
    small_student(load_reward_backbone(str(tmp_path / "vlm")), spec=str(tmp_path / "vlm")).save(tmp_path / "student")
    import shutil

    shutil.rmtree(tmp_path / "vlm")
    with pytest.raises(FileNotFoundError, match="embeds texts with the VLM"):
        load_reward_backbone(str(tmp_path / "student"))

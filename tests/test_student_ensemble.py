"""Several students as one reward model (zsrm/fullmodel/ensemble.py): its image-text scores are
the mean of its members', it loads by its folder like any reward model, its members are found
relative to it, and a missing or wrong member list is one clear line."""
import json
import shutil

import numpy as np
import pytest
import torch

from zsrm.common.files import ZsrmFileError
from zsrm.fullmodel import StudentEnsemble, load_reward_backbone, write_ensemble
from zsrm.fullmodel.student import StudentConfig, StudentRewardNet
from zsrm.rewards.binarised import ZSRMReward, decide

TEXTS = ["a red block on the left of a blue block", "a blue block on the left of a red block",
         "a red block on top of a blue block"]
GOAL = "a red block on the left of a green block"


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    """``models/``: a tiny stand-in VLM (the students' text tower) and three students of seeds 0-2."""
    from zsrm.vlm import create_scene_vlm

    root = tmp_path_factory.mktemp("ens") / "models"
    create_scene_vlm("tiny", seed=0, image_size=32).save(root / "vlm")
    text_vlm = load_reward_backbone(str(root / "vlm"))
    for seed, name in enumerate(("student", "student-seed1", "student-seed2")):
        torch.manual_seed(seed)
        StudentRewardNet(StudentConfig(image_size=32, widths=(8, 8, 8, 8), embed_dim=16, text_hidden=16), text_vlm,
                         str(root / "vlm")).save(root / name)
    return root


def images(n=4, seed=0):
    return np.random.default_rng(seed).integers(0, 255, (n, 32, 32, 3), dtype=np.uint8)


def test_its_scores_are_the_mean_of_its_members_scores(models, tmp_path):
    root = tmp_path / "models"
    shutil.copytree(models, root)
    names = ["student", "student-seed1", "student-seed2"]
    write_ensemble(root / "students", [root / n for n in names])
    ensemble = load_reward_backbone(str(root / "students"))
    assert isinstance(ensemble, StudentEnsemble) and ensemble.backend == "zsrm-ensemble"
    members = [load_reward_backbone(str(root / n)) for n in names]
    x = images()
    each = [m.similarity(x, TEXTS) for m in members]
    assert not torch.allclose(each[0], each[1], atol=1e-3)  # the seeds differ: the mean is not any one of them
    torch.testing.assert_close(ensemble.similarity(x, TEXTS), torch.stack(each).mean(0))
    # the binarised reward reads the mean: its cosines, argmax and margin are those of the mean
    mean = np.mean([ZSRMReward(m).similarities(x, GOAL) for m in members], axis=0)
    np.testing.assert_allclose(ZSRMReward(ensemble).similarities(x, GOAL), mean, atol=1e-5)
    for output in ("binary", "raw", "margin"):
        np.testing.assert_allclose(ZSRMReward(ensemble, output=output)({"front": x}, GOAL), decide(mean)[output],
                                   atol=1e-5)
    # unit embeddings either way (the base reward's "dot" reads the mean cosine too)
    torch.testing.assert_close(ensemble.encode_images(x, normalize=False).norm(dim=-1), torch.ones(len(x)))
    # the students reading texts through one VLM share one copy of it
    assert ensemble.members[0].text_vlm is ensemble.members[2].text_vlm


def test_the_members_are_found_relative_to_the_ensemble_so_the_folder_moves(models, tmp_path):
    root = tmp_path / "chain"
    shutil.copytree(models, root)
    write_ensemble(root / "students", [root / "student", root / "student-seed1"])
    assert json.loads((root / "students" / "config.json").read_text())["members"] == ["../student",
                                                                                      "../student-seed1"]
    x = images()
    before = load_reward_backbone(str(root / "students")).similarity(x, TEXTS)
    moved = tmp_path / "elsewhere"
    root.rename(moved)
    torch.testing.assert_close(load_reward_backbone(str(moved / "students")).similarity(x, TEXTS), before)


def test_a_saved_ensemble_keeps_its_members_weights(models, tmp_path):
    """What the corrected reward does with a model it trained: save it, and load it back."""
    ensemble = StudentEnsemble([load_reward_backbone(str(models / n)) for n in ("student", "student-seed1")])
    ensemble.save(tmp_path / "copy")
    x = images()
    torch.testing.assert_close(load_reward_backbone(str(tmp_path / "copy")).similarity(x, TEXTS),
                               ensemble.similarity(x, TEXTS))


def test_a_missing_member_is_one_clear_line(models, tmp_path):
    root = tmp_path / "models"
    shutil.copytree(models, root)
    write_ensemble(root / "students", [root / "student", root / "student-seed1"])
    shutil.rmtree(root / "student-seed1")
    with pytest.raises(FileNotFoundError) as err:
        load_reward_backbone(str(root / "students"))
    line = str(err.value)
    assert "\n" not in line and "lists the member '../student-seed1'" in line and "holds no saved model" in line
    assert "zsrm finetune --student --seed N" in line
    with pytest.raises(FileNotFoundError, match="holds no saved model"):  # nor is one written
        write_ensemble(root / "other", [root / "student", root / "student-seed1"])
    assert not (root / "other" / "config.json").exists()


@pytest.mark.parametrize("members, words", [([], "lists no members"),
                                            (["../student", "../student"], "lists a member twice"),
                                            (["../students"], "is itself an ensemble")])
def test_a_wrong_member_list_is_refused(models, tmp_path, members, words):
    root = tmp_path / "models"
    shutil.copytree(models, root)
    write_ensemble(root / "students", [root / "student"])
    (root / "bad").mkdir()
    (root / "bad" / "config.json").write_text(json.dumps({"kind": "zsrm-ensemble", "members": members}))
    with pytest.raises(ZsrmFileError, match=words):
        load_reward_backbone(str(root / "bad"))


def test_an_ensemble_has_no_one_image_tower_for_grad_cam(models):
    ensemble = StudentEnsemble([load_reward_backbone(str(models / "student"))])
    with pytest.raises(NotImplementedError, match="no one image tower"):
        ensemble.image_trunk(torch.zeros(1, 3, 32, 32))

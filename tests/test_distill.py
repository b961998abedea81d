"""The multi-task policy (paper 2.3, 3.3, Table 2): rollout data without blue, the nearest
primitive code, the three policies and the grounded variant, and a tiny end to end run of the
four commands."""
import json
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

from zsrm.cli import build_parser
from zsrm.cli.options import from_namespace
from zsrm.common.files import ZsrmFileError
from zsrm.pipeline.distill import Distill, EvalMultitask, MultitaskRollouts, train_goals
from zsrm.policy.models import (SHAPE_GREY, DistilledPolicy, PolicyConfig, embed_goals, grey_frames, load_policy,
                                resnet18, save_policy, shape_frames)
from zsrm.policy.rollouts import RolloutData, keep_task_policies, policy_folder, train_task_index
from zsrm.policy.training import DistillConfig, centres_text, load_distilled, random_crops
from zsrm.rl import TrainConfig, train
from zsrm.rl.envs import make_vec
from zsrm.rl.features import policy_view
from zsrm.rl.policy import PolicyBundle
from zsrm.rl.sweep import trial_grid
from zsrm.tasks.catalogue import TEST_TASKS, TRAIN_TASKS
from zsrm.tasks.language import parse_goal
from zsrm.testing import hostile as H
from zsrm.vlm import load_vlm
from zsrm.vlm.scene import SceneConfig

TINY = dict(steps=256, n_envs=2, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=2, eval_every=128,
            checkpoint_every=128, keypoints=4)
# One stack and one place-right task (TRAIN_TASKS order: on top of, left of, right of x 6 pairs).
GOALS = [TRAIN_TASKS[0].text, TRAIN_TASKS[12].text]
SMALL_SCENE = SceneConfig(widths=(8, 8, 8), groups=4)
POLICIES = ("language", "primitive", "none", "grounded")


def blue_pixels(frames: np.ndarray) -> np.ndarray:
    """Pixels of the blue block's colour (rgba 0.12 0.25 0.9 as the scene renders it lit):
    strongly blue, well above red and green (the grey-blue walls are not)."""
    f = frames.astype(np.int16)
    r, g, b = f[..., 0], f[..., 1], f[..., 2]
    return (b > 100) & (b - r > 60) & (b - g > 40)


def run_benchmark(name: str, monkeypatch, *args: str, folder: str = "benchmarks") -> None:
    """Run FOLDER/NAME (benchmarks/ or probes/) as python would, with ARGS."""
    import runpy
    import sys

    script = Path(__file__).parent.parent / folder / name
    monkeypatch.setattr(sys, "argv", [str(script), *args])
    monkeypatch.syspath_prepend(str(script.parent))  # as python puts the script's folder first
    runpy.run_path(str(script), run_name="__main__")


def run_probe(name: str, monkeypatch, *args: str) -> None:
    """Run probes/NAME as python would, with ARGS."""
    run_benchmark(name, monkeypatch, *args, folder="probes")


@pytest.fixture(scope="module")
def pipeline(tmp_path_factory):
    """Two tiny zsrm-trained task policies, 2 rollouts each, 1 epoch of distillation, a tiny table."""
    root = tmp_path_factory.mktemp("multitask")
    for goal in GOALS:
        train(TrainConfig(goal=goal, reward="zsrm", seed=0, **TINY), policy_folder(root / "policies", goal).parent,
              progress=False)
    assert MultitaskRollouts(tasks=tuple(GOALS), policies=str(root / "policies"), episodes=2, envs=2,
                             out=str(root / "rollouts")).run() == 0
    assert Distill(epochs=1, threads=1, policies=POLICIES, data=str(root / "rollouts"),
                   out=str(root / "distill")).run() == 0
    assert EvalMultitask(policies=str(root / "distill"), data=str(root / "rollouts"), seeds=2, tasks=2,
                         threads=1, out=str(root / "table2.json")).run() == 0
    return root


def test_blue_never_appears_in_the_distillation_data(pipeline):
    data = RolloutData(pipeline / "rollouts")
    arrays = data.load()
    texts = list(data.goals) + [str(g) for g in arrays["goal"]] + list(data.manifest["config"]["tasks"])
    assert texts and not any("blue" in t.lower() for t in texts)
    assert sorted(set(arrays["task"].tolist())) == [0, 12] and len(arrays["frames"]) == len(arrays["actions"])
    assert arrays["frames"].shape[1:] == (64, 64, 3) and arrays["frames"].dtype == np.uint8
    assert not blue_pixels(arrays["frames"]).any()
    # The detector does find the blue block where one is shown: a test task's first frame.
    venv = make_vec(TrainConfig(goal=TEST_TASKS[0].text), 1, 0)
    assert blue_pixels(venv.reset()["front"]).sum() > 10
    venv.close()


def test_no_blue_task_word_or_block_reaches_what_distill_trains_on(pipeline, tmp_path):
    """Through the functions zsrm multitask-rollouts and zsrm distill call: the objects each task's
    scenes held, the goals, their words and embeddings, and the frames the policies are fitted to."""
    from zsrm.data.shards import MANIFEST
    from zsrm.policy.training import cloning_data
    from zsrm.tasks.catalogue import TEST_COLOUR, TRAIN_COLOURS

    data = RolloutData(pipeline / "rollouts")
    assert [info["objects"] for info in data.infos] == [sorted(parse_goal(g).objects) for g in GOALS]
    assert all(set(info["objects"]) <= set(TRAIN_COLOURS) for info in data.infos)
    vlm = load_vlm("scene")
    cloning = cloning_data(data, vlm, ["language", "grounded"])
    assert cloning.goals == GOALS and all(parse_goal(g) in TRAIN_TASKS for g in cloning.goals)
    assert TEST_COLOUR not in {word for goal in cloning.goals for word in goal.split()}
    assert torch.equal(cloning.embeddings["language"], embed_goals(vlm, GOALS))  # these goals' and no other's
    assert sorted(set(cloning.codes.tolist())) == [0, 1] and len(cloning.images) == len(cloning.actions) > 0
    assert not blue_pixels(cloning.images.permute(0, 2, 3, 1).numpy()).any()
    # Each distilled policy keeps the goals it was fitted to: the training goals, no blue one.
    _, policies = load_distilled(pipeline / "distill")
    assert all(list(policy.cfg.goals) == GOALS for policy in policies.values())
    # Rollouts whose manifest names a test task are refused before a frame is read.
    shutil.copytree(pipeline / "rollouts", tmp_path / "rollouts")
    manifest = json.loads((tmp_path / "rollouts" / MANIFEST).read_text())
    manifest["shards"]["shard_00000"]["goal"] = TEST_TASKS[0].text
    (tmp_path / "rollouts" / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(ValueError, match="not one of the 18 training tasks"):
        Distill(epochs=1, threads=1, policies=("none",), data=str(tmp_path / "rollouts"),
                out=str(tmp_path / "distill")).run()


def test_the_collection_scenes_show_the_tasks_two_blocks_only():
    for goal in GOALS:
        venv = make_vec(TrainConfig(goal=goal), 1, 0)
        env = venv.envs[0].unwrapped
        assert set(env.objects) == set(parse_goal(goal).objects) and "blue" not in env.objects
        assert not blue_pixels(venv.reset()["front"]).any()
        venv.close()


def test_test_tasks_are_refused_as_distillation_data():
    with pytest.raises(ValueError, match="not one of the 18 training tasks"):
        train_task_index(TEST_TASKS[0].text)
    with pytest.raises(ValueError):
        train_goals(("a blue block on top of a red block",))
    assert train_goals(("put the red block onto the green one",)) == [TRAIN_TASKS[0].text]


def test_nearest_primitive_code_keeps_the_relation():
    from zsrm.vlm import load_vlm

    vlm = load_vlm("scene")
    goals = tuple(t.text for t in TRAIN_TASKS)
    cfg = PolicyConfig(conditioning="primitive", tower="scene", image_size=64, action_dim=3, text_dim=384,
                       goals=goals, scene=SMALL_SCENE, hidden=8, keypoints=2)
    policy = DistilledPolicy(cfg)
    policy.goal_embeddings.copy_(embed_goals(vlm, goals))
    tests = [t.text for t in TEST_TASKS]
    nearest = [TRAIN_TASKS[int(c)] for c in policy.nearest_codes(embed_goals(vlm, tests))]
    # Every test goal maps to a training task of its own relation that shares its training colour.
    for test, train_task in zip(TEST_TASKS, nearest):
        assert train_task.relation == test.relation
        assert set(test.objects) - {"blue"} <= set(train_task.objects), (test.text, train_task.text)
    # The paper's example: "a blue block on the right of a yellow block" maps to a right-of task with
    # yellow (here "a yellow block on the right of a green block"; the paper's CLIP gave red right of yellow).
    mapped = nearest[tests.index("a blue block on the right of a yellow block")]
    assert mapped.relation == "right_of" and "yellow" in mapped.objects
    # Training goals map to themselves.
    assert policy.nearest_codes(policy.goal_embeddings).tolist() == list(range(18))


@pytest.mark.parametrize("tower", ["scene", "resnet18"])
@pytest.mark.parametrize("conditioning", ["language", "primitive", "none"])
def test_the_three_policies_give_one_action_per_frame(tmp_path, tower, conditioning):
    cfg = PolicyConfig(conditioning=conditioning, tower=tower, image_size=64, action_dim=3, text_dim=6,
                       goals=("a red block on top of a green block", "a green block on top of a red block"),
                       scene=SMALL_SCENE if tower == "scene" else None, hidden=16, keypoints=4)
    policy = DistilledPolicy(cfg).eval()
    frames = np.random.default_rng(0).integers(0, 255, (5, 64, 64, 3), dtype=np.uint8)
    embeddings = torch.randn(5, 6)
    actions = policy.act(frames, embeddings)
    assert tuple(actions.shape) == (5, 3) and actions.abs().max() <= 1
    save_policy(policy, tmp_path)
    assert torch.equal(load_policy(tmp_path).act(frames, embeddings), actions)
    assert json.loads((tmp_path / "config.json").read_text())["config"]["conditioning"] == conditioning


@pytest.mark.parametrize("view", ["grey", "shape"])
def test_the_papers_policies_can_read_grey_or_shape_frames(tmp_path, view):
    """--image-view: the image tower reads what the view keeps, so frames that differ only in what
    it drops give the same action."""
    cfg = PolicyConfig(conditioning="none", tower="scene", image_size=64, action_dim=3, text_dim=6,
                       goals=("a red block on top of a green block",), scene=SMALL_SCENE, hidden=16, keypoints=4,
                       keypoint_view=view)
    policy = DistilledPolicy(cfg).eval()
    frames = np.random.default_rng(0).integers(0, 255, (2, 64, 64, 3), dtype=np.uint8)
    if view == "grey":  # the same luma in another colour: (r, g, b) -> its grey level in all three
        other = grey_frames(torch.as_tensor(frames).permute(0, 3, 1, 2)).round().byte().permute(0, 2, 3, 1).numpy()
    else:  # every saturated pixel another saturated colour
        other = frames.copy()
        coloured = shape_frames(torch.as_tensor(frames).permute(0, 3, 1, 2))[:, 0] == SHAPE_GREY
        other[coloured.numpy()] = (20, 40, 230)
    colour = DistilledPolicy(PolicyConfig(**{**cfg.__dict__, "keypoint_view": "colour"})).eval()
    colour.load_state_dict(policy.state_dict())
    moved = (colour.act(frames, None) - colour.act(other, None)).abs().max()
    same = (policy.act(frames, None) - policy.act(other, None)).abs().max()
    # Shape frames are equal; grey ones up to the byte rounding of the luma (half a grey level).
    assert same == 0 if view == "shape" else same < 0.05 * moved
    save_policy(policy, tmp_path)
    assert load_policy(tmp_path).cfg.keypoint_view == view
    with pytest.raises(ValueError, match="image view"):
        DistillConfig(image_view="none")
    # The cpu schedule reads grey frames (its scene tower's features are colour-bound), the paper's colour.
    assert DistillConfig().image_view == "grey" and DistillConfig(schedule="paper").image_view == "colour"


@pytest.mark.parametrize("view", ["colour", "grey", "shape", "none"])
def test_the_grounded_policy_gives_one_action_per_frame_and_keeps_the_vlm_frozen(tmp_path, view):
    vlm = load_vlm("scene")
    goals = ("a red block on top of a green block", "a green block on the left of a red block")
    embeddings = embed_goals(vlm, goals, "grounded")
    cfg = PolicyConfig(conditioning="grounded", tower="scene", image_size=64, action_dim=3,
                       text_dim=embeddings.shape[1], goals=goals, scene=vlm.config, hidden=16, keypoints=4,
                       text_embedding="grounded", keypoint_view=view)
    policy = DistilledPolicy(cfg)
    policy.load_scene_vlm(vlm)
    trainable = {n for n, p in policy.named_parameters() if p.requires_grad}
    assert trainable and not any(n.startswith(("encoder.net.0.", "grounding_proj.")) for n in trainable)
    assert torch.equal(policy.grounding_proj.weight, vlm.visual.proj.weight)
    frames = np.random.default_rng(0).integers(0, 255, (5, 64, 64, 3), dtype=np.uint8)
    actions = policy.eval().act(frames, embeddings[[0, 1, 0, 1, 0]])
    assert tuple(actions.shape) == (5, 3) and actions.abs().max() <= 1
    # Training reaches the fc layers and the keypoint head, never the VLM's trunk or head.
    before = policy.encoder.net[0].state_dict()["0.0.weight"].clone()
    loss = policy.train()(torch.as_tensor(frames).permute(0, 3, 1, 2), embeddings[[0, 1, 0, 1, 0]]).square().sum()
    loss.backward()
    assert policy.encoder.net[0][0][0].weight.grad is None and policy.head[0].weight.grad is not None
    # The keypoint head learns (with shapes, its own trunk copy too); with view none there is none.
    if view in ("none", "shape"):
        assert len(policy.encoder.net) == 1 and not any(n.startswith("encoder.net.1.") for n in policy.state_dict())
    else:
        assert policy.encoder.net[1][0].weight.grad is not None
    if view == "shape":
        assert policy.shape_encoder.net[0][0][0].weight.grad is not None
        assert torch.equal(policy.shape_encoder.net[0].state_dict()["0.0.weight"], before)  # started from the VLM
    else:
        assert not hasattr(policy, "shape_encoder")
    assert torch.equal(policy.encoder.net[0].state_dict()["0.0.weight"], before)
    save_policy(policy.eval(), tmp_path)
    assert torch.equal(load_policy(tmp_path).act(frames, embeddings[[0, 1, 0, 1, 0]]), actions)
    with pytest.raises(ValueError, match="grounded"):
        PolicyConfig(conditioning="grounded", tower="resnet18", image_size=64, action_dim=3, text_dim=8,
                     goals=goals, text_embedding="grounded")
    with pytest.raises(ValueError, match="only the grounded"):
        PolicyConfig(conditioning="language", tower="scene", image_size=64, action_dim=3, text_dim=8,
                     goals=goals, keypoint_view="none")


def test_centred_goal_embeddings_keep_the_geometry_at_the_scale_of_one_hot_codes(tmp_path):
    cfg = PolicyConfig(conditioning="language", tower="scene", image_size=64, action_dim=3, text_dim=8,
                       goals=tuple(GOALS + ["a green block on top of a red block"]), scene=SMALL_SCENE, hidden=16,
                       keypoints=4, centre_text=True)
    policy = DistilledPolicy(cfg)
    raw = 1.0 + 0.01 * torch.randn(3, 8, generator=torch.Generator().manual_seed(0))  # cosines ~0.99
    policy.goal_embeddings.copy_(raw)
    centred = policy.centred(raw)
    assert torch.allclose(centred.mean(dim=0), torch.zeros(8), atol=1e-5)
    assert torch.isclose(centred.pow(2).sum(dim=1).mean(), torch.tensor(1.0))
    pairs = ~torch.eye(3, dtype=torch.bool)
    ratio = torch.cdist(centred, centred)[pairs] / torch.cdist(raw, raw)[pairs]
    assert torch.allclose(ratio, ratio[0])  # one scale: distances keep their proportions
    save_policy(policy, tmp_path / "p")
    again = load_policy(tmp_path / "p")
    assert again.cfg.centre_text and torch.allclose(again(torch.zeros(2, 3, 64, 64, dtype=torch.uint8), raw[:2]),
                                                    policy(torch.zeros(2, 3, 64, 64, dtype=torch.uint8), raw[:2]))
    with pytest.raises(ValueError, match="only the language policy"):
        PolicyConfig(**{**vars(cfg), "conditioning": "primitive"})


def test_span_projection_keeps_training_goals_and_drops_what_they_do_not_span():
    goals = tuple(GOALS + ["a green block on top of a red block"])
    cfg = PolicyConfig(conditioning="language", tower="scene", image_size=64, action_dim=3, text_dim=8,
                       goals=goals, scene=SMALL_SCENE, hidden=16, keypoints=4, text_span=True)
    policy = DistilledPolicy(cfg)
    train = torch.randn(3, 8, generator=torch.Generator().manual_seed(0))
    policy.goal_embeddings.copy_(train)
    assert torch.allclose(policy.in_goal_span(train), train, atol=1e-5)
    # A goal off the training goals' (affine, 2-d) span: its projection is the point of the span it
    # is nearest to, and the policy acts on it as on that point.
    mean, along = train.mean(dim=0), 0.3 * (train[1] - train[0]) - 0.2 * (train[2] - train[0])
    off = torch.linalg.svd((train - mean), full_matrices=False)[2][2:]  # orthonormal, and orthogonal to the span
    goal = mean + along + off[:3].sum(dim=0)
    assert torch.allclose(policy.in_goal_span(goal[None]), (mean + along)[None], atol=1e-5)
    frames = torch.zeros(1, 64, 64, 3, dtype=torch.uint8)
    assert torch.allclose(policy.act(frames, goal[None]), policy.act(frames, (mean + along)[None]), atol=1e-6)
    plain = DistilledPolicy(PolicyConfig(**{**vars(cfg), "text_span": False}))
    plain.load_state_dict(policy.state_dict())
    assert torch.allclose(plain.act(frames, train[1:2]), policy.act(frames, train[1:2]), atol=1e-6)
    assert not torch.allclose(plain.act(frames, goal[None]), policy.act(frames, goal[None]), atol=1e-6)
    with pytest.raises(ValueError, match="only the language policy"):
        PolicyConfig(**{**vars(cfg), "conditioning": "primitive"})


def test_distill_refuses_a_grounded_policy_it_cannot_build():
    for bad in ({"tower": "resnet18"}, {"pretrained": False}, {"keypoint_view": "sepia"}):
        with pytest.raises(ValueError, match="grounded|keypoint view"):
            DistillConfig(policies=("grounded",), **bad)
    with pytest.raises(ValueError, match="text-embedding"):
        DistillConfig(text_embedding="grounded")


def test_grounded_goal_embeddings_contrast_the_goals_own_two_objects():
    vlm = load_vlm("scene")
    e = vlm.config.embed_dim
    red_on_blue, blue_on_red, red_left_of_blue = embed_goals(
        vlm, ["a red block on top of a blue block", "a blue block on top of a red block",
              "a red block on the left of a blue block"], "grounded")
    assert red_on_blue.shape == (2 * e + vlm.config.text_dim,)
    # Each object's target is its phrase minus the other's: swapping the objects swaps (and
    # negates) them; the relation's words are the same.
    assert torch.allclose(red_on_blue[:e], -red_on_blue[e:2 * e])
    assert torch.allclose(red_on_blue[:e], blue_on_red[e:2 * e])
    assert torch.equal(red_on_blue[2 * e:], blue_on_red[2 * e:])
    # Another relation changes only the relation's words.
    assert torch.equal(red_on_blue[:2 * e], red_left_of_blue[:2 * e])
    assert not torch.allclose(red_on_blue[2 * e:], red_left_of_blue[2 * e:])
    with pytest.raises(ValueError, match="2 objects"):
        embed_goals(vlm, ["a red block between a green block and a yellow block"], "grounded")


def test_grounded_features_find_a_colour_never_distilled_on():
    """The grounded policy's Grad-CAM centroids, on rendered test-task scenes, land on the blue
    block as on the training colours (the blue block's pixels give where it is)."""
    from zsrm.grounding.gradcam import head_gradcam
    from zsrm.policy.models import map_centroids

    vlm = load_vlm("scene")
    e = vlm.config.embed_dim
    goal = "a blue block on the left of a red block"
    venv = make_vec(TrainConfig(goal=goal, image_size=64), 4, 7, "seen")
    frames = venv.reset()["front"]
    venv.close()
    target = embed_goals(vlm, [goal], "grounded")[:, :2 * e].view(1, 2, e).expand(len(frames), 2, e)
    with torch.no_grad():
        feats = vlm.image_trunk(vlm.preprocess(frames))
    maps, scores = head_gradcam(vlm.image_head, feats, target)
    centroid = (map_centroids(maps)[:, 0].numpy() + 1) / 2 * 63  # the blue block's, in pixels
    for i, frame in enumerate(frames):
        ys, xs = np.nonzero(blue_pixels(frame[None])[0])
        assert abs(centroid[i, 0] - xs.mean()) < 4 and abs(centroid[i, 1] - ys.mean()) < 4
    assert (scores[:, 0] > 0).all()


def test_random_crops_keep_the_size():
    images = torch.randint(0, 255, (4, 3, 64, 64), dtype=torch.uint8)
    out = random_crops(images, torch.Generator().manual_seed(0))
    assert out.shape == images.shape and out.dtype == torch.uint8


def test_resnet18_imagenet_weights_offline_is_one_clear_line():
    hub = Path(torch.hub.get_dir()) / "checkpoints" / "resnet18-f37072fd.pth"
    if hub.is_file():
        pytest.skip("ResNet18's ImageNet weights are cached on this machine")
    with pytest.raises(ValueError, match="--tower scene"):
        resnet18(pretrained=True)


def test_finished_task_policies_are_kept_and_roll_out_from_there(pipeline, tmp_path):
    unfinished = policy_folder(pipeline / "policies", TRAIN_TASKS[1].text)
    shutil.copytree(policy_folder(pipeline / "policies", GOALS[0]), unfinished)  # a run without summary.json
    trials = trial_grid([*GOALS, TRAIN_TASKS[1].text], ["zsrm"], [0], TINY)
    stale = trial_grid(GOALS, ["zsrm"], [0], {**TINY, "steps": 512})  # finished, but with other settings
    try:
        assert keep_task_policies(pipeline / "policies", tmp_path / "stale", stale) == []
        kept = keep_task_policies(pipeline / "policies", tmp_path / "kept", trials)
    finally:
        shutil.rmtree(unfinished.parent)
    assert kept == [policy_folder(tmp_path / "kept", g) for g in GOALS]
    for goal in GOALS:
        src = policy_folder(pipeline / "policies", goal)
        assert (policy_folder(tmp_path / "kept", goal) / "model.safetensors").read_bytes() == \
            (src / "model.safetensors").read_bytes()
    assert not policy_folder(tmp_path / "kept", TRAIN_TASKS[1].text).exists()
    assert not (tmp_path / "stale").exists()
    # Kept policies stay kept (and are not copied again) once their run folders are gone.
    assert keep_task_policies(tmp_path / "gone", tmp_path / "kept", trials) == kept
    # The rollouts read the kept folder as they read the run folders.
    assert MultitaskRollouts(tasks=(GOALS[0],), policies=str(tmp_path / "kept"), episodes=1, envs=1,
                             out=str(tmp_path / "rollouts")).run() == 0
    assert RolloutData(tmp_path / "rollouts").goals == [GOALS[0]]
    # The same command gives the same data (the policies sample their actions from a seeded generator).
    torch.manual_seed(123)
    assert MultitaskRollouts(tasks=(GOALS[0],), policies=str(tmp_path / "kept"), episodes=1, envs=1,
                             out=str(tmp_path / "again")).run() == 0
    first, again = RolloutData(tmp_path / "rollouts").load(), RolloutData(tmp_path / "again").load()
    assert all(np.array_equal(first[k], again[k]) for k in ("frames", "actions", "task"))


def test_tiny_end_to_end_writes_table2(pipeline):
    table = json.loads((pipeline / "table2.json").read_text())
    for policy in POLICIES:
        for spread in ("seen", "unseen"):
            for split in ("train", "test"):
                cell = table[policy][spread][split]
                assert 0 <= cell["mean"] <= 100 and cell["se"] >= 0 and cell["episodes"] == 4
    assert table["schedule"] == "cpu" and table["tower"] == "scene" and table["image_view"] == "grey"
    assert load_policy(pipeline / "distill" / "language").cfg.keypoint_view == "grey"
    assert "reads grey frames" in (pipeline / "table2.md").read_text()
    assert table["oracle_task_policies"]["episodes"] == 4 and 0 <= table["oracle_task_policies"]["mean"] <= 100
    assert set(table["meta"]["primitive_mapping_test"].values()) <= set(GOALS)
    assert table["meta"]["distill_seed"] == 0
    md = (pipeline / "table2.md").read_text()
    assert "Language Cond." in md and "Primitive Code Cond." in md and "No Conditioning" in md
    assert "Grounded Language Cond. (zsrm)" in md
    assert (pipeline / "table2.png").read_bytes()[:4] == b"\x89PNG"
    summary = json.loads((pipeline / "distill" / "distill.json").read_text())
    assert summary["epochs"] == 1 and summary["goals"] == GOALS
    # A second collection and a second distill find their work finished and leave it as it is.
    shard = pipeline / "rollouts" / "shard_00000.npz"
    shard_mtime = shard.stat().st_mtime_ns
    assert MultitaskRollouts(tasks=tuple(GOALS), policies=str(pipeline / "policies"), episodes=2, envs=2,
                             out=str(pipeline / "rollouts")).run() == 0
    assert shard.stat().st_mtime_ns == shard_mtime
    weights = pipeline / "distill" / "language" / "model.safetensors"
    mtime = weights.stat().st_mtime_ns
    assert Distill(epochs=1, threads=1, policies=POLICIES, data=str(pipeline / "rollouts"),
                   out=str(pipeline / "distill")).run() == 0
    assert weights.stat().st_mtime_ns == mtime


def test_a_finished_distillation_goes_on_to_more_epochs_as_if_asked_at_the_start(pipeline, tmp_path):
    shutil.copytree(pipeline / "distill" / "none", tmp_path / "longer" / "none")
    for out in ("longer", "fresh"):
        assert Distill(epochs=2, threads=1, policies=("none",), data=str(pipeline / "rollouts"),
                       out=str(tmp_path / out)).run() == 0
    longer, fresh = (load_policy(tmp_path / out / "none") for out in ("longer", "fresh"))
    log = json.loads((tmp_path / "longer" / "none" / "config.json").read_text())["training"]["log"]
    assert [e["epoch"] for e in log] == [1, 2]
    assert all(torch.allclose(a, b, atol=1e-6) for a, b in zip(longer.state_dict().values(),
                                                                fresh.state_dict().values()))
    with pytest.raises(ValueError, match="more than --epochs 1"):
        Distill(epochs=1, threads=1, policies=("none",), data=str(pipeline / "rollouts"),
                out=str(tmp_path / "longer")).run()


def test_the_table_says_how_the_language_policy_read_its_goal_embeddings(pipeline, tmp_path):
    # The cpu schedule centres them (the fixture's policies were distilled with its defaults).
    assert load_policy(pipeline / "distill" / "language").cfg.centre_text
    assert json.loads((pipeline / "distill" / "distill.json").read_text())["centre_text"] is True
    assert json.loads((pipeline / "table2.json").read_text())["language_text"] == "centred"
    assert "goal embeddings centred and scaled" in (pipeline / "table2.md").read_text()
    assert Distill(epochs=1, threads=1, policies=("language",), centre_text=False, data=str(pipeline / "rollouts"),
                   out=str(tmp_path / "distill")).run() == 0
    assert not load_policy(tmp_path / "distill" / "language").cfg.centre_text
    assert "centre_text" not in json.loads((tmp_path / "distill" / "distill.json").read_text())
    assert EvalMultitask(policies=str(tmp_path / "distill"), data=str(pipeline / "rollouts"), seeds=1, tasks=1,
                         threads=1, out=str(tmp_path / "table2.json")).run() == 0
    assert "language_text" not in json.loads((tmp_path / "table2.json").read_text())
    assert "centred" not in (tmp_path / "table2.md").read_text()


def test_centring_is_the_cpu_schedules_default_and_needs_two_goals():
    assert DistillConfig().centre_text is True and DistillConfig(schedule="paper").centre_text is False
    assert DistillConfig(centre_text=False).centre_text is False
    def distill_command(*argv):  # as `zsrm distill ...` parses them
        args = build_parser().parse_args(["distill", *argv])
        return from_namespace(args.options_class, args)

    assert distill_command().centre_text is True
    assert distill_command("--no-centre-text").centre_text is False
    assert distill_command("--schedule", "paper", "--centre-text").centre_text is True
    # One training goal has no spread to scale by: its policy reads the embedding raw.
    assert centres_text(DistillConfig(), "language", tuple(t.text for t in TRAIN_TASKS[:2]))
    assert not centres_text(DistillConfig(), "language", tuple(t.text for t in TRAIN_TASKS[:1]))
    assert not centres_text(DistillConfig(), "primitive", tuple(t.text for t in TRAIN_TASKS[:2]))


def test_eval_multitask_text_span_scores_the_language_policy_again_and_says_so(pipeline, tmp_path, monkeypatch):
    import zsrm.evaluation.multitask as M

    shutil.copytree(pipeline / "distill", tmp_path / "distill")
    calls = []

    def scored(policy, goal, embedding, seeds, spread, task_seed, choice=False):
        calls.append(policy.cfg.conditioning)
        assert policy.cfg.text_span == (policy.cfg.conditioning == "language")
        return [3.0] * seeds

    monkeypatch.setattr(M, "task_rewards", scored)
    out = tmp_path / "table2.json"
    assert EvalMultitask(policies=str(tmp_path / "distill"), data=str(pipeline / "rollouts"), seeds=2, tasks=2,
                         threads=1, text_span=True, out=str(out)).run() == 0
    table = json.loads(out.read_text())
    assert set(calls) == {"language"} and len(calls) == 2 * 2 * 2  # the other policies' cells are reused
    # The fixture's language policy is centred (the cpu schedule's default), so it reads both.
    assert table["language_text"] == "centred, span" and table["language"]["seen"]["test"]["mean"] == 3.0
    assert table["meta"]["command"].endswith("--text-span --out " + str(out))
    assert "projected onto the training goals' span" in out.with_suffix(".md").read_text()
    summary = json.loads((pipeline / "distill" / "distill.json").read_text())
    shutil.copytree(pipeline / "distill" / "none", tmp_path / "none-only" / "none")
    (tmp_path / "none-only" / "distill.json").write_text(
        json.dumps({**summary, "policies": {"none": summary["policies"]["none"]}}))
    with pytest.raises(ValueError, match="has none"):
        EvalMultitask(policies=str(tmp_path / "none-only"), data=str(pipeline / "rollouts"), seeds=2, tasks=2,
                      threads=1, text_span=True, out=str(tmp_path / "t.json")).run()


def test_eval_multitask_reuses_finished_cells_and_rescores_changed_ones(pipeline, tmp_path, monkeypatch):
    import zsrm.evaluation.multitask as M

    first = json.loads((pipeline / "table2.json").read_text())
    csv_rows = (pipeline / "table2.csv").read_text().splitlines()
    # One row per cell of all the split's tasks and one per relation (the fixture's two tasks per split stack).
    assert csv_rows[0] == "policy,spread,split,relation,mean,se,episodes" and len(csv_rows) == 1 + 4 * 2 * 2 * 2
    assert len(list((pipeline / "distill" / "eval").glob("*.json"))) == 4 * 2 * 2

    def scored(policy, goal, embedding, seeds, spread, task_seed, choice=False):
        calls.append((goal, spread))
        return [7.0] * seeds

    monkeypatch.setattr(M, "task_rewards", scored)
    calls = []
    out = tmp_path / "again.json"
    assert EvalMultitask(policies=str(pipeline / "distill"), data=str(pipeline / "rollouts"), seeds=2, tasks=2,
                         threads=1, out=str(out)).run() == 0
    again = json.loads(out.read_text())
    assert calls == [] and {k: again[k] for k in POLICIES} == {k: first[k] for k in POLICIES}
    # Other weights (or other seeds) are scored again, and only that policy.
    _, policies = load_distilled(pipeline / "distill")
    with torch.no_grad():
        next(policies["none"].parameters()).add_(1.0)
    cache = tmp_path / "cells"
    shutil.copytree(pipeline / "distill" / "eval", cache)
    table = M.evaluate_policies(policies, load_vlm("scene"), M.split_goals(2), 2, progress=False, cache=cache)
    assert len(calls) == 2 * 2 * 2 and table["none"]["seen"]["test"]["mean"] == 7.0
    assert table["language"] == first["language"]
    calls.clear()
    M.evaluate_policies({"language": policies["language"]}, load_vlm("scene"), M.split_goals(2), 3,
                        progress=False, cache=cache)
    assert len(calls) == 2 * 2 * 2


def test_table2_has_a_cell_per_relation_and_each_relations_ceiling(pipeline, tmp_path, monkeypatch):
    import zsrm.evaluation.multitask as M
    from zsrm.rl.evaluate import mean_se_cell

    # The ceiling: the task policies' own rollouts, split by each task's relation (the fixture's two
    # tasks stack and place right).
    table = json.loads((pipeline / "table2.json").read_text())
    ceiling = table["oracle_task_policies"]["relations"]
    assert list(ceiling) == ["on_top_of", "right_of"]
    for info in RolloutData(pipeline / "rollouts").infos:
        assert ceiling[parse_goal(info["goal"]).relation] == mean_se_cell(info["episode_rewards"])
    # The fixture's splits hold two stacking tasks each: their one relation's cell is the split's.
    cell = table["language"]["seen"]["test"]
    assert cell["relations"] == {"on_top_of": {k: cell[k] for k in ("mean", "se", "episodes")}}

    # Every relation: each task's episodes count in its own relation's cell and nowhere else.
    rewards = {TRAIN_TASKS[0].text: [10.0, 30.0], TRAIN_TASKS[6].text: [1.0, 3.0], TRAIN_TASKS[7].text: [5.0, 7.0],
               TRAIN_TASKS[12].text: [0.0, 2.0], TEST_TASKS[0].text: [50.0, 70.0], TEST_TASKS[6].text: [4.0, 4.0],
               TEST_TASKS[12].text: [9.0, 11.0]}
    monkeypatch.setattr(M, "task_rewards", lambda policy, goal, *args, **kw: rewards[goal])
    splits = {"train": [TRAIN_TASKS[i].text for i in (0, 6, 7, 12)], "test": [TEST_TASKS[i].text for i in (0, 6, 12)]}
    _, policies = load_distilled(pipeline / "distill")
    cells = M.evaluate_policies({"language": policies["language"]}, load_vlm("scene"), splits, 2, progress=False)
    train = cells["language"]["seen"]["train"]
    assert list(train["relations"]) == ["on_top_of", "left_of", "right_of"]
    assert train["relations"]["left_of"] == mean_se_cell([1.0, 3.0, 5.0, 7.0])
    assert train["relations"]["on_top_of"] == mean_se_cell([10.0, 30.0])
    assert cells["language"]["unseen"]["test"]["relations"]["right_of"] == mean_se_cell([9.0, 11.0])
    assert train["mean"] == pytest.approx(np.mean([r for g in splits["train"] for r in rewards[g]]))
    # The markdown, CSV and plot show them, with each relation's ceiling.
    out = tmp_path / "table2.json"
    M.write_table({**{k: v for k, v in table.items() if k not in M.POLICY_NAMES}, **cells}, out)
    md = out.with_suffix(".md").read_text()
    assert "| on the left of | Language Cond. | 4.0 +- 1.3 | 4.0 +- 0.0 | 4.0 +- 1.3 | 4.0 +- 0.0 |" in md
    top = ceiling["on_top_of"]
    assert f"| on top of | the task policies (ceiling) | {top['mean']:.1f} +- {top['se']:.1f} |" in md
    rows = out.with_suffix(".csv").read_text().splitlines()
    assert "language,seen,train,left_of,4,1.29099,4" in rows and len(rows) == 1 + 2 * 2 * (1 + 3)
    assert out.with_suffix(".png").read_bytes()[:4] == b"\x89PNG"
    # A cell cached before relations were kept is scored again.
    cache = tmp_path / "cells"
    M.evaluate_policies({"language": policies["language"]}, load_vlm("scene"), splits, 2, progress=False, cache=cache)
    saved = json.loads((cache / "language-seen-train.json").read_text())
    del saved["result"]["relations"]
    (cache / "language-seen-train.json").write_text(json.dumps(saved))
    again = M.evaluate_policies({"language": policies["language"]}, load_vlm("scene"), splits, 2, progress=False,
                                cache=cache)
    assert again["language"]["seen"]["train"]["relations"] == train["relations"]


def test_dagger_relabels_the_students_frames_with_the_task_policies_actions(pipeline, tmp_path):
    """zsrm's method: one round on two tasks, two student episodes each, one epoch."""
    from zsrm.policy.dagger import Teacher, aggregate
    from zsrm.policy.training import cloning_data
    from zsrm.tasks.catalogue import TRAIN_COLOURS

    out = tmp_path / "dagger"
    shutil.copytree(pipeline / "distill" / "language", out / "language")  # its behaviour cloning, finished
    args = build_parser().parse_args(["distill", "--dagger-rounds", "1", "--dagger-episodes", "2", "--dagger-epochs",
                                      "1", "--epochs", "1", "--threads", "1", "--policies", "language",
                                      "--data", str(pipeline / "rollouts"), "--out", str(out)])
    assert from_namespace(args.options_class, args).run() == 0
    round_1 = out / "dagger" / "language" / "round_1"
    relabelled = np.load(round_1 / "relabelled.npz")
    frames, actions, codes = relabelled["frames"], relabelled["actions"], relabelled["codes"]
    assert sorted(set(codes.tolist())) == [0, 1] and len(frames) == len(actions) == len(codes)
    record = json.loads((round_1 / "config.json").read_text())["training"]
    bc = RolloutData(pipeline / "rollouts").load()
    # The data grew by exactly the relabelled frames: the rollouts' and the student's.
    assert record["relabelled"] == len(actions) and record["frames"] == len(bc["actions"]) + len(actions)
    vlm = load_vlm("scene")
    data = cloning_data(RolloutData(pipeline / "rollouts"), vlm, ["language"])
    whole = aggregate(data, [{"frames": frames, "actions": actions, "codes": codes}])
    assert len(whole.actions) == record["frames"] and torch.equal(whole.actions[len(data.actions):],
                                                                  torch.from_numpy(actions))
    student = load_policy(pipeline / "distill" / "language")
    embeddings = embed_goals(vlm, GOALS)
    for code, goal in enumerate(GOALS):
        mine = codes == code
        # Each frame's label is its task policy's action on that frame, not what the student did there.
        bundle = PolicyBundle.load(policy_folder(pipeline / "policies", goal))
        venv = make_vec(bundle.cfg, 1, 0)
        expected = bundle.act(policy_view(venv, vlm, bundle.cfg).convert(frames[mine]), deterministic=True)
        venv.close()
        assert np.allclose(actions[mine], expected, atol=1e-6)
        assert np.allclose(Teacher(policy_folder(pipeline / "policies", goal), goal).actions(frames[mine]), expected,
                           atol=1e-6)
        own = student.act(frames[mine][:10], embeddings[code:code + 1].expand(10, -1)).numpy()
        assert not np.allclose(own, actions[mine][:10], atol=1e-3)
    # The student's frames are of its two training tasks' scenes: no blue block, word or task.
    assert set(record["objects"]) <= set(TRAIN_COLOURS) and not blue_pixels(frames).any()
    assert set(record["student_reward"]) == set(GOALS)
    # distill.json names the round's policy; eval-multitask scores it and says how it was distilled.
    summary, policies = load_distilled(out)
    assert summary["distillation"] == "dagger" and summary["policies"]["language"]["folder"] == \
        "dagger/language/round_1"
    assert summary["policies"]["language"]["behaviour_cloning"]["folder"] == "language"
    after = load_policy(round_1)
    assert all(torch.equal(a, b) for a, b in zip(policies["language_dagger"].state_dict().values(),
                                                 after.state_dict().values()))
    # Beside it, its behaviour cloning: the paper's method, as a table shows them both.
    assert all(torch.equal(a, b) for a, b in zip(policies["language"].state_dict().values(),
                                                 student.state_dict().values()))
    assert not all(torch.equal(a, b) for a, b in zip(student.state_dict().values(), after.state_dict().values()))
    # A second run finds the round finished and leaves it as it is.
    mtime = (round_1 / "model.safetensors").stat().st_mtime_ns
    assert from_namespace(args.options_class, args).run() == 0
    assert (round_1 / "model.safetensors").stat().st_mtime_ns == mtime
    assert EvalMultitask(policies=str(out), data=str(pipeline / "rollouts"), seeds=1, tasks=1, threads=1,
                         out=str(tmp_path / "table2.json")).run() == 0
    table = json.loads((tmp_path / "table2.json").read_text())
    assert {"language", "language_dagger"} <= set(table) and table["dagger"]["rounds"] == 1
    md = (tmp_path / "table2.md").read_text()
    assert "DAgger-style relabelling" in md and "| Language Cond. + DAgger (zsrm) |" in md
    # zsrm's own policy is the table's best; its test score over the ceiling of each relation it was scored on.
    best = table["best"]
    assert best["policy"] == "language_dagger" and set(best["test_over_ceiling"]) == {"on_top_of"}
    cell, top = table["language_dagger"]["unseen"]["test"], table["oracle_task_policies"]["relations"]["on_top_of"]
    assert best["test_over_ceiling"]["on_top_of"]["unseen"] == (pytest.approx(cell["mean"] / top["mean"])
                                                                 if top["mean"] else None)
    # One table of several runs: a policy name twice is refused.
    with pytest.raises(ValueError, match="named as one of an earlier folder's"):
        EvalMultitask(policies=(str(pipeline / "distill"), str(out)), data=str(pipeline / "rollouts"), seeds=1,
                      tasks=1, threads=1, out=str(tmp_path / "both.json")).run()
    # Without its task policies DAgger has no labels: one line naming the folder.
    with pytest.raises(FileNotFoundError, match="no task policy in .*nowhere"):
        Distill(epochs=1, threads=1, policies=("language",), dagger_rounds=1, teachers=str(tmp_path / "nowhere"),
                data=str(pipeline / "rollouts"), out=str(out)).run()


def test_the_best_policy_is_zsrms_own_chosen_on_the_training_tasks():
    import zsrm.evaluation.multitask as M

    def policy(train, test):
        cell = lambda mean: {"mean": mean, "se": 1.0, "episodes": 2, "relations": {"left_of": {"mean": mean}}}
        return {s: {"train": cell(train), "test": cell(test)} for s in M.SPREADS}

    table = {"language": policy(90.0, 90.0), "grounded": policy(30.0, 40.0), "grounded_dagger": policy(35.0, 20.0),
             "oracle_task_policies": {"mean": 50.0, "relations": {"left_of": {"mean": 40.0}}}}
    # The paper's policies are not zsrm's; the test tasks do not choose.
    best = M.best_policy(table)
    assert best["policy"] == "grounded_dagger" and best["test_over_ceiling"] == {"left_of": {"seen": 0.5,
                                                                                             "unseen": 0.5}}
    assert M.best_policy({k: table[k] for k in ("language", "oracle_task_policies")}) is None
    # A policy taught by mirrored teachers is also measured against the teachers that taught it.
    table |= {"grounded_mirror_teachers_dagger": policy(40.0, 30.0),
              "oracle_teachers": {"mean": 60.0, "relations": {"left_of": {"mean": 60.0}}}}
    best = M.best_policy(table)
    assert best["policy"] == "grounded_mirror_teachers_dagger"
    assert best["test_over_ceiling"]["left_of"] == {"seen": 0.75, "unseen": 0.75}
    assert best["test_over_teachers"]["left_of"] == {"seen": 0.5, "unseen": 0.5}


def test_docstring_examples():
    import doctest

    import zsrm.policy.models

    result = doctest.testmod(zsrm.policy.models)
    assert result.attempted > 0 and result.failed == 0


@pytest.mark.parametrize("damage", [*H.WEIGHT_DAMAGE, "pickle", "config_a_list", "config_unknown_key"])
def test_a_damaged_distilled_policy_is_one_line_naming_the_file(pipeline, damage, tmp_path):
    """The distilled policies load through the registry: damage is refused before any weight is read."""
    folder = tmp_path / "language"
    shutil.copytree(pipeline / "distill" / "language", folder)
    weights, config, marker = folder / "model.safetensors", folder / "config.json", tmp_path / "code-ran"
    if damage == "pickle":
        H.write_pickle_bomb(weights, marker)
    elif damage in H.WEIGHT_DAMAGE:
        H.WEIGHT_DAMAGE[damage](weights)
    elif damage == "config_a_list":
        config.write_text("[1, 2]")
    else:
        config.write_text(json.dumps({**json.loads(config.read_text()), "surprise": 1}))
    with pytest.raises(ZsrmFileError) as err:
        load_policy(folder)
    message = str(err.value)
    assert "\n" not in message.strip()
    assert str(config if damage.startswith("config") else weights) in message
    assert not marker.exists()


def test_blue_sensitivity_probe_measures_each_moved_block(pipeline, tmp_path, monkeypatch):
    out = tmp_path / "blue.json"
    run_probe("distill_blue_sensitivity.py", monkeypatch, "--policies", str(pipeline / "distill"), "--scenes", "1",
                  "--out", str(out))
    result = json.loads(out.read_text())
    for policy in ("language", "primitive", "none"):
        for moved in ("blue", "test_other", "train"):
            cell = result[policy][moved]
            # A block that moves a block width moves the frame, so the keypoints move.
            assert cell["keypoint_shift"]["mean"] > 0 and cell["action_change"]["mean"] >= 0


def test_goal_probe_reads_swapped_and_other_relation_sentences(pipeline, tmp_path, monkeypatch):
    out = tmp_path / "probe.json"
    run_probe("distill_goal_probe.py", monkeypatch, "--policies", str(pipeline / "distill"), "--seeds", "1",
                  "--tasks", "1", "--out", str(out))
    result = json.loads(out.read_text())
    assert set(result) >= {"language", "primitive"} and "none" not in result
    test = result["language"]["test"]
    # The first test goal is "a blue block on top of a red block"; the policy is scored on its scenes.
    assert test["own"]["per_task"] == {"a blue block on top of a red block": test["own"]["per_task"][
        "a blue block on top of a red block"]}
    assert test["swapped"]["per_task"]["a blue block on top of a red block"]["reads"] == \
        "a red block on top of a blue block"
    assert test["left_of"]["per_task"]["a blue block on top of a red block"]["reads"] == \
        "a blue block on the left of a red block"
    for reading in ("own", "swapped", "left_of"):
        assert test[reading]["episodes"] == 1 and 0 <= test[reading]["mean"] <= 100


def test_task_policy_distractor_probe_adds_the_third_colour(pipeline, tmp_path, monkeypatch):
    venv = make_vec(TrainConfig(goal=GOALS[0]), 1, 0, distractors=("yellow",))
    venv.reset()
    assert set(venv.envs[0].unwrapped.object_positions()) == {"red", "green", "yellow"}
    venv.close()
    out = tmp_path / "distractor.json"
    run_probe("task_policy_distractor.py", monkeypatch, "--policies", str(pipeline / "policies"), "--tasks", "1",
                  "--episodes", "1", "--out", str(out))
    result = json.loads(out.read_text())
    row = result["per_task"][GOALS[0]]  # "a red block on top of a green block"
    assert row["third_colour"] == "yellow" and row["plain"]["on_distractor"] == 0.0
    for scene in ("plain", "distractor"):
        assert result[scene]["on_base"]["episodes"] == 1
        assert 0 <= row[scene]["on_base"] + row[scene]["on_distractor"] <= 100


def test_table2_seeds_gives_each_seeds_gap_and_the_mean_over_seeds(pipeline, tmp_path, monkeypatch):
    table = json.loads((pipeline / "table2.json").read_text())
    paths = []
    for seed, (language, primitive) in enumerate([(30.0, 25.0), (20.0, 26.0)]):
        for policy, mean in (("language", language), ("primitive", primitive), ("none", 10.0)):
            for spread in ("seen", "unseen"):
                table[policy][spread]["test"] = {"mean": mean, "se": 1.0, "episodes": 900}
        table["meta"]["distill_seed"] = seed
        paths.append(tmp_path / f"table{seed}.json")
        paths[-1].write_text(json.dumps(table))
    out = tmp_path / "seeds.json"
    run_benchmark("table2_seeds.py", monkeypatch, *map(str, paths), "--out", str(out))
    result = json.loads(out.read_text())
    assert result["distill_seeds"] == [0, 1]
    gap = result["test_gaps"]["language-primitive"]["seen"]
    assert [row["gap"] for row in gap["per_table"]] == [5.0, -6.0] and gap["holds_in"] == "1 of 2"
    assert gap["mean"] == -0.5 and gap["se_over_seeds"] == pytest.approx(5.5)
    assert result["language"]["unseen"]["test"]["mean"] == 25.0
    assert result["primitive"]["seen"]["test"]["se_over_seeds"] == pytest.approx(0.5)
    assert result["test_gaps"]["primitive-none"]["unseen"]["holds_in"] == "2 of 2"
    # Language rows scored apart stand in for the tables' own, checked to be of the same data and seed.
    apart = []
    for seed, path in enumerate(paths):
        other = json.loads(path.read_text())
        other["language"]["seen"]["test"] = {"mean": 40.0, "se": 1.0, "episodes": 900}
        other["language_text"] = "centred, span"
        apart.append(tmp_path / f"language{seed}.json")
        apart[-1].write_text(json.dumps(other))
    run_benchmark("table2_seeds.py", monkeypatch, *map(str, paths), "--language", *map(str, apart), "--out", str(out))
    result = json.loads(out.read_text())
    assert [row["gap"] for row in result["test_gaps"]["language-primitive"]["seen"]["per_table"]] == [15.0, 14.0]
    assert result["language_text"] == ["centred, span"] * 2
    with pytest.raises(SystemExit):
        run_benchmark("table2_seeds.py", monkeypatch, *map(str, paths), "--language", str(apart[1]), str(apart[0]),
                      "--out", str(out))


def test_shape_frames_paint_every_block_colour_one_grey_and_keep_the_rest_grey():
    """The shape view shows where the blocks and the gripper are, never which colour a block is."""
    frames = {}
    for goal in ("a blue block on the left of a yellow block", "a red block on the left of a green block"):
        env = gym.make("zsrm/Tabletop-v0", task=goal)
        obs, info = env.reset(seed=0)
        env.close()
        frames[goal] = torch.as_tensor(obs["front"]).permute(2, 0, 1)[None]
    blue, red = frames.values()
    shapes = shape_frames(torch.cat([blue, red]))
    assert torch.equal(shapes[:, 0], shapes[:, 1]) and torch.equal(shapes[:, 0], shapes[:, 2])  # grey
    painted = shapes[:, 0] == SHAPE_GREY
    # Two 6 cm blocks at 64 px cover about 94 pixels, every one of them painted, whatever its colour.
    assert all(80 <= int(m.sum()) <= 110 for m in painted)
    rest = ~painted
    assert torch.equal(shapes[:, 0][rest], grey_frames(torch.cat([blue, red]))[:, 0][rest])
    # Same seed, same layout: with the colours swapped the shape frames are the same but for the
    # blocks' own positions.
    assert (shapes[0] != shapes[1]).float().mean() < 0.05


def test_mirror_batch_flips_half_the_frames_their_actions_x_and_their_goal():
    from zsrm.policy.mirror import mirror_batch

    g = torch.Generator().manual_seed(0)
    images = torch.randint(0, 256, (64, 3, 4, 5), generator=g, dtype=torch.uint8)
    actions, codes = torch.rand(64, 3, generator=g) * 2 - 1, torch.randint(0, 3, (64,), generator=g)
    mirrors = torch.tensor([0, 2, 1])  # a stacking goal (its own mirror), a left of and its right of
    out_images, out_actions, out_codes = mirror_batch(images, actions, codes, mirrors, g)
    flipped = torch.tensor([not torch.equal(a, b) for a, b in zip(out_images, images)])
    assert 10 < int(flipped.sum()) < 54
    assert torch.equal(out_images[flipped], images[flipped].flip(-1))
    assert torch.equal(out_actions[flipped, 0], -actions[flipped, 0])
    assert torch.equal(out_actions[:, 1:], actions[:, 1:]) and torch.equal(out_actions[~flipped], actions[~flipped])
    assert torch.equal(out_codes, torch.where(flipped, mirrors[codes], codes))


@pytest.fixture(scope="module")
def mirrored(pipeline, tmp_path_factory):
    """The tiny pipeline's task policies, a third for GOALS[1]'s mirror goal, and rollouts of all three."""
    root, left = tmp_path_factory.mktemp("mirrored"), TRAIN_TASKS[6].text
    shutil.copytree(pipeline / "policies", root / "policies")
    train(TrainConfig(goal=left, reward="zsrm", seed=0, **TINY), policy_folder(root / "policies", left).parent,
          progress=False)
    assert MultitaskRollouts(tasks=(*GOALS, left), policies=str(root / "policies"), episodes=2, envs=2,
                             out=str(root / "rollouts")).run() == 0
    return root


def test_distill_mirror_reads_each_placing_task_as_its_mirror_too(pipeline, mirrored, tmp_path):
    """--mirror on rollouts of a place-right task and its mirror (and a stacking task, its own)."""
    from zsrm.policy.training import cloning_data, identity

    left = TRAIN_TASKS[6].text  # the mirror of GOALS[1]
    assert parse_goal(GOALS[1]).mirrored().text == left and parse_goal(GOALS[0]).mirrored() == parse_goal(GOALS[0])
    data = cloning_data(RolloutData(mirrored / "rollouts"), load_vlm("scene"), ["language"])
    assert data.goals == [GOALS[0], left, GOALS[1]]  # TRAIN_TASKS order
    assert [data.goals[i] for i in data.mirror_codes()] == [GOALS[0], GOALS[1], left]
    assert "mirror" not in identity(DistillConfig(), "language", data)  # earlier runs' checkpoints still resume
    assert identity(DistillConfig(mirror=True), "language", data)["mirror"] is True
    assert Distill(epochs=1, threads=1, policies=("language",), mirror=True, data=str(mirrored / "rollouts"),
                   out=str(tmp_path / "distill")).run() == 0
    summary, policies = load_distilled(tmp_path / "distill")
    # A table shows it apart from the same policy distilled without mirrored frames.
    assert summary["mirror"] is True and set(policies) == {"language_mirror"}
    # Rollouts without a task's mirror are refused before any work, in one line.
    for option in ("mirror", "mirror_teachers"):
        with pytest.raises(ValueError, match="mirroring needs each goal's mirror goal in the rollouts"):
            Distill(epochs=1, threads=1, policies=("language",), data=str(pipeline / "rollouts"),
                    out=str(tmp_path / "refused"), **{option: True}).run()
    assert not (tmp_path / "refused" / "language").exists()
    with pytest.raises(ValueError, match="left camera, whose image does not flip"):
        parse_goal("a red block in front of a green block").mirrored()


def test_each_task_is_taught_by_whichever_of_it_and_its_mirror_the_zsrm_reward_rates_higher(tmp_path, monkeypatch):
    import zsrm.policy.mirror as M

    # The training return: the zsrm reward's, over the last three evaluations, from the trial's
    # summary beside a sweep's policy or kept in trials/ beside the kept policies.
    curve = [{"env_steps": k, "mean": 99.0, "train_reward": r} for k, r in enumerate([1.0, 2.0, 3.0, 7.0])]
    kept = tmp_path / "results" / "task_policies" / "trial" / "policy"
    kept.mkdir(parents=True)
    (tmp_path / "results" / "trials").mkdir()
    (tmp_path / "results" / "trials" / "trial.json").write_text(json.dumps({"curve": curve}))
    assert M.teacher_return(kept) == pytest.approx(4.0)  # 2, 3, 7: the oracle's 99 is never read
    (kept.parent / "summary.json").write_text(json.dumps({"curve": curve[:2]}))
    assert M.teacher_return(kept) == pytest.approx(1.5)
    with pytest.raises(FileNotFoundError, match="no trial summary for the task policy"):
        M.teacher_return(tmp_path / "elsewhere" / "policy")
    from zsrm.policy.training import CloningData

    goals = [GOALS[0], TRAIN_TASKS[6].text, GOALS[1]]  # stack, left of, its mirror right of
    data = lambda goals: CloningData(torch.zeros(0), torch.zeros(0), torch.zeros(0), goals, {}, "front", 4)
    mirrors = data(goals).mirror_codes().tolist()
    assert mirrors == [0, 2, 1]
    returns = {"stack": 1.0, "left": 9.0, "right": 5.0}
    monkeypatch.setattr(M, "teacher_return", lambda folder: returns[folder])
    assert M.teaching_tasks(mirrors, ["stack", "left", "right"]) == [0, 1, 1]
    returns["right"] = 10.0
    assert M.teaching_tasks(mirrors, ["stack", "left", "right"]) == [0, 2, 2]
    with pytest.raises(ValueError, match="mirror goal in the rollouts"):
        data(goals[::2]).mirror_codes()


def test_distill_mirror_teachers_distils_and_relabels_a_task_with_its_mirrors_policy(mirrored, tmp_path,
                                                                                      monkeypatch):
    """The place-right task taught by the place-left policy: its rollouts mirrored, its DAgger labels
    that policy's actions on the flipped frames, x negated."""
    import zsrm.policy.mirror as M
    from zsrm.policy.dagger import MirroredTeacher, Teacher
    from zsrm.policy.training import cloning_data

    left, right = TRAIN_TASKS[6].text, GOALS[1]
    monkeypatch.setattr(M, "teacher_return", lambda folder: 9.0 if "left" in str(folder) else 1.0)
    rollouts = RolloutData(mirrored / "rollouts")
    data = cloning_data(rollouts, load_vlm("scene"), ["language"])
    taught = M.taught_by(data, M.teaching_tasks(data.mirror_codes().tolist(),
                                                [policy_folder(mirrored / "policies", g) for g in data.goals]))
    codes = {g: data.goals.index(g) for g in data.goals}
    assert taught.teaching == (codes[GOALS[0]], codes[left], codes[left])
    mine, source = taught.codes == codes[right], data.codes == codes[left]
    assert torch.equal(taught.images[mine], data.images[source].flip(-1))
    assert torch.equal(taught.actions[mine][:, 0], -data.actions[source][:, 0])
    assert torch.equal(taught.images[taught.codes == codes[left]], data.images[source])
    out = tmp_path / "distill"
    assert Distill(epochs=1, threads=1, policies=("language",), mirror_teachers=True, dagger_rounds=1,
                   dagger_episodes=2, dagger_epochs=1, data=str(mirrored / "rollouts"), out=str(out)).run() == 0
    summary, policies = load_distilled(out)
    assert summary["mirror_teachers"] == {right: left}
    assert set(policies) == {"language_mirror_teachers", "language_mirror_teachers_dagger"}
    relabelled = np.load(out / "dagger" / "language" / "round_1" / "relabelled.npz")
    frames = relabelled["frames"][relabelled["codes"] == codes[right]]
    teacher = MirroredTeacher(policy_folder(mirrored / "policies", right), right,
                              policy_folder(mirrored / "policies", left))
    expected = Teacher(policy_folder(mirrored / "policies", left), left).actions(frames[:, :, ::-1].copy())
    expected[:, 0] *= -1
    assert np.allclose(relabelled["actions"][relabelled["codes"] == codes[right]], expected, atol=1e-6)
    assert np.allclose(teacher.actions(frames), expected, atol=1e-6)
    # the student rolled out in the place-right task's own scenes
    assert teacher.scenes(1, 0).get_attr("task")[0] == parse_goal(right)
    # The table names the rows and says which tasks their mirrors taught.
    assert EvalMultitask(policies=str(out), data=str(mirrored / "rollouts"), seeds=1, tasks=1, threads=1,
                         out=str(tmp_path / "table2.json")).run() == 0
    table = json.loads((tmp_path / "table2.json").read_text())
    assert table["mirror_teachers"] == {right: left}
    # Beside the ceiling, the bar of the teachers that taught: the place-right task's is the place-left policy's.
    own = {info["goal"]: np.mean(info["episode_rewards"]) for info in rollouts.infos}
    assert table["oracle_task_policies"]["relations"]["right_of"]["mean"] == pytest.approx(own[right])
    assert table["oracle_teachers"]["relations"]["right_of"]["mean"] == pytest.approx(own[left])
    assert table["oracle_teachers"]["relations"]["on_top_of"] == table["oracle_task_policies"]["relations"]["on_top_of"]
    assert {"language_mirror_teachers", "language_mirror_teachers_dagger"} <= set(table)
    md = (tmp_path / "table2.md").read_text()
    assert "| Language Cond. + mirrored teachers + DAgger (zsrm) |" in md
    assert "mirrored teachers: a task is taught by its mirror task's policy" in md and f"{right} <- {left}" in md


def test_relation_word_probe_reads_each_placing_goal_and_its_mirror(pipeline, tmp_path, monkeypatch):
    out = tmp_path / "probe.json"
    run_probe("relation_word_probe.py", monkeypatch, "--policies", str(pipeline / "distill"), "--names", "language",
              "--seeds", "1", "--tasks", "1", "--out", str(out))
    probe = json.loads(out.read_text())
    assert set(probe["language"]) == {"train", "test"}
    for cell in probe["language"].values():
        assert set(cell) == {"own", "mirrored"} and all(c["episodes"] == 1 for c in cell.values())

"""The push_close probes (probes/push_state_ppo.py, push_scripts.py, push_pixel_sac.py) at a tiny scale."""
import json
import runpy
import sys
from pathlib import Path

import numpy as np
import pytest

from zsrm.rl.config import TrainConfig

PROBES = Path(__file__).parent.parent / "probes"


def probe(name: str) -> dict:
    return runpy.run_path(str(PROBES / name), run_name="probe")


def run(name: str, monkeypatch, *args: str) -> None:
    monkeypatch.setattr(sys, "argv", [str(PROBES / name), *args])
    runpy.run_path(str(PROBES / name), run_name="__main__")


@pytest.mark.parametrize("observe,width", [("positions", 6), ("relative", 4), ("pairs", 12)])
def test_the_state_view_reads_the_pusher_and_pucks_and_never_renders(observe, width):
    ns = probe("push_state_ppo.py")
    env = ns["make_env"](TrainConfig(goal="push_close"), ns["Probe"](observe=observe, scale=0.1), seed=3)
    obs, info = env.reset(seed=3)
    scene = env.unwrapped
    pusher, puck, other = scene.pusher_position[:2], *(info["object_positions"][c][:2] for c in scene.task.objects[:2])
    assert obs.shape == (width,)
    expected = {"positions": [pusher, puck, other], "relative": [puck - pusher, other - puck],
                "pairs": [pusher, puck, other, puck - pusher, other - pusher, other - puck]}[observe]
    np.testing.assert_allclose(obs, np.concatenate(expected) / 0.1, rtol=1e-5, atol=1e-5)
    assert not scene._observation()["front"].any()  # a blank frame: no renderer runs
    _, reward, _, _, info = env.step(np.zeros(2, np.float32))
    assert reward == info["oracle_steps"]


def test_the_state_probe_writes_its_trials_and_command(tmp_path, monkeypatch):
    out = tmp_path / "state.json"
    run("push_state_ppo.py", monkeypatch, "--steps", "2048", "--seeds", "0", "--episodes", "2",
        "--observe", "relative", "--scale", "0.1", "--out", str(out))
    result = json.loads(out.read_text())
    assert [t["seed"] for t in result["trials"]] == [0]
    assert 0.0 <= result["final_success_rate"] <= 1.0 and result["trials"][0]["final_action_std"] > 0
    assert result["meta"]["probe"]["observe"] == "relative" and "--observe relative" in result["meta"]["command"]


def test_a_steering_script_finishes_push_close_deciding_every_4_steps():
    ns = probe("push_scripts.py")
    steering, straight = (ns["play"](ns[name], 4, 4, 20_000) for name in ("align", "straight"))
    assert steering["final_success_rate"] == 1.0
    assert straight["final_success_rate"] < 1.0 and straight["final_mean"] < steering["final_mean"]


def test_the_pixel_sac_probe_trains_and_evaluates(tmp_path, monkeypatch):
    out = tmp_path / "sac"
    run("push_pixel_sac.py", monkeypatch, "--steps", "1600", "--envs", "2", "--batch-size", "16",
        "--learning-starts", "100", "--eval-every", "800", "--eval-episodes", "2", "--out", str(out))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["gradient_steps"] > 0 and [r["env_steps"] for r in summary["curve"]] == [800, 1600]
    assert (out / "eval.csv").read_text().count("\n") == 3  # the header and two evaluations


def test_the_pixel_sac_probes_shifted_buffer_moves_the_pixel_view_alone():
    import gymnasium as gym
    import torch

    from zsrm.rl.features import FEATURES_KEY, IMAGE_KEY

    space = gym.spaces.Dict({FEATURES_KEY: gym.spaces.Box(0.0, 1.0, (2, 4, 4), np.float32),
                             IMAGE_KEY: gym.spaces.Box(0, 255, (3, 8, 8), np.uint8)})
    buffer = probe("push_pixel_sac.py")["shifted_buffer"](2, seed=0)(
        16, space, gym.spaces.Box(-1.0, 1.0, (2,), np.float32), n_envs=1)
    rng = np.random.default_rng(0)
    for _ in range(16):
        obs = {FEATURES_KEY: rng.random((1, 2, 4, 4), dtype=np.float32),
               IMAGE_KEY: rng.integers(0, 256, (1, 3, 8, 8), dtype=np.uint8)}
        buffer.add(obs, obs, np.zeros((1, 2), np.float32), np.zeros(1), np.zeros(1), [{}])
    batch = buffer.sample(64)
    stored = {k: torch.as_tensor(v[batch_rows(buffer, batch), 0]).float() for k, v in buffer.observations.items()}
    assert torch.equal(batch.observations[FEATURES_KEY], stored[FEATURES_KEY])  # the VLM map as stored
    assert batch.observations[IMAGE_KEY].shape == (64, 3, 8, 8)
    assert not torch.equal(batch.observations[IMAGE_KEY], stored[IMAGE_KEY])  # some frames moved


def batch_rows(buffer, batch) -> np.ndarray:
    """The buffer rows a sample drew, found by its VLM maps (each row's map is unique)."""
    maps = buffer.observations["features"][:buffer.size(), 0].reshape(buffer.size(), -1)
    drawn = batch.observations["features"].numpy().reshape(len(batch.actions), -1)
    return np.array([int(np.flatnonzero((maps == row).all(axis=1))[0]) for row in drawn])


def test_the_state_probes_sac_records_its_envs_and_gradient_steps(tmp_path, monkeypatch):
    out = tmp_path / "sac.json"
    run("push_state_ppo.py", monkeypatch, "--learner", "sac", "--steps", "800", "--seeds", "0", "--episodes", "1",
        "--sac-envs", "2", "--sac-gradient-steps", "2", "--out", str(out))
    probe_meta = json.loads(out.read_text())["meta"]["probe"]
    assert (probe_meta["learner"], probe_meta["sac_envs"], probe_meta["sac_gradient_steps"]) == ("sac", 2, 2)


def test_the_pixel_sac_probe_learns_on_a_frozen_extractors_keypoints(tmp_path, monkeypatch):
    out = tmp_path / "kp"
    run("push_pixel_sac.py", monkeypatch, "--steps", "800", "--envs", "2", "--batch-size", "16",
        "--learning-starts", "50", "--eval-every", "800", "--eval-episodes", "1", "--keypoints-from", "random",
        "--anneal-lr", "--out", str(out))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["gradient_steps"] > 0 and summary["meta"]["keypoints_from"] == "random"
    assert summary["meta"]["anneal_lr"] is True


def test_frozen_keypoints_are_the_extractors_points_and_stay_frozen():
    import gymnasium as gym
    import torch
    from stable_baselines3.common.vec_env import DummyVecEnv

    from zsrm.rl.features import FEATURES_KEY, IMAGE_KEY, KeypointExtractor

    space = gym.spaces.Dict({FEATURES_KEY: gym.spaces.Box(0.0, 1.0, (4, 4, 4), np.float32),
                             IMAGE_KEY: gym.spaces.Box(0, 255, (3, 16, 16), np.uint8)})

    space.seed(0)
    first, last = space.sample(), space.sample()

    class Still(gym.Env):
        observation_space, action_space = space, gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

        def reset(self, seed=None, options=None):
            return first, {}

        def step(self, action):
            return last, 0.0, True, False, {}

    ns = probe("push_pixel_sac.py")
    extractor = KeypointExtractor(space, keypoints=3)
    venv = ns["VecKeypoints"](DummyVecEnv([Still]), extractor)
    obs = venv.reset()
    assert obs.shape == (1, extractor.points_dim) and venv.observation_space.shape == (extractor.points_dim,)
    assert not any(p.requires_grad for p in extractor.parameters())
    _, _, dones, infos = venv.step(np.zeros((1, 2), np.float32))
    with torch.no_grad():
        expected = [extractor.points({k: torch.as_tensor(v[None]) for k, v in o.items()})[0].numpy()
                    for o in (first, last)]
    np.testing.assert_allclose(obs[0], expected[0], rtol=1e-6)
    assert dones[0]
    np.testing.assert_allclose(infos[0]["terminal_observation"], expected[1], rtol=1e-6)  # the episode's last frame


def test_the_state_views_noise_moves_each_position_by_about_its_size():
    ns = probe("push_state_ppo.py")
    env = ns["make_env"](TrainConfig(goal="push_close"), ns["Probe"](scale=1.0, noise=0.01), seed=3)
    obs, info = env.reset(seed=3)
    scene = env.unwrapped
    true = np.concatenate([scene.pusher_position[:2], *(info["object_positions"][c][:2] for c in scene.task.objects[:2])])
    errors = [obs - true]
    for _ in range(30):
        obs, _, _, _, info = env.step(np.zeros(2, np.float32))
        true = np.concatenate([scene.pusher_position[:2],
                               *(info["object_positions"][c][:2] for c in scene.task.objects[:2])])
        errors.append(obs - true)
    spread = np.std(np.concatenate(errors))
    assert 0.007 < spread < 0.013  # 186 draws of a 1 cm normal


def test_the_pixel_sac_probe_reads_a_trained_extractor_on_its_own_views(tmp_path, monkeypatch):
    from zsrm.rl.ppo import train

    # a tiny PPO policy whose pixel CNN reads 16 px frames, not the default 32
    cfg = TrainConfig(goal="push_close", reward="oracle", steps=128, eval_every=128, checkpoint_every=128,
                      n_envs=2, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=1, keypoints=4, pixel_size=16)
    train(cfg, tmp_path / "ppo", progress=False)
    out = tmp_path / "kp"
    run("push_pixel_sac.py", monkeypatch, "--steps", "400", "--envs", "2", "--batch-size", "8",
        "--learning-starts", "20", "--eval-every", "400", "--eval-episodes", "1",
        "--keypoints-from", str(tmp_path / "ppo" / "policy"), "--out", str(out))
    assert json.loads((out / "summary.json").read_text())["gradient_steps"] > 0


def test_the_pixel_sac_probe_starts_every_extractor_from_a_trained_policys(tmp_path, monkeypatch):
    from zsrm.rl.ppo import train

    cfg = TrainConfig(goal="push_close", reward="oracle", steps=128, eval_every=128, checkpoint_every=128,
                      n_envs=2, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=1, keypoints=4, pixel_size=16,
                      pixel_stride=2)
    train(cfg, tmp_path / "ppo", progress=False)
    out = tmp_path / "ft"
    run("push_pixel_sac.py", monkeypatch, "--steps", "400", "--envs", "2", "--batch-size", "8",
        "--learning-starts", "20", "--eval-every", "400", "--eval-episodes", "1",
        "--finetune-from", str(tmp_path / "ppo" / "policy"), "--out", str(out))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["gradient_steps"] > 0 and summary["meta"]["finetune_from"].endswith("policy")


def test_start_extractors_copies_the_trained_extractor_into_actor_critic_and_target():
    import gymnasium as gym
    import torch
    from stable_baselines3 import SAC
    from stable_baselines3.common.vec_env import DummyVecEnv

    from zsrm.rl.features import FEATURES_KEY, IMAGE_KEY, KeypointExtractor

    space = gym.spaces.Dict({FEATURES_KEY: gym.spaces.Box(0.0, 1.0, (4, 8, 8), np.float32),
                             IMAGE_KEY: gym.spaces.Box(0, 255, (3, 16, 16), np.uint8)})

    class Still(gym.Env):
        observation_space, action_space = space, gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

        def reset(self, seed=None, options=None):
            return space.sample(), {}

        def step(self, action):
            return space.sample(), 0.0, True, False, {}

    kwargs = dict(keypoints=3, pixel_stride=2)
    model = SAC("MultiInputPolicy", DummyVecEnv([Still]), buffer_size=10, policy_kwargs=dict(
        features_extractor_class=KeypointExtractor, features_extractor_kwargs=kwargs, share_features_extractor=False,
        normalize_images=False))
    torch.manual_seed(1)
    trained = KeypointExtractor(space, **kwargs)
    probe("push_pixel_sac.py")["start_extractors"](model, trained)
    for net in (model.actor, model.critic, model.critic_target):
        for name, value in trained.state_dict().items():
            torch.testing.assert_close(net.features_extractor.state_dict()[name], value)
    assert model.actor.features_extractor is not model.critic.features_extractor  # each trains on


def test_the_keypoint_precision_probe_scores_each_extractor_in_cm(tmp_path, monkeypatch):
    out = tmp_path / "precision.json"
    run("keypoint_precision.py", monkeypatch, "--episodes", "4", "--steps", "5", "--extractors", "random",
        "--supervised", "pixel_size=64,pixel_stride=2", "--out", str(out))
    result = json.loads(out.read_text())
    supervised = result["extractors"]["supervised:pixel_size=64,pixel_stride=2"]
    assert (supervised["pixel_size"], supervised["pixel_stride"]) == (64, 2)
    errors = result["extractors"]["random"]["error_cm"]
    assert set(errors) >= {"pusher x", "puck y", "other x", "puck from pusher", "mean"}
    assert all(np.isfinite(v) and v >= 0 for v in errors.values())
    assert result["frames"]["held_out"] > 0 and result["meta"]["command"].startswith("python probes/keypoint_precision.py")


def test_the_keypoint_precision_probes_frames_hold_the_true_places():
    from zsrm.rl.envs import make_vec

    ns = probe("keypoint_precision.py")
    cfg = TrainConfig(goal="push_close")
    venv = make_vec(cfg, 1, 0)
    images, targets, episode = ns["collect"](venv, cfg, 2, 0)
    venv.close()
    assert images.shape[1:] == (64, 64, 3) and targets.shape == (len(images), 6)
    assert set(episode) == {0, 1} and np.abs(targets).max() < 0.5  # table (x, y) in metres
    moved = np.abs(np.diff(targets[episode == 0, :2], axis=0)).max()  # the script walks the pusher
    assert moved > 0.005


def test_the_autoencoders_blobs_peak_at_their_points():
    import torch

    gaussian_maps = probe("keypoint_autoencoder.py")["gaussian_maps"]
    maps = gaussian_maps(torch.tensor([[[-1.0, -1.0], [1.0, 0.0]]]), 9, 0.1)
    assert maps.shape == (1, 2, 9, 9)
    assert divmod(int(maps[0, 0].argmax()), 9) == (0, 0)  # (x, y) = (-1, -1): the top-left cell
    assert divmod(int(maps[0, 1].argmax()), 9) == (4, 8)  # (1, 0): the middle row's last cell
    assert float(maps.max()) == pytest.approx(1.0)


def test_the_keypoint_autoencoder_rebuilds_half_the_frame_and_learns(tmp_path, monkeypatch):
    import torch

    ns = probe("keypoint_autoencoder.py")
    model = ns["KeypointAutoencoder"](32, keypoints=4, stride=2)
    frames = torch.randint(0, 256, (6, 3, 32, 32), dtype=torch.uint8)
    assert model(frames[:3], frames[3:]).shape == (3, 3, 16, 16)
    assert model.points(frames).shape == (6, 4, 2)
    out = tmp_path / "ae"
    run("keypoint_autoencoder.py", monkeypatch, "--episodes", "8", "--steps", "3", "--batch-size", "4",
        "--pixel-size", "32", "--inverse-weight", "1", "--out", str(out))
    training = json.loads((out / "training.json").read_text())
    assert training["frames"] > 0 and np.isfinite(training["loss_last_100"])
    # a SAC run reads its keypoints, frozen, on the views it was trained on (32 px here)
    sac = tmp_path / "sac"
    run("push_pixel_sac.py", monkeypatch, "--steps", "400", "--envs", "2", "--batch-size", "8",
        "--learning-starts", "20", "--eval-every", "400", "--eval-episodes", "1", "--keypoints-from", str(out),
        "--out", str(sac))
    assert json.loads((sac / "summary.json").read_text())["gradient_steps"] > 0


def test_the_autoencoders_random_frames_pair_each_action_with_its_envs_next_frame():
    random_frames = probe("keypoint_autoencoder.py")["random_frames"]
    frames, episode, actions = random_frames(TrainConfig(goal="push_close", reward="oracle"), 4, 2, 0)
    assert len(frames) == len(episode) == len(actions) and actions.shape[1] == 2
    ends = np.isnan(actions).any(axis=1)
    assert ends[-2:].all()  # the last step of the envs' episodes leads to no frame of theirs
    valid = np.flatnonzero(~ends)
    assert np.all(episode[valid + 2] == episode[valid])  # the next frame (2 envs on) is the same episode's
    assert np.abs(actions[valid]).max() <= 1.0

"""The fast default of ``zsrm train``: shrunk policy views, the v1 preset behind the older
results, and the two benchmark scripts that measure it (no timed assertions)."""
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from zsrm.rl.config import PRESETS, TrainConfig, preset
from zsrm.rl.envs import make_vec
from zsrm.rl.features import FEATURES_KEY, IMAGE_KEY, check_view, policy_view
from zsrm.testing import ColourVLM

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
TINY = dict(n_envs=2, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=2, keypoints=4)


def v1_trials() -> list[Path]:
    return sorted((ROOT / "results" / "rl" / "v1" / "trials").glob("*.json"))


def test_v1_preset_is_the_configuration_of_the_older_committed_trials():
    trials = v1_trials()
    assert len(trials) >= 30
    for path in trials:
        committed = json.loads(path.read_text())["config"]
        for key, value in PRESETS["v1"].items():
            assert TrainConfig.from_dict(committed).__getattribute__(key) == value, (path.name, key)
        same = {k: committed[k] for k in ("goal", "reward", "seed", "steps", "reward_model", "vlm", "start")
                if k in committed}
        assert preset("v1", **same).to_dict() == committed, path.name


@pytest.mark.parametrize("folder, name", [("rl/v2/trials", "v2"), ("rl/trials", "cpu"), ("rl/trials", "v3")])
def test_presets_are_the_configurations_of_their_committed_trials(folder, name):
    """v2 (the default from 2026-12-04 to 2026-12-06) is the v2 sweeps' learner; the default is v3's."""
    trials = sorted((ROOT / "results" / folder).glob("*.json"))
    assert len(trials) >= 45
    for path in trials:
        committed = json.loads(path.read_text())["config"]
        same = {k: committed[k] for k in ("goal", "reward", "seed", "steps", "reward_model", "vlm", "start")
                if k in committed}
        assert preset(name, **same).to_dict() == committed, path.name


def test_the_commands_offer_every_preset_by_name():
    import typing

    from zsrm.rl.config import PresetName

    assert set(typing.get_args(PresetName)) == set(PRESETS)


def test_a_config_written_before_the_v3_default_reads_as_v2():
    old = preset("v2", goal="stack", reward="oracle")
    written = old.to_dict()
    assert "log_std_init" not in written  # as the v2 runs wrote it
    del written["eval_deterministic"]  # runs older still never wrote it
    assert TrainConfig.from_dict(written) == old
    new = TrainConfig(goal="stack", reward="oracle")
    assert (new.log_std_init, new.eval_deterministic) == (-1.0, True)
    assert TrainConfig.from_dict(new.to_dict()) == new


def test_default_differs_from_v1_and_an_old_run_reads_as_v1():
    new, old = TrainConfig(), preset("v1")
    assert (new.action_repeat, new.trunk_size, new.pixel_size) != (old.action_repeat, old.trunk_size, old.pixel_size)
    assert "trunk_size" not in old.to_dict() and "pixel_size" not in old.to_dict()  # older runs never wrote them
    assert TrainConfig.from_dict(old.to_dict()) == old
    assert TrainConfig.from_dict(new.to_dict()) == new


def test_policy_view_shrinks_the_frame_for_the_trunk_and_the_pixel_cnn():
    vlm = ColourVLM()
    for trunk, pixel in ((0, 0), (32, 32), (32, 16)):
        cfg = TrainConfig(goal="push_close", trunk_size=trunk, pixel_size=pixel, **TINY)
        venv = policy_view(make_vec(cfg, 2, 0), vlm, cfg)
        side = pixel or 64
        assert venv.observation_space[IMAGE_KEY].shape == (3, side, side)
        assert venv.observation_space.contains({k: v[0] for k, v in venv.reset().items()})
        frames = venv.venv.reset()[venv.camera]  # the camera's 64 px frames
        obs = venv.convert(frames)
        assert obs[IMAGE_KEY].shape == (2, 3, side, side) and obs[IMAGE_KEY].dtype == np.uint8
        k = 64 // side
        expected = frames.reshape(2, side, k, side, k, 3).mean(axis=(2, 4)).round().astype(np.uint8)
        np.testing.assert_array_equal(obs[IMAGE_KEY], expected.transpose(0, 3, 1, 2))
        venv.close()


def test_trunk_reads_the_shrunk_frame():
    from zsrm.vlm import load_vlm

    vlm = load_vlm("scene")
    cfg = TrainConfig(goal="stack", **TINY)
    full = policy_view(make_vec(TrainConfig(goal="stack", trunk_size=0, **TINY), 1, 0), vlm,
                       TrainConfig(goal="stack", trunk_size=0, **TINY))
    half = policy_view(make_vec(cfg, 1, 0), vlm, cfg)
    assert full.observation_space[FEATURES_KEY].shape[1:] == (16, 16)
    assert half.observation_space[FEATURES_KEY].shape[1:] == (8, 8)
    frame = full.venv.reset()[full.camera]
    pixels = torch.nn.functional.interpolate(vlm.preprocess(frame), size=32, mode="area")
    with torch.no_grad():
        np.testing.assert_allclose(half.features(frame), vlm.image_trunk(pixels).numpy(), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("size", [4, 24, 128])
def test_a_view_that_does_not_divide_the_camera_is_one_clear_error(size):
    with pytest.raises(ValueError, match="must be at least 8 and divide the camera's 64 px"):
        check_view(size, 64)


def test_train_config_rejects_a_bad_view_before_training(tmp_path):
    from zsrm.rl.ppo import train

    with pytest.raises(ValueError, match="divide the camera's 64 px"):
        train(TrainConfig(goal="push_close", reward="oracle", steps=128, pixel_size=24, **TINY), tmp_path,
              progress=False)


def test_profile_timers_count_exclusive_time_under_their_root(monkeypatch):
    import train_profile

    clock = iter(range(100))
    monkeypatch.setattr(train_profile.time, "perf_counter", lambda: next(clock))
    timers = train_profile.Timers()
    with timers.part("rollout_other"):          # t 0 .. 9
        with timers.part("scenes"):             # t 1 .. 2
            pass
        with timers.part("evaluation"):         # t 3 .. 8
            with timers.part("scenes"):         # t 4 .. 5
                pass
            with timers.part("vlm_trunk"):      # t 6 .. 7
                pass
    assert dict(timers.seconds) == {"scenes": 1, "evaluation/scenes": 1, "evaluation/vlm_trunk": 1,
                                    "evaluation": 3, "rollout_other": 9 - 1 - 5}


def test_profile_ladder_goes_from_v1_to_v2():
    import train_profile

    rungs = train_profile.ladder_settings()
    assert rungs[0][1] == PRESETS["v1"]
    assert TrainConfig(**rungs[-1][1]) == preset("v2")  # the last rung: v2, whose speed the default (v3) has


def test_profile_and_speed_benchmarks_run_a_tiny_train(tmp_path, monkeypatch):
    import ppo_speed
    import train_profile

    tiny = {**TINY, "eval_every": 128, "checkpoint_every": 128}
    monkeypatch.setitem(PRESETS, "tiny-new", tiny)
    monkeypatch.setitem(PRESETS, "tiny-old", {**PRESETS["v1"], **tiny})
    for reward in ("oracle", "curiosity"):
        run = train_profile.profile(tiny, reward, 256, "push_close")
        parts = run["seconds_per_10k_env_steps"]
        for part in ("scenes", "rendering", "vlm_trunk", "policy_forward", "inverse_dynamics", "evaluation",
                     "checkpoint", "update", "reward" if reward == "oracle" else "curiosity_update"):
            assert part in parts, part
        assert all(v >= 0 for v in parts.values()), parts
        assert {"vlm_keypoints/forward", "pixel_cnn/backward", "heads/forward"} <= set(run["update_by_network_per_10k_env_steps"])
        assert run["env_steps"] == 256 and run["ppo_updates"] >= 1
    out = tmp_path / "speed.json"
    result = ppo_speed.main(["--goal", "push_close", "--steps", "256", "--config", "tiny-new",
                             "--baseline", "tiny-old", "--out", str(out)])
    written = json.loads(out.read_text())
    assert written["speedup"] == pytest.approx(result["speedup"])
    assert written["speedup"] == pytest.approx(written["configs"]["tiny-new"]["train_steps_per_s"]
                                               / written["configs"]["tiny-old"]["train_steps_per_s"])
    assert written["env_fraction"] == pytest.approx(written["configs"]["tiny-new"]["env_fraction"])
    assert written["configs"]["tiny-old"]["train_config"]["action_repeat"] == 2


def test_profile_times_the_code_levers_against_the_simple_way():
    import train_profile

    levers = train_profile.micro(compile_extractor=False)
    assert len(levers) == 5 and all(v["simple_ms"] > 0 and v["fast_ms"] > 0 for v in levers.values())


@pytest.mark.parametrize("side", [32, 16, 64])
def test_shrunk_frames_are_the_bytes_of_the_numpy_block_mean(side):
    import train_profile
    from zsrm.rl.features import shrink_frames

    rng = np.random.default_rng(side)
    images = rng.integers(0, 256, (5, 64, 64, 3), dtype=np.uint8)
    images[:2] = rng.integers(0, 3, (2, 64, 64, 3), dtype=np.uint8) * 2 + 1  # many block means end in .5
    fast = shrink_frames(images, side)
    assert fast.dtype == np.uint8 and fast.shape == (5, 3, side, side) and fast.flags.c_contiguous
    np.testing.assert_array_equal(fast, train_profile.old_shrink_frames(images, side))


def test_a_batch_of_frames_is_preprocessed_as_its_frames_one_by_one():
    from zsrm.vlm.base import pixels_from_images

    images = np.random.default_rng(0).integers(0, 256, (4, 64, 64, 3), dtype=np.uint8)
    for size in (64, 32):
        batch = pixels_from_images(images, size, (0.5, 0.4, 0.3), (0.2, 0.3, 0.25))
        one_by_one = pixels_from_images(list(images), size, (0.5, 0.4, 0.3), (0.2, 0.3, 0.25))
        assert torch.equal(batch, one_by_one)
    with pytest.raises(ValueError, match="uint8"):
        pixels_from_images(images.astype(np.float32), 64, (0.5,) * 3, (0.2,) * 3)


def test_old_spatial_softmax_matches_the_fast_one():
    import train_profile
    from zsrm.rl.features import SpatialSoftmax

    softmax, maps = SpatialSoftmax(8, 8), torch.randn(4, 6, 8, 8)
    torch.testing.assert_close(softmax(maps), train_profile.old_spatial_softmax(softmax, maps), rtol=1e-5, atol=1e-5)


def test_a_policy_saved_before_the_views_existed_reads_64_px_views(tmp_path):
    from zsrm.rl.evaluate import rollout
    from zsrm.rl.policy import PolicyBundle
    from zsrm.rl.ppo import train

    cfg = preset("v1", goal="push_close", reward="oracle", steps=128, eval_every=128, checkpoint_every=128,
                 **{**TINY, "n_steps": 16})
    train(cfg, tmp_path, progress=False)
    saved = json.loads((tmp_path / "policy" / "config.json").read_text())["config"]
    assert "trunk_size" not in saved and "pixel_size" not in saved  # as every policy made before them
    bundle = PolicyBundle.load(tmp_path / "policy")
    assert (bundle.cfg.trunk_size, bundle.cfg.pixel_size) == (0, 0)
    assert bundle.policy.observation_space[FEATURES_KEY].shape[1:] == (16, 16)
    assert len(rollout(tmp_path / "policy", episodes=2)["episode_rewards"]) == 2


def test_a_run_records_its_seconds_and_a_sweep_adds_them_up(tmp_path):
    from zsrm.rl.ppo import train
    from zsrm.rl.sweep import core_hours

    summary = train(TrainConfig(goal="push_close", reward="oracle", steps=256, eval_every=128, checkpoint_every=128,
                                **TINY), tmp_path, progress=False)
    assert summary["wall_s"] >= summary["curve"][-1]["wall_s"] > 0
    older = {"curve": [{"wall_s": 7200.0}]}  # written before wall_s was recorded: its last evaluation's time
    assert core_hours([{"wall_s": 3600.0}, older, {"curve": []}]) == 3.0
    assert core_hours([tmp_path / "summary.json"]) == round(summary["wall_s"] / 3600, 2)


def test_a_flat_map_gives_keypoints_and_finite_gradients():
    from zsrm.rl.features import SpatialSoftmax

    softmax = SpatialSoftmax(8, 8)
    maps = torch.zeros(2, 3, 8, 8, requires_grad=True)  # a frame the trunk sees nothing in
    softmax(maps).sum().backward()
    assert torch.isfinite(maps.grad).all() and torch.isfinite(softmax.log_temperature.grad)


def test_an_evaluator_kept_for_a_run_plays_the_episodes_of_a_fresh_evaluation():
    from zsrm.rl.evaluate import Evaluator, evaluate

    cfg = TrainConfig(goal="stack", reward="oracle", **TINY)

    def recording(seen):
        def act(obs):  # acts on what it sees, and keeps it
            frames = next(iter(obs.values())).reshape(3, -1).astype(np.float64)
            seen.append(frames.mean(1))
            return np.tanh(frames[:, :3] / 64.0 - 2.0).astype(np.float32)
        return act

    seen_fresh, seen_first, seen_again = [], [], []
    fresh = evaluate(recording(seen_fresh), cfg, 3, seed=1)
    evaluator = Evaluator(cfg, 5, seed=1)  # built for 5 (the final evaluation), asked for the first 3
    try:
        first, again = evaluator(recording(seen_first), 3), evaluator(recording(seen_again), 3)
        assert len(evaluator(lambda obs: np.zeros((5, 3), np.float32))["episode_rewards"]) == 5
        with pytest.raises(ValueError, match="1 to 5 episodes"):
            evaluator(recording([]), 6)
    finally:
        evaluator.close()
    assert len(seen_fresh) == cfg.episode_decisions
    for result, seen in ((first, seen_first), (again, seen_again)):
        assert result["episode_rewards"] == fresh["episode_rewards"]
        assert np.array_equal(np.stack(seen), np.stack(seen_fresh))


def test_target_kl_reaches_ppo_and_is_off_unless_set():
    from zsrm.rl.ppo import build_ppo

    assert "target_kl" not in TrainConfig().to_dict()  # off: runs made before it existed keep their config
    cfg = TrainConfig(goal="stack", reward="oracle", target_kl=0.1, **TINY)
    assert cfg.to_dict()["target_kl"] == 0.1
    venv = policy_view(make_vec(cfg, cfg.n_envs, 0), ColourVLM(), cfg)
    try:
        assert build_ppo(cfg, venv).target_kl == 0.1
        assert build_ppo(TrainConfig(goal="stack", reward="oracle", **TINY), venv).target_kl is None
    finally:
        venv.close()
    with pytest.raises(ValueError, match="target_kl must be >= 0"):
        TrainConfig(target_kl=-1.0)


def test_anneal_lr_decays_the_learning_rate_to_zero_over_the_run():
    import pickle

    from zsrm.rl.ppo import build_ppo

    assert TrainConfig().to_dict()["anneal_lr"] is True  # the default since 2026-12-04, so written
    assert "anneal_lr" not in TrainConfig(anneal_lr=False).to_dict()  # off: older runs keep their config
    older = {k: v for k, v in TrainConfig(goal="stack").to_dict().items() if k != "anneal_lr"}
    assert TrainConfig.from_dict(older).anneal_lr is False  # a run made before it had a constant rate
    cfg = TrainConfig(goal="stack", reward="oracle", anneal_lr=True, learning_rate=1e-3, **TINY)
    venv = policy_view(make_vec(cfg, cfg.n_envs, 0), ColourVLM(), cfg)
    try:
        model = build_ppo(cfg, venv)
        schedule = pickle.loads(pickle.dumps(model.lr_schedule))
        assert schedule(1.0) == pytest.approx(1e-3) and schedule(0.25) == pytest.approx(2.5e-4)
        assert schedule(-0.01) == 0.0  # the last rollout may pass the run's steps: never a negative step
        from stable_baselines3.common.callbacks import BaseCallback

        seen = []

        class RecordLr(BaseCallback):
            def _on_rollout_start(self):
                seen.append(self.model.policy.optimizer.param_groups[0]["lr"])

            def _on_step(self):
                return True

        model.learn(4 * cfg.n_envs * cfg.n_steps, callback=RecordLr())
        seen.append(model.policy.optimizer.param_groups[0]["lr"])
        # each update takes the fraction of the run still to come after its rollout
        assert seen == pytest.approx([1e-3, 7.5e-4, 5e-4, 2.5e-4, 0.0])
        constant = build_ppo(TrainConfig(goal="stack", reward="oracle", learning_rate=1e-3, anneal_lr=False, **TINY), venv)
        assert constant.lr_schedule(0.1) == pytest.approx(1e-3)
    finally:
        venv.close()


def test_log_std_init_sets_the_first_action_noise_and_is_unwritten_at_its_old_value():
    from zsrm.rl.ppo import build_ppo

    assert "log_std_init" not in TrainConfig(log_std_init=0.0).to_dict()  # runs made before it keep their config
    cfg = TrainConfig(goal="stack", reward="oracle", log_std_init=-1.0, **TINY)
    assert cfg.to_dict()["log_std_init"] == -1.0
    venv = policy_view(make_vec(cfg, cfg.n_envs, 0), ColourVLM(), cfg)
    try:
        log_std = build_ppo(cfg, venv).policy.log_std.detach().numpy()
    finally:
        venv.close()
    assert log_std.shape == venv.action_space.shape and np.allclose(log_std, -1.0)

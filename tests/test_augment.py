"""Random shifts of the policy's pixel view and the DrAC regulariser built on them."""
import numpy as np
import pytest
import torch

from zsrm.rewards import OracleReward, VecZeroShotReward
from zsrm.rl.augment import ShiftRegulariser, random_shift
from zsrm.rl.config import TrainConfig
from zsrm.rl.envs import make_vec
from zsrm.rl.features import IMAGE_KEY, policy_view
from zsrm.rl.ppo import build_ppo
from zsrm.vlm import load_vlm


def test_each_shifted_frame_is_a_window_of_its_padded_frame():
    frames = torch.randint(0, 255, (6, 3, 8, 8)).float()
    pad = 2
    shifted = random_shift(frames, pad, torch.Generator().manual_seed(0))
    padded = torch.nn.functional.pad(frames, (pad,) * 4, mode="replicate")
    offsets = []
    for frame, out in zip(padded, shifted):
        found = [(dy, dx) for dy in range(2 * pad + 1) for dx in range(2 * pad + 1)
                 if out.equal(frame[:, dy:dy + 8, dx:dx + 8])]
        assert found, "not a window of the padded frame"
        offsets.append(found[0])
    assert len(set(offsets)) > 1  # each frame its own shift
    assert random_shift(frames, 0).equal(frames)
    assert random_shift(frames, pad, torch.Generator().manual_seed(0)).equal(shifted)  # seeded
    with pytest.raises(ValueError, match="pad must be >= 0"):
        random_shift(frames, -1)


def test_the_regulariser_pulls_the_policy_on_shifted_frames_towards_the_frames():
    torch.manual_seed(0)
    cfg = TrainConfig(goal="place_right", n_envs=2, n_steps=32, batch_size=32, keypoints=4, augment_shift=4)
    venv = VecZeroShotReward(make_vec(cfg, cfg.n_envs, 0), OracleReward(), "a yellow block on the right of a red block")
    model = build_ppo(cfg, policy_view(venv, load_vlm(cfg.vlm), cfg))
    regulariser = ShiftRegulariser(cfg.augment_shift, coef=1.0, lr=1e-3, batch_size=32, seed=0)
    model.learn(cfg.n_envs * cfg.n_steps, callback=regulariser)  # one rollout; then PPO's update
    buffer = model.rollout_buffer
    frames = {k: torch.as_tensor(v.reshape(-1, *model.observation_space[k].shape))
              for k, v in buffer.observations.items()}
    assert frames[IMAGE_KEY].dtype == torch.uint8

    def loss_on_fixed_shifts() -> float:
        regulariser.generator.manual_seed(123)
        with torch.no_grad():
            return regulariser.loss(frames).item()

    log_std = model.policy.log_std.detach().clone()
    before = loss_on_fixed_shifts()
    for _ in range(15):
        regulariser._on_rollout_end()
    assert loss_on_fixed_shifts() < 0.5 * before
    assert model.policy.log_std.equal(log_std)  # the action noise is PPO's alone
    venv.close()


def test_shifts_need_the_pixel_view():
    with pytest.raises(ValueError, match="augment_shift shifts the pixel view"):
        TrainConfig(goal="stack", pixels=False, augment_shift=2)
    assert "augment_shift" not in TrainConfig(goal="stack").to_dict()  # off: the runs before it
    assert np.isclose(ShiftRegulariser(2).coef, 0.1)  # DrAC's coefficient

"""A self-supervised auxiliary loss that teaches the policy's keypoints where the agent is.

The VLM's map locates the coloured objects, but not the gripper or the pusher, and the
sparse reward alone hardly trains the pixel CNN to find them: a policy that cannot see its
own effector learns one fixed motion (measured: the same action whatever the frame). An
inverse-dynamics model (as in ICM, Pathak et al. 2017) predicts the action taken between two
consecutive frames from their keypoints; its loss, back-propagated into the keypoint heads
after every rollout, makes some keypoints follow what the action moves. It uses only the
agent's own frames and actions: no state, no reward.
"""
from __future__ import annotations

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback
from torch import nn


class InverseDynamics(nn.Module):
    def __init__(self, points_dim: int, action_dim: int, hidden: int = 256):
        super().__init__()
        self.net = nn.Sequential(nn.Linear(2 * points_dim, hidden), nn.ReLU(), nn.Linear(hidden, action_dim))

    def forward(self, points: torch.Tensor, next_points: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([points, next_points], dim=1))


def env_groups(n_envs: int, n_steps: int, batch_size: int, rng: np.random.Generator) -> list[np.ndarray]:
    """The rollout's envs in random groups of about ``batch_size / n_steps`` envs each: one
    minibatch per group, whose frames each pass through the keypoints once.

    >>> [len(g) for g in env_groups(16, 32, 256, np.random.default_rng(0))]
    [8, 8]
    """
    return np.array_split(rng.permutation(n_envs), max(1, n_envs * n_steps // batch_size))


class InverseDynamicsAux(BaseCallback):
    """After each rollout (before PPO's update), train the policy's keypoint heads and an
    inverse-dynamics model on the rollout's consecutive frames.

    A minibatch is a group of envs' whole stretches of the rollout: each frame's keypoints are
    computed once and serve as the "after" of one transition and the "before" of the next
    (half the keypoint passes of sampling transitions one by one)."""

    def __init__(self, points_dim: int, action_dim: int, lr: float = 3e-4, epochs: int = 1, batch_size: int = 256,
                 seed: int = 0, device: str = "cpu"):
        super().__init__()
        torch.manual_seed(seed)
        self.device = torch.device(device)
        self.model_inverse = InverseDynamics(points_dim, action_dim).to(self.device)
        self.lr, self.epochs, self.batch_size = lr, epochs, batch_size
        self.rng = np.random.default_rng(seed)
        self.optimizer = None

    def _on_step(self) -> bool:
        return True

    def make_optimizer(self) -> torch.optim.Adam:
        if self.optimizer is None:
            extractor = self.model.policy.features_extractor
            self.optimizer = torch.optim.Adam([*extractor.parameters(), *self.model_inverse.parameters()], lr=self.lr)
        return self.optimizer

    def resume_state(self):
        """What exact resume keeps (:mod:`zsrm.rl.resume`): the minibatch order's generator and
        the optimiser (the head's weights are saved with the checkpoint's modules)."""
        return {"rng": self.rng.bit_generator.state}, {}, ({} if self.optimizer is None else {"inverse": self.optimizer})

    def load_resume_state(self, info: dict, arrays: dict) -> dict:
        from zsrm.rl.resume import generator_from

        self.rng = generator_from(info["rng"])
        return {"inverse": self.make_optimizer()}

    def _on_rollout_end(self) -> None:
        extractor = self.model.policy.features_extractor
        self.make_optimizer()
        buffer = self.model.rollout_buffer
        n_steps, n_envs = buffer.episode_starts.shape
        continues = torch.as_tensor(buffer.episode_starts[1:] == 0, device=self.device)  # t -> t + 1 in one episode
        low, high = self.model.action_space.low, self.model.action_space.high
        actions = torch.as_tensor(np.clip(buffer.actions[:-1], low, high), dtype=torch.float32, device=self.device)
        losses = []
        for _ in range(self.epochs):
            for group in env_groups(n_envs, n_steps, self.batch_size, self.rng):
                if not continues[:, group].any():
                    continue
                frames = {k: torch.as_tensor(v[:, group].reshape(n_steps * len(group), *v.shape[2:]), device=self.device)
                          for k, v in buffer.observations.items()}
                points = extractor.points(frames).reshape(n_steps, len(group), -1)
                mask = continues[:, group]
                predicted = self.model_inverse(points[:-1][mask], points[1:][mask])
                loss = (predicted - actions[:, group][mask]).pow(2).mean()
                self.optimizer.zero_grad()
                loss.backward()
                self.optimizer.step()
                losses.append(loss.item())
        if losses:
            self.logger.record("aux/inverse_dynamics_loss", float(np.mean(losses)))

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


def consecutive_pairs(episode_starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices (step, env) of the buffer's transitions t -> t + 1 inside one episode.

    >>> steps, envs = consecutive_pairs(np.array([[1, 1], [0, 0], [1, 0]]))
    >>> list(zip(steps.tolist(), envs.tolist()))
    [(0, 0), (0, 1), (1, 1)]
    """
    valid = episode_starts[1:] == 0  # step t + 1 continues the episode of step t
    steps, envs = np.nonzero(valid)
    return steps, envs


class InverseDynamicsAux(BaseCallback):
    """After each rollout (before PPO's update), train the policy's keypoint heads and an
    inverse-dynamics model on the rollout's consecutive frames."""

    def __init__(self, points_dim: int, action_dim: int, lr: float = 3e-4, epochs: int = 1, batch_size: int = 256,
                 seed: int = 0, device: str = "cpu"):
        super().__init__()
        torch.manual_seed(seed)
        self.device = torch.device(device)
        self.model_inverse = InverseDynamics(points_dim, action_dim).to(self.device)
        self.lr, self.epochs, self.batch_size = lr, epochs, batch_size
        self.optimizer = None

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        extractor = self.model.policy.features_extractor
        if self.optimizer is None:
            self.optimizer = torch.optim.Adam([*extractor.parameters(), *self.model_inverse.parameters()], lr=self.lr)
        buffer = self.model.rollout_buffer
        steps, envs = consecutive_pairs(buffer.episode_starts)
        low, high = self.model.action_space.low, self.model.action_space.high
        actions = torch.as_tensor(np.clip(buffer.actions[steps, envs], low, high), dtype=torch.float32,
                                  device=self.device)
        losses = []
        for _ in range(self.epochs):
            for idx in np.array_split(np.random.permutation(len(steps)), max(1, len(steps) // self.batch_size)):
                now = {k: torch.as_tensor(v[steps[idx], envs[idx]], device=self.device)
                       for k, v in buffer.observations.items()}
                nxt = {k: torch.as_tensor(v[steps[idx] + 1, envs[idx]], device=self.device)
                       for k, v in buffer.observations.items()}
                predicted = self.model_inverse(extractor.points(now), extractor.points(nxt))
                loss = (predicted - actions[idx]).pow(2).mean()
                self.optimizer.zero_grad()
                loss.backward()
                self.optimizer.step()
                losses.append(loss.item())
        if losses:
            self.logger.record("aux/inverse_dynamics_loss", float(np.mean(losses)))

"""The curiosity baseline: ICM (Pathak et al. 2017), intrinsic reward only, no goal.

Features ``phi`` of the goal camera's frame come from a small CNN trained, with an inverse
model, to predict the action between two frames (so they keep what the agent controls); a
forward model predicts ``phi(s')`` from ``phi(s)`` and the action, and its error is the reward:

    r = eta * 0.5 * ||f(phi(s), a) - phi(s')||^2   (then divided by a running std)

:class:`VecCuriosity` computes it for all envs in one batch and keeps the transitions;
:class:`ICMUpdate`, a stable-baselines3 callback, trains ICM on them after every rollout, while
the policy trains.
"""
from __future__ import annotations

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from torch import nn


class ICM(nn.Module):
    def __init__(self, action_dim: int, feature_dim: int = 128, image_size: int = 64, beta: float = 0.2):
        super().__init__()
        side = image_size // 8
        self.encoder = nn.Sequential(
            nn.Conv2d(3, 32, 3, 2, 1), nn.ELU(), nn.Conv2d(32, 32, 3, 2, 1), nn.ELU(),
            nn.Conv2d(32, 32, 3, 2, 1), nn.ELU(), nn.Flatten(), nn.Linear(32 * side * side, feature_dim))
        self.inverse = nn.Sequential(nn.Linear(2 * feature_dim, 256), nn.ReLU(), nn.Linear(256, action_dim))
        self.forward_model = nn.Sequential(nn.Linear(feature_dim + action_dim, 256), nn.ReLU(),
                                           nn.Linear(256, feature_dim))
        self.beta = beta  # weight of the forward loss against the inverse loss (the paper's 0.2)

    def features(self, images: np.ndarray | torch.Tensor) -> torch.Tensor:
        x = torch.as_tensor(np.ascontiguousarray(images)).permute(0, 3, 1, 2).float() / 255.0
        return self.encoder(x)

    def losses(self, obs, actions, next_obs) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-sample forward error (N,) and the mean inverse-model loss."""
        phi, phi_next = self.features(obs), self.features(next_obs)
        a = torch.as_tensor(actions, dtype=torch.float32)
        predicted = self.forward_model(torch.cat([phi, a], dim=1))
        forward_error = 0.5 * (predicted - phi_next.detach()).pow(2).sum(dim=1)
        inverse_loss = (self.inverse(torch.cat([phi, phi_next], dim=1)) - a).pow(2).mean()
        return forward_error, inverse_loss


class VecCuriosity(VecEnvWrapper):
    """Replace the env reward by ICM's intrinsic reward, computed in one batch per step."""

    def __init__(self, venv: VecEnv, camera: str, eta: float = 1.0, lr: float = 1e-3, seed: int = 0):
        super().__init__(venv)
        torch.manual_seed(seed)
        size = venv.observation_space[camera].shape[0]
        self.icm = ICM(venv.action_space.shape[0], image_size=size)
        self.optimizer = torch.optim.Adam(self.icm.parameters(), lr=lr)
        self.camera, self.eta = camera, eta
        self.transitions: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._obs = self._actions = None
        self._count, self._mean, self._m2 = 0, 0.0, 0.0  # running std of the raw reward (Welford)

    def reset(self):
        obs = self.venv.reset()
        self._obs = np.array(obs[self.camera])
        return obs

    def step_async(self, actions):
        self._actions = np.asarray(actions, np.float32).copy()
        self.venv.step_async(actions)

    def step_wait(self):
        obs, _, dones, infos = self.venv.step_wait()
        next_frames = np.array(obs[self.camera])
        for i in np.flatnonzero(dones):  # the episode's last frame, not the next one's first
            next_frames[i] = infos[i]["terminal_observation"][self.camera]
        with torch.no_grad():
            error, _ = self.icm.losses(self._obs, self._actions, next_frames)
        raw = self.eta * error.numpy()
        self.transitions.append((self._obs, self._actions, next_frames))
        self._obs = np.array(obs[self.camera])
        rewards = (raw / self._running_std(raw)).astype(np.float32)
        for info, r in zip(infos, rewards):
            info["curiosity_reward"] = float(r)
        return obs, rewards, dones, infos

    def _running_std(self, values: np.ndarray) -> float:
        for v in values:
            self._count += 1
            delta = v - self._mean
            self._mean += delta / self._count
            self._m2 += delta * (v - self._mean)
        return float(np.sqrt(self._m2 / self._count)) + 1e-8 if self._count > 1 else 1.0

    def resume_state(self):
        """What exact resume keeps (:mod:`zsrm.rl.resume`), saved between rollouts (when no
        transitions wait): the reward scale, the last frames and the optimiser (ICM's weights
        are saved with the checkpoint's modules)."""
        if self.transitions:
            raise RuntimeError("ICM's state is saved between rollouts, after its update")
        # the running sums keep their type (a float32 sum stays float32, a Python float a float)
        kinds = {k: "float" if isinstance(getattr(self, k), float) else np.asarray(getattr(self, k)).dtype.name
                 for k in ("_mean", "_m2")}
        return ({"count": self._count, "kinds": kinds}, {"obs": self._obs, "mean": np.asarray([self._mean]),
                                                          "m2": np.asarray([self._m2])}, {"icm": self.optimizer})

    def load_resume_state(self, info: dict, arrays: dict) -> dict:
        self._count = int(info["count"])
        for key, name in (("mean", "_mean"), ("m2", "_m2")):
            kind = info["kinds"][name]
            value = arrays[key].astype(np.float64 if kind == "float" else kind)[0]
            setattr(self, name, float(value) if kind == "float" else value)
        self._obs = arrays["obs"]
        return {"icm": self.optimizer}

    def update(self, epochs: int = 2, batch_size: int = 128) -> dict:
        """Train ICM on the kept transitions (then drop them); returns the mean losses."""
        if not self.transitions:
            return {}
        obs, actions, next_obs = (np.concatenate(x) for x in zip(*self.transitions))
        self.transitions = []
        forward_sum = inverse_sum = 0.0
        batches = 0
        for _ in range(epochs):
            for idx in np.array_split(np.random.permutation(len(obs)), max(1, len(obs) // batch_size)):
                forward_error, inverse_loss = self.icm.losses(obs[idx], actions[idx], next_obs[idx])
                loss = self.icm.beta * forward_error.mean() + (1 - self.icm.beta) * inverse_loss
                self.optimizer.zero_grad()
                loss.backward()
                self.optimizer.step()
                forward_sum, inverse_sum, batches = forward_sum + forward_error.mean().item(), inverse_sum + inverse_loss.item(), batches + 1
        return {"forward_loss": forward_sum / batches, "inverse_loss": inverse_sum / batches}


class ICMUpdate(BaseCallback):
    """Train ICM on each rollout's transitions as soon as the rollout ends."""

    def __init__(self, curiosity: VecCuriosity):
        super().__init__()
        self.curiosity = curiosity

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        for key, value in self.curiosity.update().items():
            self.logger.record(f"icm/{key}", value)

"""Random shifts of the policy's frames, as a regulariser of PPO (DrAC, Raileanu et al. 2021).

DrQ (Kostrikov et al. 2021) trains off-policy learners on randomly shifted frames. PPO cannot
simply train on shifted frames: its ratio compares the policy on the frames it acted on with
the rollout's log-probabilities. DrAC keeps PPO's loss and adds two terms that ask the policy
and the value to read a shifted frame as they read the frame itself; here they are minimised
after each rollout, before PPO's update, as the inverse-dynamics loss is
(:mod:`zsrm.rl.auxiliary`). Only the pixel CNN's view is shifted: the frozen VLM trunk's map
is computed outside the policy, once per frame.
"""
from __future__ import annotations

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback
from torch.distributions import kl_divergence

from zsrm.rl.features import IMAGE_KEY


def random_shift(images: torch.Tensor, pad: int, generator: torch.Generator | None = None) -> torch.Tensor:
    """Each ``(C, H, W)`` frame of ``images`` moved by its own whole-pixel shift of at most ``pad``
    in x and y, the border repeated into the gap (DrQ's augmentation).

    >>> frames = torch.arange(16.).reshape(1, 1, 4, 4)
    >>> random_shift(frames, 0).equal(frames)
    True
    >>> random_shift(frames, 1, torch.Generator().manual_seed(0)).shape
    torch.Size([1, 1, 4, 4])
    """
    if pad < 0:
        raise ValueError(f"a shift's pad must be >= 0, got {pad}")
    if pad == 0:
        return images
    n, c, h, w = images.shape
    padded = torch.nn.functional.pad(images.float(), (pad, pad, pad, pad), mode="replicate")
    dy, dx = torch.randint(0, 2 * pad + 1, (2, n, 1), generator=generator)
    rows = (torch.arange(h) + dy)[:, None, :, None]  # (n, 1, h, 1)
    cols = (torch.arange(w) + dx)[:, None, None, :]  # (n, 1, 1, w)
    return padded[torch.arange(n)[:, None, None, None], torch.arange(c)[None, :, None, None], rows, cols]


class ShiftRegulariser(BaseCallback):
    """After each rollout, ``epochs`` passes over its frames in minibatches: the policy's action
    distribution and value on shifted frames are pulled towards theirs on the frames themselves
    (held fixed), ``coef * (KL(pi(s) || pi(shift(s))) + (V(s) - V(shift(s)))^2 / 2)``."""

    def __init__(self, pad: int, coef: float = 0.1, lr: float = 3e-4, epochs: int = 1, batch_size: int = 256,
                 seed: int = 0):
        super().__init__()
        if pad < 1 or coef <= 0:
            raise ValueError(f"pad must be >= 1 and coef > 0, got {pad} and {coef}")
        self.pad, self.coef, self.lr, self.epochs, self.batch_size = int(pad), float(coef), lr, epochs, batch_size
        self.rng = np.random.default_rng(seed)
        self.generator = torch.Generator().manual_seed(seed)
        self.optimizer = None

    def _on_step(self) -> bool:
        return True

    def make_optimizer(self) -> torch.optim.Adam:
        if self.optimizer is None:
            # not the action noise: the KL between two Gaussians of one width would widen it
            params = [p for name, p in self.model.policy.named_parameters() if name != "log_std"]
            self.optimizer = torch.optim.Adam(params, lr=self.lr)
        return self.optimizer

    def resume_state(self):
        """What exact resume keeps (:mod:`zsrm.rl.resume`): both generators and the optimiser."""
        info = {"rng": self.rng.bit_generator.state}
        return info, {"generator": self.generator.get_state().numpy()}, (
            {} if self.optimizer is None else {"shift": self.optimizer})

    def load_resume_state(self, info: dict, arrays: dict) -> dict:
        from zsrm.rl.resume import generator_from

        self.rng = generator_from(info["rng"])
        self.generator.set_state(torch.as_tensor(arrays["generator"], dtype=torch.uint8))
        return {"shift": self.make_optimizer()}

    def loss(self, observations: dict) -> torch.Tensor:
        policy = self.model.policy
        with torch.no_grad():
            target = policy.get_distribution(observations).distribution
            value = policy.predict_values(observations)
        shifted = {**observations, IMAGE_KEY: random_shift(observations[IMAGE_KEY], self.pad, self.generator)}
        moved = policy.get_distribution(shifted).distribution
        kl = kl_divergence(target, moved).sum(-1).mean()
        return self.coef * (kl + 0.5 * (value - policy.predict_values(shifted)).pow(2).mean())

    def _on_rollout_end(self) -> None:
        self.make_optimizer()
        buffer = self.model.rollout_buffer
        space = self.model.observation_space  # the buffer's (steps, envs, ...), or flat after PPO's update
        flat = {k: v.reshape(-1, *space[k].shape) for k, v in buffer.observations.items()}
        total, device, losses = len(next(iter(flat.values()))), self.model.policy.device, []
        for _ in range(self.epochs):
            for batch in np.array_split(self.rng.permutation(total), max(1, total // self.batch_size)):
                loss = self.loss({k: torch.as_tensor(v[batch], device=device) for k, v in flat.items()})
                self.optimizer.zero_grad()
                loss.backward()
                self.optimizer.step()
                losses.append(loss.item())
        self.logger.record("aux/shift_loss", float(np.mean(losses)))

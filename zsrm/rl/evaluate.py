"""The oracle metric of a policy on separate evaluation envs with their own seeds, and
``zsrm rollout`` (a saved or random policy, with a GIF of its first episode).

The oracle episode reward is the number of the episode's 100 control steps in which the goal
relation holds (paper 3.2): it reads the true state and is used for evaluation only. For the
double pendulum (Figure 4) it is the oracle episode return: the sum of gymnasium's reward
(alive bonus 10 minus distance and velocity penalties, about 9.35 per upright step) over an
episode of at most 100 control steps (0.05 s each; :data:`zsrm.rl.envs.EPISODE_STEPS`, the same
cap as the other scenes), which ends earlier when the pendulum falls: at most about 935.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from zsrm.common.files import atomic_path
from zsrm.envs.rollout import run_vec_episodes
from zsrm.rl.config import TrainConfig
from zsrm.rl.envs import make_vec
from zsrm.rl.goals import goal_camera, is_pendulum

EVAL_SEED = 1_000_000  # evaluation envs: seeds far from the training envs'


def eval_seed(seed: int) -> int:
    return EVAL_SEED + 1000 * seed


def mean_se(values) -> tuple[float, float]:
    """Mean and standard error of the mean (0 for a single value)."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return float("nan"), float("nan")
    se = v.std(ddof=1) / np.sqrt(v.size) if v.size > 1 else 0.0
    return float(v.mean()), float(se)


def mean_se_cell(values) -> dict:
    """``{"mean", "se", "episodes"}`` of one table cell's episode values."""
    mean, se = mean_se(values)
    return {"mean": mean, "se": se, "episodes": len(values)}


def evaluate(act, cfg: TrainConfig, episodes: int, seed: int, spread: str = "seen", wrap=None) -> dict:
    """Mean and standard error of the oracle episode reward over ``episodes`` seeded episodes,
    one env each. ``wrap`` turns the image VecEnv into what ``act`` reads (e.g.
    :func:`~zsrm.rl.features.policy_view`)."""
    evaluator = Evaluator(cfg, episodes, seed, spread, wrap)
    try:
        return evaluator(act)
    finally:
        evaluator.close()


class Evaluator:
    """:func:`evaluate` on envs built once (at the first call) and reseeded before each call, so
    every call plays the same seeded episodes as a fresh :func:`evaluate`. A call may ask for
    fewer episodes than the envs built: it plays the first ones (seeded as make_vec seeds them).
    Training evaluates every ``eval_every`` steps and at the end: building the scenes' renderers
    each time cost more than playing."""

    def __init__(self, cfg: TrainConfig, episodes: int, seed: int, spread: str = "seen", wrap=None):
        self.cfg, self.episodes, self.seed, self.spread, self.wrap = cfg, episodes, eval_seed(seed), spread, wrap
        self.views: dict[int, object] = {}  # episodes -> the (wrapped) VecEnv of the first that many envs

    def venv(self, episodes: int):
        if episodes not in self.views:
            if not 1 <= episodes <= self.episodes:
                raise ValueError(f"this evaluator plays 1 to {self.episodes} episodes, not {episodes}")
            if self.episodes not in self.views:
                full = make_vec(self.cfg, self.episodes, self.seed, self.spread)
                self.views[self.episodes] = self.wrap(full) if self.wrap else full
            if episodes != self.episodes:
                from stable_baselines3.common.vec_env import DummyVecEnv

                envs = self.views[self.episodes].unwrapped.envs[:episodes]
                first = DummyVecEnv([lambda env=env: env for env in envs])
                self.views[episodes] = self.wrap(first) if self.wrap else first
        return self.views[episodes]

    def __call__(self, act, episodes: int | None = None) -> dict:
        venv = self.venv(episodes or self.episodes)
        venv.seed(self.seed)  # the next reset seeds every env as make_vec did
        key = "oracle_reward" if is_pendulum(self.cfg.goal, self.cfg.scene) else "oracle_steps"
        out = run_vec_episodes(venv, act, key=key)
        mean, se = mean_se(out["episode_rewards"])
        return {"mean": mean, "se": se, "success_rate": float(np.mean(out["successes"])), **out}

    def close(self) -> None:
        if self.episodes in self.views:  # the first-n views share its envs
            self.views[self.episodes].close()
        self.views = {}


def random_actions(action_space, seed: int) -> Callable[[dict], np.ndarray]:
    """A uniform random policy over the action box (the `random` baseline)."""
    rng = np.random.default_rng(seed)

    def act(obs):
        n = len(next(iter(obs.values())))
        return rng.uniform(action_space.low, action_space.high, (n, *action_space.shape)).astype(np.float32)

    return act


def rollout(policy: str | Path, episodes: int = 10, seed: int = 0, spread: str = "seen",
            gif: str | Path | None = None, scene: str | None = None, deterministic: bool | None = None) -> dict:
    """The oracle episode reward of a saved policy (a folder written by ``zsrm train``) or of
    ``"random:GOAL"`` (on your own ``scene`` when given) over seeded episodes; with ``gif``, a
    GIF of the first episode. ``deterministic``: play the policy's mean action (True) or sample
    it (False); None: as its run evaluated it (``eval_deterministic``)."""
    from zsrm.rl.features import policy_view
    from zsrm.rl.policy import load_policy
    from zsrm.vlm import load_vlm

    if isinstance(policy, str) and policy.startswith("random:"):
        cfg = TrainConfig(goal=policy.split(":", 1)[1], reward="random", scene=scene)
        probe = make_vec(cfg, 1, 0)
        act, features = random_actions(probe.action_space, seed), None
        probe.close()
    else:
        if scene:
            raise ValueError("--scene is for random:GOAL; a trained policy's folder names its scene")
        bundle = load_policy(policy)
        cfg, vlm = bundle.cfg, load_vlm(bundle.cfg.vlm)

        mean_action = cfg.eval_deterministic if deterministic is None else deterministic

        def act(obs):
            return bundle.act(obs, deterministic=mean_action)

        def features(venv):
            return policy_view(venv, vlm, cfg)

    import torch

    torch.manual_seed(eval_seed(seed))  # a policy that samples its actions: same seed, same episodes
    frames = []
    if gif:
        record = FirstEpisodeFrames(goal_camera(cfg.goal, cfg.scene), frames)
        wrap = (lambda v: features(record.wrap(v))) if features else record.wrap
    else:
        wrap = features
    result = evaluate(act, cfg, episodes, seed, spread, wrap=wrap)
    if gif:
        write_gif(frames, gif)
        result["gif"] = str(gif)
    return result


class FirstEpisodeFrames:
    """Keeps the camera frames of the first env's first episode of a VecEnv it wraps."""

    def __init__(self, camera: str, frames: list):
        self.camera, self.frames, self.done = camera, frames, False

    def wrap(self, venv):
        from stable_baselines3.common.vec_env import VecEnvWrapper

        keep = self

        class Record(VecEnvWrapper):
            def reset(self):
                obs = self.venv.reset()
                keep.frames.append(np.array(obs[keep.camera][0]))
                return obs

            def step_wait(self):
                obs, rewards, dones, infos = self.venv.step_wait()
                if not keep.done:  # a done env's last frame is its terminal observation (not batched)
                    last = infos[0]["terminal_observation"][keep.camera] if dones[0] else obs[keep.camera][0]
                    keep.frames.append(np.array(last))
                    keep.done = bool(dones[0])
                return obs, rewards, dones, infos

        return Record(venv)


def write_gif(frames: list[np.ndarray], path: str | Path, scale: int = 3) -> Path:
    import imageio.v3 as iio

    with atomic_path(path) as tmp:
        iio.imwrite(tmp, np.stack([np.kron(f, np.ones((scale, scale, 1), np.uint8)) for f in frames]),
                    duration=80, loop=0)
    return Path(path)

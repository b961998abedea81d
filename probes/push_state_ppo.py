"""Is push_close's ceiling the learner or the policy's vision? PPO on TRUE state, here only.

The pixel policy's oracle run stops near success 0.3 (docs/training.md). This probe trains the
same PPO (v3's settings: 16 envs, 32-step rollouts, gamma 0.96, lambda 0.9, action noise 0.37,
learning rate annealed, action repeat 4) on the pusher's and both pucks' table positions instead
of frames, with the oracle's steps in the goal as reward, and evaluates the mean action on 30
seeded episodes. Near 0.3 here too: the learner (its budget, horizon, exploration) is the limit;
near 1: what the policy sees is. Nothing here reaches a zsrm run: state stays in this probe.

    python probes/push_state_ppo.py --steps 300000 --seeds 0 1 2 --out results/side/rl/push_state_ppo.json
"""
from __future__ import annotations

import argparse
import os
import time
from dataclasses import asdict, dataclass

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from stable_baselines3 import PPO, SAC  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv  # noqa: E402

import zsrm.envs  # noqa: E402,F401
from zsrm.common.files import write_json  # noqa: E402
from zsrm.envs import EPISODE_STEPS  # noqa: E402
from zsrm.pipeline.learn import parse_settings  # noqa: E402
from zsrm.rl.config import TrainConfig  # noqa: E402


@dataclass
class Probe:
    """What this probe changes beside PPO's settings (each off by default: v3's PPO on the positions)."""

    observe: str = "positions"
    """positions: the pusher's and both pucks' (x, y); relative: the puck from the pusher and the other puck
    from the puck (what the scripted controller reads); pairs: the positions and every pair's difference"""
    scale: float = 0.3
    """metres an observed unit is (0.3: about the table's half width)"""
    learner: str = "ppo"
    """ppo, or sac: stable-baselines3's SAC (off-policy, its defaults but the discount, one env)"""
    sde_every: int = 0
    """PPO with generalised state-dependent exploration, its noise drawn anew every this many decisions"""
    aligned: float = 0.0
    """the fraction of training episodes whose pusher starts level with its puck (a curriculum)"""
    noise_end: float | None = None
    """hold the policy's log std under a ceiling falling linearly to this over the run"""
    sac_envs: int = 1
    """SAC's envs, stepped together (one gradient step a step of them all: 1 / sac_envs per decision)"""
    sac_gradient_steps: int = 1
    """SAC's gradient steps per step of its envs"""
    noise: float = 0.0
    """metres of Gaussian noise on each observed (x, y), drawn anew each step: how exact a view
    of the scene the learner needs (a keypoint's error stands in here)"""


class StateView(gym.Wrapper):
    """The state :class:`Probe` names as the observation, the oracle's steps in the goal as reward;
    the camera is never rendered (the scene's observation is swapped for a blank frame)."""

    def __init__(self, env, probe: Probe, seed: int, training: bool):
        super().__init__(env)
        self.probe, self.rng = probe, np.random.default_rng(seed)
        self.aligned = probe.aligned if training else 0.0
        scene = env.unwrapped
        blank = {c: np.zeros(space.shape, space.dtype) for c, space in scene.observation_space.spaces.items()}
        scene._observation = lambda: {c: a.copy() for c, a in blank.items()}
        self.objects = scene.task.objects[:2]
        width = {"positions": 6, "relative": 4, "pairs": 12}[probe.observe]
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (width,), np.float32)

    def state(self, info) -> np.ndarray:
        pusher, puck, other = self.env.unwrapped.pusher_position[:2], *(info["object_positions"][c][:2] for c in self.objects)
        if self.probe.noise:
            pusher, puck, other = (p + self.rng.normal(0.0, self.probe.noise, 2) for p in (pusher, puck, other))
        points = [pusher, puck, other]
        if self.probe.observe == "relative":
            points = [puck - pusher, other - puck]
        elif self.probe.observe == "pairs":
            points += [b - a for i, a in enumerate(points) for b in points[i + 1:]]
        return np.concatenate(points).astype(np.float32) / self.probe.scale

    def reset(self, **kwargs):
        _, info = self.env.reset(**kwargs)
        if self.aligned and self.rng.random() < self.aligned:
            scene = self.env.unwrapped
            y = info["object_positions"][self.objects[0]][1]
            scene.data.mocap_pos[scene._mocap][1] = y
            scene.data.qpos[scene._pusher_qadr + 1] = y
            mujoco.mj_forward(scene.model, scene.data)
        return self.state(info), info

    def step(self, action):
        _, _, terminated, truncated, info = self.env.step(action)
        return self.state(info), float(info["oracle_steps"]), terminated, truncated, info


def make_env(cfg: TrainConfig, probe: Probe, seed: int, training: bool = False):
    near = {"near_start": cfg.near_start} if cfg.near_start and training else {}  # evaluation keeps 1.7
    env = gym.make("zsrm/Pushing-v0", task=cfg.goal, image_size=16, action_repeat=cfg.action_repeat,
                   max_episode_steps=EPISODE_STEPS // cfg.action_repeat, **near)
    env = StateView(env, probe, seed, training)
    env.reset(seed=seed)
    return env


def evaluate(model, cfg: TrainConfig, probe: Probe, episodes: int, seed: int) -> tuple[float, float]:
    """The mean action's oracle episode reward and final success rate over seeded episodes."""
    env = make_env(cfg, probe, seed)
    totals, successes = [], []
    for e in range(episodes):
        obs, _ = env.reset(seed=seed + e)
        done, total, info = False, 0.0, {}
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, info = env.step(action)
            total, done = total + reward, terminated or truncated
        totals.append(total)
        successes.append(bool(info["is_success"]))
    return float(np.mean(totals)), float(np.mean(successes))


def build(cfg: TrainConfig, probe: Probe, venv):
    if probe.learner == "sac":
        return SAC("MlpPolicy", venv, gamma=cfg.gamma, seed=cfg.seed, verbose=0,
                   gradient_steps=probe.sac_gradient_steps)
    lr = (lambda f: f * cfg.learning_rate) if cfg.anneal_lr else cfg.learning_rate
    return PPO("MlpPolicy", venv, n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.n_epochs,
               learning_rate=lr, gamma=cfg.gamma, gae_lambda=cfg.gae_lambda, ent_coef=cfg.ent_coef,
               clip_range=cfg.clip_range, policy_kwargs={"log_std_init": cfg.log_std_init}, seed=cfg.seed,
               verbose=0, use_sde=bool(probe.sde_every), sde_sample_freq=probe.sde_every)


def train(cfg: TrainConfig, probe: Probe, episodes: int) -> dict:
    torch.manual_seed(cfg.seed)
    n_envs = cfg.n_envs if probe.learner == "ppo" else probe.sac_envs
    venv = DummyVecEnv([lambda i=i: make_env(cfg, probe, 1000 * cfg.seed + i, True) for i in range(n_envs)])
    start = time.time()
    model = build(cfg, probe, venv)
    schedule = NoiseCeiling(probe.noise_end) if probe.noise_end is not None and probe.learner == "ppo" else None
    model.learn(cfg.steps // cfg.action_repeat, callback=schedule)
    final_mean, success = evaluate(model, cfg, probe, episodes, 10_000 + cfg.seed)
    std = model.policy.log_std.exp().mean().item() if probe.learner == "ppo" and not probe.sde_every else None
    return {"seed": cfg.seed, "final_mean": final_mean, "final_success_rate": success,
            "wall_s": time.time() - start, "final_action_std": std}


class NoiseCeiling(BaseCallback):
    """The policy's log standard deviation held at most at a ceiling that falls linearly from its
    start value to ``end`` over the run (an exploration schedule)."""

    def __init__(self, end: float):
        super().__init__()
        self.end, self.start = end, None

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        log_std = self.model.policy.log_std
        if self.start is None:
            self.start = log_std.max().item()
        progress = 1.0 - self.model._current_progress_remaining
        with torch.no_grad():
            log_std.clamp_(max=self.start + progress * (self.end - self.start))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--goal", default="push_close")
    p.add_argument("--steps", type=int, default=300_000, help="env (control) steps per seed")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--episodes", type=int, default=30)
    p.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE",
                   help="PPO settings other than v3's, as zsrm train's (gamma=0.99 action_repeat=2 ...)")
    p.add_argument("--observe", choices=("positions", "relative", "pairs"), default="positions")
    p.add_argument("--scale", type=float, default=0.3, help="metres an observed unit is")
    p.add_argument("--learner", choices=("ppo", "sac"), default="ppo")
    p.add_argument("--sde-every", type=int, default=0)
    p.add_argument("--aligned", type=float, default=0.0)
    p.add_argument("--noise-end", type=float, default=None)
    p.add_argument("--noise", type=float, default=0.0, help="metres of Gaussian noise on each observed position")
    p.add_argument("--sac-envs", type=int, default=1, help="SAC's envs, stepped together")
    p.add_argument("--sac-gradient-steps", type=int, default=1, help="SAC's gradient steps per step of its envs")
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    probe = Probe(args.observe, args.scale, args.learner, args.sde_every, args.aligned, args.noise_end,
                  args.sac_envs, args.sac_gradient_steps, args.noise)
    overrides = parse_settings(args.set)
    trials = [train(TrainConfig(goal=args.goal, reward="oracle", steps=args.steps, seed=s, **overrides), probe,
                    args.episodes) for s in args.seeds]
    for t in trials:
        print(f"seed {t['seed']}: {t['final_mean']:.1f}, success {t['final_success_rate']:.2f} ({t['wall_s']:.0f} s)")
    means = np.array([t["final_mean"] for t in trials])
    write_json(args.out, {
        "trials": trials, "final_mean": float(means.mean()),
        "final_mean_se": float(means.std(ddof=1) / np.sqrt(len(means))) if len(means) > 1 else None,
        "final_success_rate": float(np.mean([t["final_success_rate"] for t in trials])),
        "meta": {"observation": "true state: a probe, never a zsrm input", "probe": asdict(probe),
                 "settings": overrides or "v3", "steps": args.steps, "machine": "x86_64, 2 cores, no GPU",
                 "command": "python probes/push_state_ppo.py " + " ".join(argv or [])}})


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])

"""Where ``zsrm train``'s time goes: seconds per 10k env steps of each part of the loop.

Runs :func:`zsrm.rl.ppo.train` itself (rollouts, reward, PPO update, auxiliary loss,
evaluation, checkpoints) for each named configuration, with timers around its parts
(exclusive time: a part's time excludes the parts timed inside it):

* ``scenes`` physics and SB3's VecEnv (``rendering`` apart), ``vlm_trunk`` the frozen VLM
  trunk on each frame, ``reward`` the reward model, ``policy_forward`` the policy's action
  during rollouts, ``rollout_other`` SB3's rollout bookkeeping;
* ``update`` PPO's epochs, split per network (``update/<network>/forward`` and ``/backward``,
  timed on the run's own last rollout buffer, minibatch by minibatch as PPO does, and scaled
  to the run's updates) and ``update/other`` (losses, optimiser steps, bookkeeping: the rest);
* ``inverse_dynamics`` (the keypoints' auxiliary loss), ``curiosity`` (ICM's reward and update,
  ``--reward curiosity`` only), ``evaluation`` and ``checkpoint``.

    python benchmarks/train_profile.py --configs v1 cpu --out results/rl/profile.json
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from collections import defaultdict
from contextlib import contextmanager

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

# Parts that start their own branch of the tree: their inner parts are theirs.
ROOTS = ("evaluation", "checkpoint", "inverse_dynamics", "curiosity_update")


class Timers:
    """Exclusive wall time per part, keyed by the root part it ran under."""

    def __init__(self):
        self.seconds: dict[str, float] = defaultdict(float)
        self.stack: list[list] = []  # [key, start, time of timed children]
        self.patches: list[tuple] = []

    @contextmanager
    def part(self, name: str):
        root = next((frame[0].split("/")[0] for frame in reversed(self.stack)
                     if frame[0].split("/")[0] in ROOTS), None)
        key = name if root is None or name in ROOTS else f"{root}/{name}"
        frame = [key, time.perf_counter(), 0.0]
        self.stack.append(frame)
        try:
            yield
        finally:
            self.stack.pop()
            elapsed = time.perf_counter() - frame[1]
            self.seconds[key] += elapsed - frame[2]
            if self.stack:
                self.stack[-1][2] += elapsed

    def wrap(self, owner, attr: str, name: str):
        original = getattr(owner, attr)
        timers = self

        def timed(*args, **kwargs):
            with timers.part(name):
                return original(*args, **kwargs)

        setattr(owner, attr, timed)
        self.patches.append((owner, attr, original))

    def restore(self):
        for owner, attr, original in reversed(self.patches):
            setattr(owner, attr, original)
        self.patches.clear()


def instrument(timers: Timers):
    """Timers around the parts of the training loop (patched on their classes and modules)."""
    import zsrm.envs.base as envs_base
    import zsrm.rl.ppo as ppo
    from stable_baselines3 import PPO
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.vec_env import DummyVecEnv
    from zsrm.rewards import VecZeroShotReward
    from zsrm.rl.auxiliary import InverseDynamicsAux
    from zsrm.rl.curiosity import ICMUpdate, VecCuriosity
    from zsrm.rl.features import VecImageFeatures

    timers.wrap(PPO, "collect_rollouts", "rollout_other")
    timers.wrap(PPO, "train", "update")
    timers.wrap(DummyVecEnv, "step_wait", "scenes")
    timers.wrap(DummyVecEnv, "reset", "scenes")
    timers.wrap(envs_base.MujocoPixelEnv, "_render_camera", "rendering")
    timers.wrap(VecZeroShotReward, "step_wait", "reward")
    timers.wrap(VecImageFeatures, "step_wait", "vlm_trunk")
    timers.wrap(VecImageFeatures, "reset", "vlm_trunk")
    timers.wrap(ActorCriticPolicy, "forward", "policy_forward")
    timers.wrap(ActorCriticPolicy, "predict", "policy_forward")
    timers.wrap(InverseDynamicsAux, "_on_rollout_end", "inverse_dynamics")
    timers.wrap(VecCuriosity, "step_wait", "curiosity_reward")
    timers.wrap(ICMUpdate, "_on_rollout_end", "curiosity_update")
    timers.wrap(ppo, "evaluate", "evaluation")
    timers.wrap(ppo, "save_checkpoint", "checkpoint")
    timers.wrap(ppo.PolicyBundle, "save", "checkpoint")
    # keep the last model and rollout buffer for the per-network split of the update
    kept = {}
    original_train = PPO.train

    def train_and_keep(self, *args, **kwargs):
        kept["model"] = self
        kept["updates"] = kept.get("updates", 0) + 1
        return original_train(self, *args, **kwargs)

    PPO.train = train_and_keep
    timers.patches.append((PPO, "train", original_train))
    return kept


def networks(policy) -> list[tuple[str, torch.nn.Module, callable]]:
    """The policy's networks in the order the update runs them: (name, module, input from the previous output)."""
    from zsrm.rl.features import FEATURES_KEY, IMAGE_KEY

    extractor = policy.features_extractor
    parts = [("vlm_keypoints", lambda obs, _: extractor.softmax(extractor.heat_maps(obs[FEATURES_KEY])))]
    if extractor.pixels is not None:
        parts.append(("pixel_cnn", lambda obs, _: extractor.pixels(obs[IMAGE_KEY])))

    def heads(obs, points):
        latent_pi, latent_vf = policy.mlp_extractor(extractor.out(points))
        distribution = policy._get_action_dist_from_latent(latent_pi)
        actions = distribution.get_actions()
        return torch.cat([distribution.log_prob(actions)[:, None], policy.value_net(latent_vf)], dim=1)

    parts.append(("heads", heads))
    return parts


def update_split(model, updates: int, repeats: int = 3) -> dict[str, float]:
    """Forward and backward seconds of each network over ``updates`` PPO updates, timed on the
    model's last rollout buffer with the update's minibatch size and epochs."""
    policy, buffer = model.policy, model.rollout_buffer
    batches = list(buffer.get(model.batch_size))
    per_update = model.n_epochs * len(batches)
    seconds = defaultdict(float)
    timed = 0
    for _ in range(repeats):
        for batch in batches:
            obs = batch.observations
            inputs, outputs = [], []
            for name, fn in networks(policy):
                t = time.perf_counter()
                # each network's input is the detached output of those before it, so its backward is its own
                points = torch.cat([o.detach().requires_grad_() for o in outputs], dim=1) if outputs else None
                if name == "heads":
                    inputs.append(points)
                    out = fn(obs, points)
                else:
                    out = fn(obs, None)
                seconds[f"{name}/forward"] += time.perf_counter() - t
                outputs.append(out) if name != "heads" else None
                t = time.perf_counter()
                out.sum().backward(retain_graph=name != "heads")
                seconds[f"{name}/backward"] += time.perf_counter() - t
            policy.zero_grad(set_to_none=True)
            timed += 1
    return {k: v / timed * per_update * updates for k, v in seconds.items()}


def profile(config: str, reward: str, steps: int, goal: str) -> dict:
    from zsrm.rl.config import preset
    from zsrm.rl.ppo import train

    cfg = preset(config, goal=goal, reward=reward, steps=steps, eval_every=steps // 2, checkpoint_every=steps // 2)
    timers = Timers()
    kept = instrument(timers)
    try:
        with tempfile.TemporaryDirectory() as out:
            t = time.perf_counter()
            summary = train(cfg, out, progress=False)
            wall = time.perf_counter() - t
    finally:
        timers.restore()
    env_steps = summary["env_steps"]
    parts = dict(timers.seconds)
    update = parts.pop("update", 0.0)
    split = update_split(kept["model"], kept["updates"])
    parts.update({f"update/{k}": v for k, v in split.items()})
    parts["update/other"] = update - sum(split.values())
    parts["setup_and_final_evaluation"] = wall - sum(timers.seconds.values())
    per_10k = {k: round(v / env_steps * 10_000, 3) for k, v in sorted(parts.items())}
    return {"config": config, "reward": reward, "goal": goal, "env_steps": env_steps, "wall_s": round(wall, 1),
            "env_steps_per_s": round(env_steps / wall, 1), "seconds_per_10k_env_steps": per_10k,
            "ppo_updates": kept["updates"], "train_config": cfg.to_dict()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configs", nargs="+", default=["cpu"], help="TrainConfig presets to profile")
    parser.add_argument("--rewards", nargs="+", default=["zsrm"], help="rewards to profile each preset with")
    parser.add_argument("--goal", default="stack")
    parser.add_argument("--steps", type=int, default=20_000, help="env steps per profiled run")
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    runs = []
    for config in args.configs:
        for reward in args.rewards:
            run = profile(config, reward, args.steps, args.goal)
            runs.append(run)
            print(f"{config} {reward}: {run['env_steps_per_s']:.0f} env steps/s over {run['env_steps']} steps")
            for k, v in run["seconds_per_10k_env_steps"].items():
                print(f"  {k:36s} {v:8.2f} s / 10k env steps")
    result = {"runs": runs, "meta": {
        "what": "seconds of each part of zsrm train per 10k env steps (exclusive times; update/<network> timed on "
                "the run's last rollout buffer and scaled to its updates)",
        "torch_threads": 1, "machine": f"{platform.machine()}, {os.cpu_count()} cores, no GPU",
        "command": "python benchmarks/train_profile.py " + " ".join(
            [f"--configs {' '.join(args.configs)}", f"--rewards {' '.join(args.rewards)}",
             f"--steps {args.steps}"] + ([f"--out {args.out}"] if args.out else []))}}
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=2)
            f.write("\n")
    return result


if __name__ == "__main__":
    np.set_printoptions(precision=3)
    main()

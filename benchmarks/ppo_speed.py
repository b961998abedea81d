"""Speed of the whole ``zsrm train`` loop, the default configuration against the one before it.

Each configuration (a ``--config`` preset) trains the same goal with the zsrm reward (the
shipped student) through :func:`zsrm.rl.ppo.train` itself: rollouts, reward, PPO updates, the
inverse-dynamics loss, evaluations and checkpoints at the configuration's own intervals, the
final evaluation and the policy's save. Beside each, the scenes alone: the same vectorised envs
stepped with random actions (no reward, no policy). One process, one torch thread, all in one
run. Prints and writes (``--out``):

* ``env_fraction``: the default's train-loop env steps/s (as ``zsrm train`` runs it alone: its
  scenes stepped by :func:`~zsrm.rl.ppo.auto_env_workers` processes) over its scenes' own in
  one process; ``meta.env_fraction_one_worker`` the same with one env worker, as a sweep's
  trial runs;
* ``speedup``: the default's train-loop env steps/s over the baseline's (``--baseline``, v1: the
  configuration of the results committed before 2026-12-04).

    python benchmarks/ppo_speed.py --out results/ppo_speed.json
"""
from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from zsrm.common.files import write_json  # noqa: E402


def warm_up(cfg) -> None:
    """Pay the process's one-time costs before the first timed run, which would otherwise carry
    them alone: imports (stable-baselines3; sentence-transformers, about 5 s here, which the
    student's text tower imports to encode its goal) and the first load of the VLM and the
    student (both kept for the rest of the process)."""
    import stable_baselines3  # noqa: F401

    from zsrm.fullmodel import load_reward_backbone
    from zsrm.vlm import load_vlm

    load_vlm(cfg.vlm)
    load_reward_backbone(cfg.reward_model)


def train_steps_per_s(cfg, env_workers: int = 1) -> tuple[float, int]:
    """Env steps/s of one whole ``zsrm train`` run of ``cfg`` (and its env steps)."""
    from zsrm.rl.ppo import train

    with tempfile.TemporaryDirectory() as out:
        t = time.perf_counter()
        summary = train(cfg, out, progress=False, env_workers=env_workers)
        wall = time.perf_counter() - t
    return summary["env_steps"] / wall, summary["env_steps"]


def env_steps_per_s(cfg, steps: int) -> float:
    """Env steps/s of the training envs alone, random actions, no reward, no policy."""
    from zsrm.rl.envs import make_vec

    venv = make_vec(cfg, cfg.n_envs, cfg.seed)
    venv.reset()
    rng = np.random.default_rng(0)
    decisions = steps // cfg.action_repeat // cfg.n_envs
    t = time.perf_counter()
    for _ in range(decisions):
        venv.step(rng.uniform(-1, 1, (cfg.n_envs, *venv.action_space.shape)).astype(np.float32))
    speed = decisions * cfg.n_envs * cfg.action_repeat / (time.perf_counter() - t)
    venv.close()
    return speed


def main(argv=None):
    from zsrm.rl.config import preset

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goal", default="stack")
    parser.add_argument("--steps", type=int, default=60_000, help="env steps of each timed train run")
    parser.add_argument("--config", default="cpu", help="the configuration measured (a TrainConfig preset)")
    parser.add_argument("--baseline", default="v1", help="the configuration it is compared with")
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    from zsrm.rl.ppo import auto_env_workers

    runs = {}
    warm_up(preset(args.config, goal=args.goal, reward="zsrm"))
    # the default as zsrm train runs it alone (its env workers), as a sweep's trial runs it (one
    # process), and the baseline as its sweeps ran (one process)
    new_cfg = preset(args.config, goal=args.goal, reward="zsrm", steps=args.steps)
    one_worker = f"{args.config}, 1 env worker"
    plan = [(args.config, new_cfg, auto_env_workers(new_cfg)), (one_worker, new_cfg, 1),
            (args.baseline, preset(args.baseline, goal=args.goal, reward="zsrm", steps=args.steps), 1)]
    for name, cfg, workers in plan:
        train_speed, env_steps = train_steps_per_s(cfg, workers)
        env_only = env_steps_per_s(cfg, 16_384)
        runs[name] = {"train_steps_per_s": train_speed, "env_only_steps_per_s": env_only,
                      "env_fraction": train_speed / env_only, "env_steps": env_steps, "env_workers": workers,
                      "train_config": cfg.to_dict()}
        print(f"{name}: zsrm train {train_speed:.0f} env steps/s with {workers} env worker(s), scenes alone in one "
              f"process {env_only:.0f} (fraction {train_speed / env_only:.2f})", flush=True)
    new, old = runs[args.config], runs[args.baseline]
    result = {
        "env_fraction": new["env_fraction"],
        "speedup": new["train_steps_per_s"] / old["train_steps_per_s"],
        "train_steps_per_s": new["train_steps_per_s"], "env_only_steps_per_s": new["env_only_steps_per_s"],
        "configs": runs,
        "meta": {"goal": args.goal, "reward": "zsrm (the shipped student)", "config": args.config,
                 "baseline": args.baseline, "steps_per_run": args.steps,
                 "timed": "the whole zsrm train run: rollouts, reward, PPO updates, inverse-dynamics loss, evaluations "
                          "and checkpoints every 20k env steps, final 30-episode evaluation, saving the policy; the process's "
                          "one-time imports and model loads paid before the first timed run (warm_up); the default "
                          "with zsrm train's env workers (auto_env_workers: on 2+ cores, 2 processes step the scenes "
                          "of a lone run while the learner keeps one torch thread) and with one, as a sweep's trial "
                          "runs; the scenes alone always in one process",
                 "env_fraction_one_worker": runs[one_worker]["env_fraction"],
                 "torch_threads": 1, "machine": f"{platform.machine()}, {os.cpu_count()} cores, no GPU",
                 "command": "python benchmarks/ppo_speed.py"
                            + (f" --steps {args.steps}" if args.steps != 60_000 else "")
                            + (f" --out {args.out}" if args.out else "")},
    }
    print(f"speedup {result['speedup']:.2f} ({args.config} against {args.baseline}), "
          f"env_fraction {result['env_fraction']:.2f}")
    if args.out:
        write_json(args.out, result)
    return result


if __name__ == "__main__":
    main()

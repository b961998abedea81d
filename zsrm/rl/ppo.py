"""``zsrm train``: PPO from pixels with a reward from a goal sentence.

One run writes to its folder::

    config.json     the TrainConfig
    eval.csv        env step, oracle episode reward (mean, s.e.), success rate, train reward
    tb/             TensorBoard logs of the same and of PPO's losses
    checkpoint/     policy + optimiser + step + the run's state (zsrm.rl.resume): a killed run
                    resumes here to the same eval.csv rows and final weights as an unbroken run
    policy/         the trained policy (safetensors + JSON), for ``zsrm rollout``
    summary.json    the final evaluation

Only images reach the policy and the reward model; the oracle (true state) is read for
``--reward oracle`` and for evaluation only.
"""
from __future__ import annotations

import csv
import os
import time
from pathlib import Path

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback

from zsrm.common.files import atomic_path, read_json, write_json
from zsrm.rewards import VecZeroShotReward
from zsrm.rl.augment import ShiftRegulariser
from zsrm.rl.auxiliary import InverseDynamicsAux
from zsrm.rl.config import TrainConfig
from zsrm.rl.curiosity import ICMUpdate, VecCuriosity
from zsrm.rl.envs import make_reward, make_vec
from zsrm.rl.evaluate import Evaluator, evaluate, random_actions
from zsrm.rl.features import policy_view
from zsrm.rl.goals import goal_camera, goal_text
from zsrm.rl.policy import PolicyBundle, load_checkpoint, policy_kwargs, save_checkpoint
from zsrm.rl.resume import RunState
from zsrm.vlm import load_vlm

EVAL_FIELDS = ("env_steps", "mean", "se", "success_rate", "train_reward", "wall_s")
FINAL_EPISODES = 30


def learning_rate(cfg: TrainConfig):
    """A constant, or (anneal_lr) stable-baselines3's schedule of the run's remaining fraction, which
    it computes from the total env steps, so a resumed run continues the same decay."""
    if not cfg.anneal_lr:
        return cfg.learning_rate
    return LinearDecay(cfg.learning_rate)


class LinearDecay:
    """``lr * progress_remaining``, 0 past the end (the last rollout may overshoot the run's steps);
    a class, not a lambda, so that it pickles."""

    def __init__(self, start: float):
        self.start = start

    def __call__(self, progress_remaining: float) -> float:
        return self.start * max(progress_remaining, 0.0)


def build_ppo(cfg: TrainConfig, venv, device: str = "cpu") -> PPO:
    return PPO("MultiInputPolicy", venv, n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.n_epochs,
               learning_rate=learning_rate(cfg), gamma=cfg.gamma, gae_lambda=cfg.gae_lambda, ent_coef=cfg.ent_coef,
               clip_range=cfg.clip_range, target_kl=cfg.target_kl or None, policy_kwargs=policy_kwargs(cfg),
               seed=cfg.seed, device=device, verbose=0)


class EvalAndCheckpoint(BaseCallback):
    """Every ``eval_every`` env steps: the oracle metric on the eval envs (CSV + TensorBoard); after
    the PPO update of the first rollout past each ``checkpoint_every`` (when the next rollout
    starts): a checkpoint. Also drives the progress bar."""

    def __init__(self, cfg: TrainConfig, out: Path, evaluator: Evaluator, rows: list[dict], progress, on_eval=None,
                 extra_modules: dict | None = None):
        super().__init__()
        self.cfg, self.out, self.evaluator, self.rows, self.progress = cfg, out, evaluator, rows, progress
        self.on_eval, self.extra_modules = on_eval, extra_modules
        self.next_eval = (rows[-1]["env_steps"] if rows else 0) + cfg.eval_every
        self.next_ckpt = self.next_eval - cfg.eval_every + cfg.checkpoint_every
        self.rewards: list[float] = []
        self.t0 = time.time() - (rows[-1]["wall_s"] if rows else 0.0)
        self.run_state = None  # a zsrm.rl.resume.RunState: the checkpoints keep it

    def resume_state(self):
        return {"next_eval": self.next_eval, "next_ckpt": self.next_ckpt, "rewards": self.rewards}, {}, {}

    def load_resume_state(self, info: dict, arrays: dict) -> dict:
        self.next_eval, self.next_ckpt, self.rewards = int(info["next_eval"]), int(info["next_ckpt"]), list(info["rewards"])
        return {}

    def save(self) -> None:
        write = self.run_state.save if self.run_state is not None and self.run_state.ready() else None
        save_checkpoint(self.out / "checkpoint", self.model, self.cfg, self.env_steps(), self.rows,
                        self.extra_modules, write)

    def env_steps(self) -> int:
        return int(self.model.num_timesteps * self.cfg.action_repeat)

    def _on_step(self) -> bool:
        self.rewards.append(float(np.mean(self.locals["rewards"])))
        self.progress.update(min(self.env_steps(), self.cfg.steps) - self.progress.n)
        if self.env_steps() >= self.next_eval:
            self.evaluate()
            self.next_eval += self.cfg.eval_every
        return True

    def _on_rollout_start(self) -> None:
        # Between rollouts, after the last one's PPO update (SB3 calls on_rollout_end before it):
        # a run resumes on whole rollouts with nothing of a rollout lost or done twice.
        if self.env_steps() >= self.next_ckpt:
            while self.next_ckpt <= self.env_steps():
                self.next_ckpt += self.cfg.checkpoint_every
            self.save()

    def evaluate(self):
        cfg = self.cfg
        result = self.evaluator(policy_act(self.model, cfg.eval_deterministic), cfg.eval_episodes)
        # Mean reward per decision over the interval, times the decisions of an episode.
        train_reward = float(np.mean(self.rewards) * self.cfg.episode_decisions) if self.rewards else 0.0
        self.rewards = []
        row = {"env_steps": self.env_steps(), "mean": result["mean"], "se": result["se"],
               "success_rate": result["success_rate"], "train_reward": train_reward,
               "wall_s": round(time.time() - self.t0, 1)}
        self.rows.append(row)
        for k in ("mean", "success_rate", "train_reward"):
            self.logger.record(f"eval/{k}", row[k])
        self.logger.dump(self.num_timesteps)
        write_eval_csv(self.out / "eval.csv", self.rows)
        self.progress.set_postfix(oracle=f"{row['mean']:.1f}", success=f"{row['success_rate']:.2f}")
        if self.on_eval is not None:
            self.on_eval(row)


def policy_act(model: PPO, deterministic: bool):
    def act(obs):
        return model.predict(obs, deterministic=deterministic)[0]
    return act


def write_eval_csv(path: Path, rows: list[dict]) -> None:
    with atomic_path(path) as tmp, tmp.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=EVAL_FIELDS)
        writer.writeheader()
        writer.writerows(rows)


def train(cfg: TrainConfig, out: str | Path, fresh: bool = False, progress: bool = True, on_eval=None,
          device: str = "cpu", env_workers: int = 1) -> dict:
    """Train (or resume) one PPO run; returns the summary written to ``out/summary.json``.

    ``on_eval(row)`` is called after each evaluation (the sweep reports it to Ray Tune). Neither
    ``device`` ('cpu', 'cuda', 'auto': where the VLM trunk and PPO's networks run) nor ``env_workers``
    (:func:`auto_env_workers`) is in the run's config: a run resumes on any."""
    from stable_baselines3.common.logger import configure
    from tqdm import tqdm

    if cfg.learner != "ppo" and cfg.reward != "random":
        raise ValueError(f"a --learner {cfg.learner} run is trained by zsrm.rl.learners.train, not PPO's")
    out = Path(out)
    if (summary := finished(cfg, out, fresh)) is not None:
        return summary
    if cfg.reward == "random":
        return finish_random(cfg, out)

    device = resolve_device(device)
    vlm = load_vlm(cfg.vlm, device=device)
    done_steps, rows = 0, []
    state = None if fresh else load_checkpoint(out / "checkpoint", cfg)
    if state is not None:
        done_steps, rows = state["env_steps"], state["rows"]
    venv, extra_callbacks, extra_modules = rewarded_env(cfg, out, done_steps, int(env_workers))
    venv = policy_view(venv, vlm, cfg)
    model = build_ppo(cfg, venv, device)
    auxiliary = auxiliary_losses(cfg, model, device)
    extra_callbacks = [*extra_callbacks, *auxiliary.values()]
    if "inverse" in auxiliary:
        extra_modules = {**extra_modules, "inverse.safetensors": auxiliary["inverse"].model_inverse}
    if state is not None:
        state["restore"](model, extra_modules)
    elif cfg.init:
        start_from(model, cfg.init)
    model.set_logger(configure(str(out / "tb"), ["tensorboard"]))
    # PPO stops only at a rollout's end: train whole rollouts, never past cfg.steps.
    rollout = cfg.n_envs * cfg.n_steps * cfg.action_repeat
    remaining = max(0, max(rollout, cfg.steps // rollout * rollout) - done_steps) // rollout * rollout
    # one set of eval envs for the run: each evaluation plays the first eval_episodes, the final all
    evaluator = Evaluator(cfg, max(FINAL_EPISODES, cfg.eval_episodes), cfg.seed, wrap=lambda v: policy_view(v, vlm, cfg))
    with tqdm(total=cfg.steps, initial=done_steps, unit="step", desc=f"train {cfg.reward} {cfg.goal}",
              disable=not progress, smoothing=0.05) as bar:
        callback = EvalAndCheckpoint(cfg, out, evaluator, rows, bar, on_eval, extra_modules)
        callback.run_state = RunState(model, {"train": callback, **auxiliary})
        if state is not None and state["resume"] is not None:
            callback.run_state.restore(state["resume"])  # last before learn: it sets the random generators
        if remaining:
            model.learn(remaining // cfg.action_repeat, callback=[*extra_callbacks, callback],
                        reset_num_timesteps=state is None)
        callback.save()  # before the final evaluation, which a resume from here plays again
        by_actions = final_evaluations(evaluator, model)
    evaluator.close()
    venv.close()
    PolicyBundle(model.policy, cfg).save(out / "policy")
    return write_summary(cfg, out, by_actions["mean" if cfg.eval_deterministic else "sampled"], rows,
                         callback.env_steps(), wall_s=time.time() - callback.t0, by_actions=by_actions)


def finished(cfg: TrainConfig, out: Path, fresh: bool = False) -> dict | None:
    """A finished run's summary when ``out`` holds one of ``cfg`` (and not ``fresh``); else None,
    with the run's threads set, its folder made and its config.json written."""
    torch.set_num_threads(cfg.threads)
    out.mkdir(parents=True, exist_ok=True)
    if (out / "summary.json").is_file() and not fresh:
        summary = read_json(out / "summary.json", "a zsrm train summary")
        if summary.get("config", {}) == cfg.to_dict():
            return summary  # finished run: nothing to do
    write_json(out / "config.json", cfg.to_dict())
    return None


def auxiliary_losses(cfg: TrainConfig, model: PPO, device: str) -> dict:
    """The callbacks that train the policy between rollouts beside PPO's loss, by resume name:
    the inverse-dynamics loss (``aux_inverse``) and the shift regulariser (``augment_shift``)."""
    losses = {}
    if cfg.aux_inverse:
        points_dim = model.policy.features_extractor.points_dim
        losses["inverse"] = InverseDynamicsAux(points_dim, model.action_space.shape[0], seed=cfg.seed, device=device)
    if cfg.augment_shift:
        losses["shift"] = ShiftRegulariser(cfg.augment_shift, lr=cfg.learning_rate, seed=cfg.seed)
    return losses


def final_evaluations(evaluator: Evaluator, model: PPO) -> dict:
    """The final policy on the same seeded episodes by its mean action and by sampled ones: the
    summary's ``final_*`` is the one ``eval_deterministic`` names, and both are kept, so every run
    says what the mean action is worth."""
    return {"mean": evaluator(policy_act(model, True), FINAL_EPISODES),
            "sampled": evaluator(policy_act(model, False), FINAL_EPISODES)}


def start_from(model: PPO, folder: str) -> None:
    """Copy a trained policy's weights (``--init``) into a new run's actor-critic; the optimiser
    and the inverse-dynamics head start fresh."""
    init = PolicyBundle.load(folder)
    try:
        model.policy.load_state_dict(init.policy.state_dict())
    except RuntimeError as err:
        raise ValueError(f"--init {folder}: that policy's architecture differs from this run's "
                         f"({str(err).splitlines()[0][:160]})") from None


def resolve_device(device: str) -> str:
    """'auto' -> 'cuda' when torch sees a GPU, else 'cpu'; 'cuda' without one is an error."""
    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise ValueError(f"--device {device}: torch sees no CUDA GPU on this machine (use cpu or auto)")
    if device != "cpu" and not device.startswith("cuda"):
        raise ValueError(f"--device {device!r}: expected cpu, cuda, cuda:N or auto")
    return device


def auto_env_workers(cfg: TrainConfig) -> int:
    """``zsrm train``'s env workers: two processes step the scenes of a run of 8 or more envs on
    a machine with two cores or more for it (the learner keeps its one torch thread), else one.
    The numbers are the same either way (:mod:`zsrm.rl.workers`); a sweep runs each trial with
    one. More than one starts processes by spawn: a script calling :func:`train` with them
    needs ``if __name__ == "__main__":``."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return 2 if cores >= 2 and cfg.n_envs >= 8 else 1


def rewarded_env(cfg: TrainConfig, out: Path, done_steps: int, workers: int = 1):
    """The training envs (stepped by ``workers`` processes) with the reward ``cfg.reward`` names,
    the callbacks it needs while PPO trains and the modules a checkpoint must keep for it
    (curiosity's ICM)."""
    venv = make_vec(cfg, cfg.n_envs, cfg.seed * 10_000 + done_steps, workers=workers, training=True)
    if cfg.reward == "curiosity":
        curiosity = VecCuriosity(venv, goal_camera(cfg.goal, cfg.scene), seed=cfg.seed)
        return curiosity, [ICMUpdate(curiosity)], {"icm.safetensors": curiosity.icm}
    reward = make_reward(cfg, out)
    return VecZeroShotReward(venv, reward, goal_text(cfg.goal, cfg.scene)), [], {}


def finish_random(cfg: TrainConfig, out: Path) -> dict:
    """The uniform random policy's oracle metric (the `random` baseline of the results)."""
    t0 = time.time()
    probe = make_vec(cfg, 1, 0)
    act = random_actions(probe.action_space, cfg.seed)
    probe.close()
    final = evaluate(act, cfg, FINAL_EPISODES, cfg.seed)
    return write_summary(cfg, out, final, [], 0, wall_s=time.time() - t0)


def write_summary(cfg: TrainConfig, out: Path, final: dict, rows: list[dict], env_steps: int,
                  wall_s: float | None = None, by_actions: dict | None = None) -> dict:
    """``summary.json``; ``wall_s``: the run's seconds, the parts before a resume included;
    ``by_actions``: the final evaluation with the policy's mean action and with sampled ones
    (``final_*`` is the one ``eval_deterministic`` names)."""
    summary = {"config": cfg.to_dict(), "env_steps": env_steps, "final_mean": final["mean"], "final_se": final["se"],
               "final_success_rate": final["success_rate"], "final_episodes": len(final["episode_rewards"]),
               "final_episode_rewards": final["episode_rewards"], "curve": rows,
               **({"wall_s": round(wall_s, 1)} if wall_s is not None else {})}
    if by_actions:
        summary["final_by_actions"] = {k: {"mean": r["mean"], "se": r["se"], "success_rate": r["success_rate"]}
                                       for k, r in sorted(by_actions.items())}
    write_json(out / "summary.json", summary)
    return summary

"""``zsrm train --learner sac``: SAC on keypoints pretrained without a reward.

Two stages in one run folder. First ``keypoints/`` (:mod:`zsrm.rl.pretrain`): a keypoint
autoencoder trained on frames of random actions, its env steps counted in the run's. Then
stable-baselines3's SAC on those keypoints, frozen, read from the policy view as a flat state
(:class:`VecKeypoints`), with the reward the config names. On push_close this learner reached
success 0.70 (oracle) and 0.59 (zsrm) in 500k env steps where PPO stops near 0.3 (docs/training.md).

The run folder holds what a PPO run's does (config.json, eval.csv, summary.json, policy/, whose
kind is ``zsrm-sac-policy``: the extractor and SAC's actor) and a checkpoint of SAC's networks,
optimisers and replay buffer (safetensors, JSON and ``replay.npz``; nothing pickled). A killed run
resumes there with nothing finished lost; its training envs restart from fresh episodes (seeded by
the step), so a resumed run is not the same run step for step, unlike PPO's.
"""
from __future__ import annotations

import shutil
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import SAC
from stable_baselines3.common.vec_env import VecEnvWrapper

from zsrm.common.checkpoints import load_optimizer, read_checkpoint_state, save_optimizer
from zsrm.common.checkpoints import save_checkpoint as save_checkpoint_folder
from zsrm.common.files import ZsrmFileError
from zsrm.common.registry import load_tensors, load_weights, save_tensors, save_weights
from zsrm.rl.config import TrainConfig
from zsrm.rl.evaluate import Evaluator
from zsrm.rl.features import KeypointExtractor, policy_view
from zsrm.rl.policy import SAC_NET_ARCH, SacPolicyBundle
from zsrm.rl.ppo import FINAL_EPISODES, EvalAndCheckpoint, final_evaluations, learning_rate, rewarded_env, write_summary
from zsrm.rl.pretrain import freeze, points_of, pretrain_keypoints
from zsrm.vlm import load_vlm

# SAC's settings, stable-baselines3's defaults but these (measured on push_close, docs/training.md)
BATCH_SIZE, LEARNING_STARTS = 256, 1000
REPLAY_FILE = "replay.npz"
REPLAY_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


class VecKeypoints(VecEnvWrapper):
    """The policy view's keypoints (x, y, strength of every keypoint, :meth:`KeypointExtractor.points`)
    read by a frozen extractor, as a flat observation: SAC then learns on them as on a state."""

    def __init__(self, venv, extractor: KeypointExtractor):
        self.extractor = freeze(extractor)
        space = gym.spaces.Box(-np.inf, np.inf, (extractor.points_dim,), np.float32)
        super().__init__(venv, observation_space=space)

    def convert(self, obs: dict) -> np.ndarray:
        return points_of(self.extractor, obs).numpy()

    def reset(self):
        return self.convert(self.venv.reset())

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        for info in infos:
            if "terminal_observation" in info:
                info["terminal_observation"] = self.convert({k: v[None] for k, v in info["terminal_observation"].items()})[0]
        return self.convert(obs), rewards, dones, infos


def build_sac(cfg: TrainConfig, venv, device: str = "cpu") -> SAC:
    """SAC on ``venv``'s flat keypoints; its replay buffer holds the whole run."""
    return SAC("MlpPolicy", venv, learning_rate=learning_rate(cfg), buffer_size=max(1, cfg.steps // cfg.action_repeat),
               batch_size=BATCH_SIZE, learning_starts=LEARNING_STARTS, gamma=cfg.gamma, train_freq=1,
               gradient_steps=1, seed=cfg.seed, device=device, verbose=0, policy_kwargs=dict(net_arch=SAC_NET_ARCH))


class SacEvalAndCheckpoint(EvalAndCheckpoint):
    """PPO's evaluations and progress, counted after the pretraining's ``offset`` env steps, and
    checkpoints of SAC (:func:`save_sac_checkpoint`)."""

    def __init__(self, cfg: TrainConfig, out: Path, evaluator: Evaluator, rows: list[dict], progress, offset: int,
                 on_eval=None):
        super().__init__(cfg, out, evaluator, rows, progress, on_eval)
        self.offset = offset
        if not rows:
            self.next_eval, self.next_ckpt = offset + cfg.eval_every, offset + cfg.checkpoint_every

    def env_steps(self) -> int:
        return self.offset + int(self.model.num_timesteps * self.cfg.action_repeat)

    def save(self) -> None:
        save_sac_checkpoint(self.out / "checkpoint", self.model, self.cfg, self.env_steps(), self.rows,
                            self.resume_state()[0])


def save_sac_checkpoint(folder: Path, model: SAC, cfg: TrainConfig, env_steps: int, rows: list[dict],
                        callback: dict) -> None:
    """SAC's networks, its three optimisers, its entropy coefficient and its replay buffer, swapped
    in atomically (:func:`zsrm.common.checkpoints.save_checkpoint`)."""
    buffer = model.replay_buffer
    state = {"config": cfg.identity(), "env_steps": int(env_steps), "rows": rows, "callback": callback,
             "decisions": int(model.num_timesteps), "updates": int(model._n_updates),
             "buffer": {"pos": int(buffer.pos), "full": bool(buffer.full)}}

    def save_rest(tmp: Path) -> None:
        save_weights(model.policy, tmp)
        save_tensors({"log_ent_coef": model.log_ent_coef.detach()}, tmp / "ent_coef.safetensors")
        for name in ("critic", "ent_coef"):
            (tmp / name).mkdir()
            save_optimizer(optimisers(model)[name], tmp / name)
        rows_held = buffer.buffer_size if buffer.full else buffer.pos
        np.savez(tmp / REPLAY_FILE, **{k: getattr(buffer, k)[:rows_held] for k in REPLAY_ARRAYS})

    save_checkpoint_folder(folder, save_rest, optimisers(model)["actor"], state)


def optimisers(model: SAC) -> dict:
    return {"actor": model.actor.optimizer, "critic": model.critic.optimizer, "ent_coef": model.ent_coef_optimizer}


def load_sac_checkpoint(folder: Path, cfg: TrainConfig) -> dict | None:
    """The checkpoint's state and ``restore(model)``, or None when there is none."""
    if not (folder / "state.json").is_file():
        return None
    state = read_checkpoint_state(folder, cfg.identity(), {"env_steps": int, "rows": list, "callback": dict,
                                                           "decisions": int, "updates": int, "buffer": dict})

    def restore(model: SAC) -> None:
        load_weights(model.policy, folder)
        model.log_ent_coef.data.copy_(load_tensors(folder / "ent_coef.safetensors")["log_ent_coef"])
        for name, opt in optimisers(model).items():
            load_optimizer(folder if name == "actor" else folder / name, opt)
        restore_buffer(model.replay_buffer, folder / REPLAY_FILE, state["buffer"])
        model.num_timesteps, model._n_updates = state["decisions"], state["updates"]

    state["restore"] = restore
    return state


def restore_buffer(buffer, path: Path, where: dict) -> None:
    """The replay buffer's rows from ``path`` (plain arrays, no pickle), checked against the buffer."""
    try:
        with np.load(path, allow_pickle=False) as saved:
            arrays = {k: saved[k] for k in REPLAY_ARRAYS}
    except (OSError, KeyError, ValueError) as err:
        raise ZsrmFileError(f"{path} cannot be read as a replay buffer ({err}); pass --fresh to start over") from None
    for key, array in arrays.items():
        target = getattr(buffer, key)
        if array.shape[1:] != target.shape[1:] or len(array) > len(target):
            raise ZsrmFileError(f"{path}: {key} has shape {array.shape}, the run's buffer {target.shape}; "
                                "pass --fresh to start over")
        target[:len(array)] = array
    buffer.pos, buffer.full = int(where["pos"]), bool(where["full"])


def train_sac(cfg: TrainConfig, out: Path, fresh: bool = False, progress: bool = True, on_eval=None,
              device: str = "cpu", env_workers: int = 1, shared_keypoints: Path | None = None) -> dict:
    """Pretrain the keypoints (or load them; ``shared_keypoints``: :func:`pretrain_keypoints`'s
    ``shared``), then train (or resume) SAC on them; the summary."""
    from tqdm import tqdm

    if fresh:
        shutil.rmtree(out / "keypoints", ignore_errors=True)
    start, vlm = time.time(), load_vlm(cfg.vlm, device=device)
    state = None if fresh else load_sac_checkpoint(out / "checkpoint", cfg)
    done_steps, rows = (state["env_steps"], state["rows"]) if state is not None else (0, [])
    view = policy_view(rewarded_env(cfg, out, done_steps, env_workers)[0], vlm, cfg)
    extractor, offset = pretrain_keypoints(cfg, view.observation_space, out / "keypoints", progress,
                                           shared_keypoints)
    train_env = VecKeypoints(view, extractor)
    model = build_sac(cfg, train_env, device)
    if state is not None:
        state["restore"](model)
    evaluator = Evaluator(cfg, FINAL_EPISODES, cfg.seed, wrap=lambda v: VecKeypoints(policy_view(v, vlm, cfg), extractor))
    decisions = max(0, cfg.steps - offset) // cfg.action_repeat
    with tqdm(total=cfg.steps, initial=offset + model.num_timesteps * cfg.action_repeat, unit="step",
              desc=f"sac {cfg.reward} {cfg.goal}", disable=not progress, smoothing=0.05) as bar:
        callback = SacEvalAndCheckpoint(cfg, out, evaluator, rows, bar, offset, on_eval)
        if state is not None:
            callback.load_resume_state(state["callback"], {})
        else:  # the run's seconds count the pretraining's
            callback.t0 = start
        if decisions > model.num_timesteps:
            model.learn(decisions - model.num_timesteps, callback=callback, reset_num_timesteps=state is None)
        callback.save()
        by_actions = final_evaluations(evaluator, model)
    evaluator.close()
    train_env.close()
    SacPolicyBundle(extractor, model.actor, cfg).save(out / "policy")
    return write_summary(cfg, out, by_actions["mean" if cfg.eval_deterministic else "sampled"], rows,
                         callback.env_steps(), wall_s=time.time() - callback.t0, by_actions=by_actions)

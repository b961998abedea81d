"""What would an off-policy learner from pixels cost, and does it learn push_close?

PPO stops near success 0.3 on push_close whether it reads frames or true state; stable-baselines3's
SAC on true state reached 0.88 (``probes/push_state_ppo.py --learner sac``). This probe trains SAC
on what zsrm's PPO policy reads (the frozen VLM trunk's map and the 32 px frame, through the same
keypoint extractor; actor and critic each with their own) with a zsrm reward, evaluating the mean
action on zsrm's seeded evaluation episodes every ``--eval-every`` env steps. ``--shift N``: DrQ's
random shifts of the sampled pixel views. ``--keypoints-from random|POLICY``: SAC on the keypoints of
a frozen extractor instead (an untrained one, or a trained zsrm policy's), as on a state.
``--finetune-from POLICY``: SAC on the policy view whose actor's and critic's extractors start as a
trained zsrm policy's and go on learning (the critic's from its loss, as in DrQ). Not
resumable, no policy saved: a measurement for deciding what belongs in ``zsrm train`` (SAC on an
autoencoder's keypoints went there as ``--learner sac``).

    python probes/push_pixel_sac.py --reward oracle --steps 150000 --out results/side/rl/push_pixel_sac/oracle-0
    python probes/push_pixel_sac.py --reward oracle --keypoints-from results/rl/pilots/v3-push_close-oracle-pairs3-500k-0/policy \
        --out results/side/rl/push_pixel_sac/keypoints-ppo-oracle-0
"""
from __future__ import annotations

import argparse
import functools
import os
import runpy
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from stable_baselines3 import SAC  # noqa: E402
from tqdm import tqdm  # noqa: E402

from zsrm.common.files import write_json  # noqa: E402
from zsrm.rl.config import TrainConfig  # noqa: E402
from zsrm.rl.evaluate import Evaluator  # noqa: E402
from zsrm.rl.augment import random_shift  # noqa: E402
from zsrm.rl.features import IMAGE_KEY, KeypointExtractor, policy_view  # noqa: E402
from zsrm.rl.policy import PolicyBundle  # noqa: E402
from zsrm.rl.ppo import EvalAndCheckpoint, LinearDecay, policy_act, rewarded_env  # noqa: E402
from zsrm.rl.sac import VecKeypoints  # noqa: E402
from zsrm.vlm import load_vlm  # noqa: E402


def shifted_buffer(pad: int, seed: int):
    """A replay buffer whose samples' pixel views are shifted by up to ``pad`` px (DrQ: the current
    and the next frames each by their own shift); the VLM map is left as it is."""
    from stable_baselines3.common.buffers import DictReplayBuffer

    generator = torch.Generator().manual_seed(seed)

    class ShiftedReplayBuffer(DictReplayBuffer):
        def sample(self, batch_size, env=None):
            batch = super().sample(batch_size, env)
            for obs in (batch.observations, batch.next_observations):
                obs[IMAGE_KEY] = random_shift(obs[IMAGE_KEY], pad, generator)
            return batch

    return ShiftedReplayBuffer


def is_autoencoder(folder: str) -> bool:
    """Whether ``folder`` holds an extractor of ``probes/keypoint_autoencoder.py``."""
    return bool(folder) and (Path(folder) / "extractor.pt").is_file()


def load_autoencoder(folder: str, space, settings_only: bool = False):
    return runpy.run_path(str(Path(__file__).with_name("keypoint_autoencoder.py")))["load_extractor"](
        folder, space, settings_only)


@functools.lru_cache
def load_policy(folder: str) -> PolicyBundle:  # once: its settings and its extractor come from one load
    return PolicyBundle.load(folder)


def trained_settings(trained: str) -> TrainConfig:
    """The settings of the views a trained extractor reads (zsrm train's defaults for none)."""
    if is_autoencoder(trained):
        return TrainConfig(**load_autoencoder(trained, None, settings_only=True))
    return load_policy(trained).cfg if trained else TrainConfig()


def trained_extractor(trained: str, space, cfg: TrainConfig) -> KeypointExtractor:
    """A trained zsrm policy's extractor, as PPO left it, or a keypoint autoencoder's; without one, an
    untrained extractor (seeded by the run)."""
    if is_autoencoder(trained):
        return load_autoencoder(trained, space)[0]
    if trained:
        return load_policy(trained).policy.features_extractor
    torch.manual_seed(cfg.seed)
    return KeypointExtractor(space, keypoints=cfg.keypoints, pixels=cfg.pixels)


def start_extractors(model: SAC, extractor: KeypointExtractor) -> None:
    """Start every extractor of ``model`` (the actor's, the critic's and its target's) as ``extractor``."""
    state = extractor.state_dict()
    for net in (model.actor, model.critic, model.critic_target):
        net.features_extractor.load_state_dict(state)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--goal", default="push_close")
    p.add_argument("--reward", default="oracle", choices=("oracle", "zsrm"))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--steps", type=int, default=150_000, help="env (control) steps")
    p.add_argument("--envs", type=int, default=4)
    p.add_argument("--gradient-steps", type=int, default=1, help="per step of all the envs")
    p.add_argument("--batch-size", type=int, default=256)
    p.add_argument("--learning-starts", type=int, default=1000, help="decisions before the first gradient step")
    p.add_argument("--shift", type=int, default=0, help="DrQ's random shift of sampled pixel views (px; 0: none)")
    p.add_argument("--keypoints-from", default="", metavar="random|POLICY",
                   help="SAC on the keypoints of a frozen extractor (untrained, or a trained policy's) instead of "
                        "learning its own")
    p.add_argument("--finetune-from", default="", metavar="POLICY",
                   help="SAC on the policy view, its extractors started from a trained policy's and trained on")
    p.add_argument("--anneal-lr", action="store_true",
                   help="decay SAC's learning rate (3e-4) linearly to 0 over the run, as zsrm train's PPO does")
    p.add_argument("--eval-every", type=int, default=20_000)
    p.add_argument("--eval-episodes", type=int, default=10, help="per evaluation; the final plays 30")
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    if args.shift and args.keypoints_from:
        p.error("--shift moves the pixel view SAC learns from; with --keypoints-from it reads frozen keypoints")
    if args.keypoints_from and args.finetune_from:
        p.error("--keypoints-from freezes an extractor, --finetune-from trains one on: give one")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    # a trained extractor reads the views it was trained on (its policy's trunk and pixel sizes)
    trained = args.finetune_from or (args.keypoints_from if args.keypoints_from != "random" else "")
    source = trained_settings(trained)
    # zsrm train's evaluations and eval.csv, never its checkpoints (they keep PPO's state)
    cfg = TrainConfig(goal=args.goal, reward=args.reward, seed=args.seed, steps=args.steps, n_envs=args.envs,
                      eval_every=args.eval_every, eval_episodes=args.eval_episodes, checkpoint_every=args.steps + 1,
                      trunk_size=source.trunk_size, pixel_size=source.pixel_size)
    vlm = load_vlm(cfg.vlm)
    venv = policy_view(rewarded_env(cfg, out, 0, 1)[0], vlm, cfg)
    start_from = trained_extractor(trained, venv.observation_space, cfg) if trained or args.keypoints_from else None
    frozen = start_from if args.keypoints_from else None

    def keypoints(v):  # what SAC reads of a policy view: the view itself, or its frozen keypoints
        return VecKeypoints(v, frozen) if frozen is not None else v

    train_env = keypoints(venv)
    decisions = cfg.steps // cfg.action_repeat
    if frozen is not None:
        policy, policy_kwargs = "MlpPolicy", dict(net_arch=[256, 256])
    else:
        policy, policy_kwargs = "MultiInputPolicy", dict(
            features_extractor_class=KeypointExtractor, share_features_extractor=False,
            features_extractor_kwargs=dict(keypoints=source.keypoints, pixels=source.pixels,
                                           pair_scale=source.pair_scale, pixel_stride=source.pixel_stride),
            net_arch=[256, 256], normalize_images=False)
    model = SAC(policy, train_env, learning_rate=LinearDecay(3e-4) if args.anneal_lr else 3e-4,
                buffer_size=decisions, batch_size=args.batch_size,
                learning_starts=args.learning_starts,
                replay_buffer_class=shifted_buffer(args.shift, args.seed) if args.shift else None,
                gamma=cfg.gamma, train_freq=1, gradient_steps=args.gradient_steps, seed=cfg.seed, verbose=0,
                policy_kwargs=policy_kwargs)
    if args.finetune_from:
        start_extractors(model, start_from)
    evaluator = Evaluator(cfg, 30, cfg.seed, wrap=lambda v: keypoints(policy_view(v, vlm, cfg)))
    start = time.time()
    with tqdm(total=cfg.steps, unit="step", desc=f"sac {cfg.reward} {cfg.goal}") as bar:
        callback = EvalAndCheckpoint(cfg, out, evaluator, [], bar)
        model.learn(decisions, callback=callback)
    final = evaluator(policy_act(model, True), 30)
    gradient_steps = model._n_updates
    write_json(out / "summary.json", {
        "final_mean": final["mean"], "final_se": final["se"], "final_success_rate": final["success_rate"],
        "env_steps": callback.env_steps(), "gradient_steps": gradient_steps, "wall_s": time.time() - start,
        "curve": callback.rows, "meta": {"learner": "stable-baselines3 SAC, its defaults but those named here",
                                         "envs": args.envs, "gradient_steps_per_step": args.gradient_steps,
                                         "batch_size": args.batch_size, "shift": args.shift,
                                         "keypoints_from": args.keypoints_from,
                                         "finetune_from": args.finetune_from, "anneal_lr": args.anneal_lr,
                                         "machine": "x86_64, 2 cores, no GPU",
                                         "command": "python probes/push_pixel_sac.py " + " ".join(argv or [])}})
    evaluator.close()
    train_env.close()


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])

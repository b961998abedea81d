"""Trained policies and checkpoints on disk: safetensors + JSON, never pickle.

A policy folder holds ``model.safetensors`` (the SB3 actor-critic's weights) and
``config.json`` (kind ``zsrm-policy``, the TrainConfig, the observation and action shapes), so
it loads without the env that trained it (a ``--learner sac`` run's: kind ``zsrm-sac-policy``, the
frozen keypoint extractor and SAC's actor; :func:`load_policy` reads either); the frozen VLM it sees through is named in the
config (``vlm``) and loaded from there.
"""
from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.policies import MultiInputActorCriticPolicy
from stable_baselines3.sac.policies import SACPolicy
from torch import nn

from zsrm.common.checkpoints import check_optimizer, load_optimizer, read_checkpoint_state
from zsrm.common.checkpoints import save_checkpoint as save_checkpoint_folder
from zsrm.common.registry import WEIGHTS_FILE, build_model, folder_kind, load_weights, read_config, save_folder
from zsrm.common.registry import save_weights as save_module_weights
from zsrm.rl.config import TrainConfig
from zsrm.rl.features import FEATURES_KEY, IMAGE_KEY, KeypointExtractor
from zsrm.rl.pretrain import freeze, keypoint_extractor, points_of
from zsrm.rl.resume import read_resume

KIND = "zsrm-policy"
SAC_KIND = "zsrm-sac-policy"
SAC_NET_ARCH = [256, 256]  # the hidden layers of a --learner sac run's actor and critics


def policy_kwargs(cfg: TrainConfig) -> dict:
    return dict(features_extractor_class=KeypointExtractor,
                features_extractor_kwargs=dict(keypoints=cfg.keypoints, pixels=cfg.pixels, pair_scale=cfg.pair_scale,
                                               pixel_stride=cfg.pixel_stride),
                net_arch=dict(pi=[256], vf=[256]), normalize_images=False, log_std_init=cfg.log_std_init)


class PolicyBundle:
    """An SB3 actor-critic and the settings it was trained with."""

    def __init__(self, policy: MultiInputActorCriticPolicy, cfg: TrainConfig):
        self.policy, self.cfg = policy, cfg

    def save(self, folder: str | Path) -> None:
        # The actor and critic share one feature extractor: save_folder keeps tied tensors once.
        config = {"kind": KIND, "config": self.cfg.to_dict(),
                  "observation_shape": list(self.policy.observation_space[FEATURES_KEY].shape),
                  "image_size": int(self.policy.observation_space[IMAGE_KEY].shape[-1]),
                  "action_dim": int(self.policy.action_space.shape[0])}
        save_folder(folder, config, {WEIGHTS_FILE: self.policy})

    @classmethod
    def load(cls, folder: str | Path) -> "PolicyBundle":
        """The policy in ``folder``: its config.json checked against the policy config (keys, types,
        the TrainConfig), its weights' names, shapes and dtypes against the policy that config
        describes, before anything is loaded; else one ZsrmFileError naming the file."""
        config = read_config(folder, kind=KIND, schema={
            "kind": str, "config": TrainConfig, "observation_shape": tuple[int, ...], "image_size": int,
            "action_dim": int})
        shape, size, cfg = config.observation_shape, config.image_size, config.config

        def make():
            if config.action_dim < 1:
                raise ValueError(f"action_dim must be positive, got {config.action_dim}")
            act_space = gym.spaces.Box(-1.0, 1.0, (config.action_dim,), np.float32)
            return MultiInputActorCriticPolicy(view_space(shape, size), act_space, lambda _: 0.0, **policy_kwargs(cfg))

        policy = build_model(folder, make)
        load_weights(policy, folder)  # checks the weights file first (zsrm.common.registry.check_weights)
        return cls(policy.eval(), cfg)

    @torch.no_grad()
    def act(self, observation: dict, deterministic: bool = True) -> np.ndarray:
        """Actions ``(N, action_dim)`` for a batch of observations of :class:`VecImageFeatures`."""
        actions, _ = self.policy.predict(observation, deterministic=deterministic)
        return actions


class SacPolicyBundle:
    """A SAC run's policy: the frozen keypoint extractor and SAC's actor, with the run's settings.
    Acts on the policy view as :class:`zsrm.rl.policy.PolicyBundle` does."""

    def __init__(self, extractor: KeypointExtractor, actor: nn.Module, cfg: TrainConfig):
        self.extractor, self.actor, self.cfg = extractor, actor, cfg

    def modules(self) -> nn.Module:
        return nn.ModuleDict({"extractor": self.extractor, "actor": self.actor})

    def save(self, folder: str | Path) -> None:
        space = self.extractor._observation_space
        shape, size = space.spaces[FEATURES_KEY].shape, space.spaces[IMAGE_KEY].shape[-1]
        save_folder(folder, {"kind": SAC_KIND, "config": self.cfg.to_dict(), "observation_shape": list(shape),
                             "image_size": int(size), "action_dim": int(self.actor.action_space.shape[0])},
                    {WEIGHTS_FILE: self.modules()})

    @classmethod
    def load(cls, folder: str | Path) -> "SacPolicyBundle":
        """The policy in ``folder``, its config and weights checked before anything is loaded."""
        config = read_config(folder, kind=SAC_KIND, schema={
            "kind": str, "config": TrainConfig, "observation_shape": tuple[int, ...], "image_size": int,
            "action_dim": int})
        cfg = config.config

        def make():
            extractor = keypoint_extractor(view_space(config.observation_shape, config.image_size), cfg.keypoints,
                                         cfg.pixel_stride)
            return nn.ModuleDict({"extractor": extractor, "actor": sac_actor(extractor.points_dim, config.action_dim)})

        modules = build_model(folder, make)
        load_weights(modules, folder)
        return cls(freeze(modules["extractor"]), modules["actor"].eval(), cfg)

    @torch.no_grad()
    def act(self, observation: dict, deterministic: bool = True) -> np.ndarray:
        """Actions ``(N, action_dim)`` for a batch of policy views."""
        return self.actor(points_of(self.extractor, observation), deterministic=deterministic).numpy()


def sac_actor(points_dim: int, action_dim: int) -> nn.Module:
    """An untrained actor of :func:`build_sac`'s shape."""
    space = gym.spaces.Box(-np.inf, np.inf, (points_dim,), np.float32)
    actions = gym.spaces.Box(-1.0, 1.0, (action_dim,), np.float32)
    return SACPolicy(space, actions, lambda _: 0.0, net_arch=SAC_NET_ARCH).actor


def view_space(shape: tuple[int, ...], image_size: int) -> gym.spaces.Dict:
    """The policy view's space (:func:`zsrm.rl.features.policy_view`) from a saved policy's shapes."""
    if min((*shape, image_size), default=0) < 1:
        raise ValueError(f"observation_shape and image_size must be positive, got {list(shape)} and {image_size}")
    return gym.spaces.Dict({FEATURES_KEY: gym.spaces.Box(0.0, np.inf, tuple(shape), np.float32),
                            IMAGE_KEY: gym.spaces.Box(0, 255, (3, image_size, image_size), np.uint8)})


def load_policy(folder: str | Path):
    """A policy folder of either learner: :class:`PolicyBundle` (PPO) or, for a ``--learner sac``
    run's, :class:`SacPolicyBundle`; both act on the policy view."""
    if folder_kind(folder) == SAC_KIND:
        return SacPolicyBundle.load(folder)
    return PolicyBundle.load(folder)


def save_checkpoint(folder: Path, model, cfg: TrainConfig, env_steps: int, rows: list[dict],
                    extra: dict | None = None, write_more=None) -> None:
    """Policy weights, optimiser and the step count, swapped in atomically; ``extra`` maps file
    names to more modules to keep (the curiosity baseline's ICM); ``write_more(folder)`` writes
    more files into it (the run's state for exact resume, :class:`zsrm.rl.resume.RunState`)."""
    state = {"config": cfg.identity(), "env_steps": int(env_steps), "rows": rows}

    def save_weights(tmp):
        PolicyBundle(model.policy, cfg).save(tmp)
        for file, module in (extra or {}).items():
            save_module_weights(module, tmp, file)
        if write_more is not None:
            write_more(tmp)

    save_checkpoint_folder(folder, save_weights, model.policy.optimizer, state)


def load_checkpoint(folder: Path, cfg: TrainConfig) -> dict | None:
    """The checkpoint's state plus ``restore(model)`` and ``resume`` (the run's state for exact
    resume, :func:`zsrm.rl.resume.read_resume`; None in a checkpoint written before it), or None
    when there is none."""
    if not (folder / "state.json").is_file():
        return None
    state = read_checkpoint_state(folder, cfg.identity(), {"env_steps": int, "rows": list})
    bundle = PolicyBundle.load(folder)
    check_optimizer(folder, bundle.policy.optimizer)  # before any work: a bad file is one line now
    state["resume"] = read_resume(folder)

    def restore(model, extra: dict | None = None):
        model.policy.load_state_dict(bundle.policy.state_dict())
        load_optimizer(folder, model.policy.optimizer)
        model.num_timesteps = state["env_steps"] // cfg.action_repeat
        for file, module in (extra or {}).items():
            load_weights(module, folder, file)

    state["restore"] = restore
    return state

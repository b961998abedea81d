"""Exact resume of ``zsrm train``: what a checkpoint keeps besides the policy and its optimiser.

A run killed at any moment and resumed gives the same ``eval.csv`` rows (wall time aside) and
the same final weights as an unbroken run, on the same machine and thread count. For that a
checkpoint is written after a rollout's PPO update (when the next rollout starts, and when
training ends), and holds everything the next update depends on:

* every random generator: Python's, numpy's, torch's (CPU, and CUDA's where used), the
  action space's, each training scene's, the auxiliary loss's minibatch order;
* the training scenes mid-episode (:mod:`zsrm.envs.state`: physics, step counters, grip);
* PPO's last observations and episode starts, which the next rollout starts from;
* the parts that learn beside PPO: the inverse-dynamics head's and ICM's optimisers, ICM's
  reward scale and last frames (their weights are saved with the policy);
* the training loop's counters: the next evaluation and checkpoint, the rewards seen since
  the last evaluation.

The evaluation envs need nothing: each evaluation reseeds them. Files: ``resume.json``,
``resume.safetensors`` and one ``optimizer-<part>/`` folder per extra optimiser; nothing
pickled. A checkpoint without them (written before exact resume) still resumes, at the right
step count but with fresh episodes and generators.
"""
from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback

from zsrm.common.checkpoints import load_optimizer, save_optimizer
from zsrm.common.files import ZsrmFileError, read_json, write_json
from zsrm.common.registry import load_tensors, save_tensors
from zsrm.envs.state import env_state, set_env_state

RESUME_JSON, RESUME_TENSORS = "resume.json", "resume.safetensors"
VERSION = 1


def _tensor(array) -> torch.Tensor:
    array = np.ascontiguousarray(array)
    if array.dtype == np.uint32:  # safetensors' torch side has no uint32
        array = array.astype(np.int64)
    return torch.from_numpy(array.copy())


def generator_state(rng) -> dict | None:
    """A numpy Generator's (or a gymnasium space's) bit generator state, JSON-able."""
    return None if rng is None else rng.bit_generator.state


def generator_from(state: dict) -> np.random.Generator:
    rng = np.random.Generator(getattr(np.random, state["bit_generator"])())
    rng.bit_generator.state = state
    return rng


def vec_chain(venv):
    """A VecEnv and each VecEnv it wraps, outermost first."""
    while venv is not None:
        yield venv
        venv = getattr(venv, "venv", None)


class RunState:
    """Saves and restores a training run's state (see the module's docstring). ``parts``: the
    callbacks and env wrappers with ``resume_state()`` -> ``(info, arrays, optimizers)`` and
    ``load_resume_state(info, arrays)`` -> ``optimizers``, keyed by a name each."""

    def __init__(self, model, parts: dict):
        self.model = model
        self.parts = dict(parts)
        for part in self.parts.values():
            if isinstance(part, BaseCallback):  # what it reads of the model now (learn sets it again)
                part.init_callback(model)
        for layer in vec_chain(model.get_env()):
            if hasattr(layer, "resume_state"):
                self.parts.setdefault(type(layer).__name__, layer)
        # the scenes: a DummyVecEnv's envs, or a WorkerVecEnv's, whose states its workers read and set
        self.scenes = [layer for layer in vec_chain(model.get_env())
                       if hasattr(layer, "envs") or hasattr(layer, "env_states")][-1]

    def env_states(self) -> list[tuple[dict, dict]]:
        if hasattr(self.scenes, "env_states"):
            return self.scenes.env_states()
        return [env_state(env) for env in self.scenes.envs]

    def ready(self) -> bool:
        """Has the run a state to save (it has stepped its envs)?"""
        return self.model._last_obs is not None

    def save(self, folder: Path) -> None:
        """Write the run's state into ``folder`` (a checkpoint being written)."""
        folder, model = Path(folder), self.model
        np_state = np.random.get_state()
        python_state = random.getstate()
        info = {"version": VERSION,
                "rng": {"python": [python_state[0], list(python_state[1]), python_state[2]],
                        "numpy": {"pos": int(np_state[2]), "has_gauss": int(np_state[3]),
                                  "cached_gaussian": float(np_state[4])},
                        "action_space": generator_state(getattr(model.action_space, "_np_random", None))},
                "num_timesteps": int(model.num_timesteps), "envs": [], "parts": {}}
        arrays = {"rng.numpy.keys": _tensor(np_state[1]), "rng.torch": torch.get_rng_state(),
                  "ppo.episode_starts": _tensor(np.asarray(model._last_episode_starts, bool))}
        if torch.cuda.is_available() and torch.cuda.is_initialized():
            for i, state in enumerate(torch.cuda.get_rng_state_all()):
                arrays[f"rng.cuda.{i}"] = state
        for key, value in model._last_obs.items():
            arrays[f"ppo.last_obs.{key}"] = _tensor(value)
        for i, (env_info, env_arrays) in enumerate(self.env_states()):
            info["envs"].append(env_info)
            arrays.update({f"env{i}.{k}": _tensor(v) for k, v in env_arrays.items()})
        for name, part in self.parts.items():
            part_info, part_arrays, optimizers = part.resume_state()
            info["parts"][name] = {"info": part_info, "optimizers": sorted(optimizers)}
            arrays.update({f"{name}.{k}": _tensor(v) for k, v in part_arrays.items()})
            for opt_name, opt in optimizers.items():
                sub = folder / f"optimizer-{opt_name}"
                sub.mkdir(parents=True, exist_ok=True)
                save_optimizer(opt, sub)
        save_tensors(arrays, folder / RESUME_TENSORS)
        write_json(folder / RESUME_JSON, info, indent=None)

    def restore(self, saved: dict) -> None:
        """Put back what :meth:`save` wrote (``saved``: :func:`read_resume`'s). Last thing before
        ``learn``: it sets the random generators, which building the run's parts reseeded. A state
        that does not fit this run is one ZsrmFileError."""
        try:
            self._restore(saved)
        except ZsrmFileError:
            raise
        except (KeyError, IndexError, TypeError, ValueError, AttributeError, RuntimeError) as err:
            first = str(err).strip().splitlines()[0][:200] if str(err).strip() else ""
            raise ZsrmFileError(f"{saved['folder']}: the run's state ({RESUME_JSON}, {RESUME_TENSORS}) does not fit "
                                f"this run ({type(err).__name__}: {first}); pass --fresh to start over") from None

    def _restore(self, saved: dict) -> None:
        info, arrays, folder = saved["info"], saved["arrays"], saved["folder"]
        model = self.model
        if len(info["envs"]) != self.scenes.num_envs:
            raise ZsrmFileError(f"{folder}: a state of {len(info['envs'])} training envs, this run has "
                                f"{self.scenes.num_envs}")
        if set(info["parts"]) != set(self.parts):
            raise ZsrmFileError(f"{folder}: a state of the parts {sorted(info['parts'])}, this run has {sorted(self.parts)}")
        states = [(info["envs"][i], {k[len(f"env{i}."):]: v.numpy() for k, v in arrays.items()
                                     if k.startswith(f"env{i}.")}) for i in range(self.scenes.num_envs)]
        if hasattr(self.scenes, "set_env_states"):
            self.scenes.set_env_states(states)
        else:
            for env, (env_info, env_arrays) in zip(self.scenes.envs, states):
                set_env_state(env, env_info, env_arrays)
        model._last_obs = {k[len("ppo.last_obs."):]: v.numpy() for k, v in arrays.items() if k.startswith("ppo.last_obs.")}
        model._last_episode_starts = arrays["ppo.episode_starts"].numpy()
        model.num_timesteps = info["num_timesteps"]
        for name, part in self.parts.items():
            prefix = f"{name}."
            entry = info["parts"][name]
            optimizers = part.load_resume_state(entry["info"], {k[len(prefix):]: v.numpy() for k, v in arrays.items()
                                                                 if k.startswith(prefix)})
            for opt_name in entry["optimizers"]:
                load_optimizer(folder / f"optimizer-{opt_name}", optimizers[opt_name])
        rng = info["rng"]
        if rng["action_space"] is not None:
            model.action_space._np_random = generator_from(rng["action_space"])
        python = rng["python"]
        random.setstate((python[0], tuple(python[1]), python[2]))
        np.random.set_state(("MT19937", arrays["rng.numpy.keys"].numpy().astype(np.uint32), rng["numpy"]["pos"],
                             rng["numpy"]["has_gauss"], rng["numpy"]["cached_gaussian"]))
        torch.set_rng_state(arrays["rng.torch"])
        cuda = [arrays[k] for k in sorted(k for k in arrays if k.startswith("rng.cuda."))]
        if cuda and torch.cuda.is_available() and len(cuda) == torch.cuda.device_count():
            torch.cuda.set_rng_state_all(cuda)


def read_resume(folder: Path) -> dict | None:
    """The run state in checkpoint ``folder``, read and checked before any work (one
    ZsrmFileError naming the file when it is damaged); None when the checkpoint has none."""
    folder = Path(folder)
    if not (folder / RESUME_JSON).is_file():
        return None
    info = read_json(folder / RESUME_JSON, "a training run's state")
    if not isinstance(info, dict) or info.get("version") != VERSION or not {"rng", "envs", "parts"} <= set(info):
        raise ZsrmFileError(f"{folder / RESUME_JSON} is not a training run's state of version {VERSION}; "
                            "pass --fresh to start over")
    arrays = load_tensors(folder / RESUME_TENSORS)
    missing = [k for k in ("rng.torch", "rng.numpy.keys", "ppo.episode_starts") if k not in arrays]
    if missing:
        raise ZsrmFileError(f"{folder / RESUME_TENSORS}: missing {', '.join(missing)}; pass --fresh to start over")
    return {"info": info, "arrays": arrays, "folder": folder}


"""A scene's whole state mid-episode, read and written back: what exact resume of ``zsrm train``
saves for each training env.

:func:`env_state` reads everything the next ``step`` of an env made by ``gym.make`` depends on:

* MuJoCo's integration state (``mj_getState(mjSTATE_INTEGRATION)``: time, positions,
  velocities, controls, mocap targets, active welds, the solver's warm start), with which
  MuJoCo simulates bit for bit as before;
* the kinematics the last step left (``xpos``, ``xquat``, ...): they are those of the last
  substep's start, not of the state, and a step reads the gripper's and blocks' positions
  before it simulates (which block the fingers close on, the weld's pose);
* the model fields a scene changes as it runs (weld anchors, the box's place);
* the scene's own attributes (grip state, held block), its random generator, and the
  wrappers' counters (the time limit's elapsed steps).

:func:`set_env_state` writes them into an env built with the same arguments. The state is a
JSON-able dict and a dict of arrays (for safetensors): nothing is pickled.

>>> import gymnasium as gym, numpy as np, zsrm.envs
>>> a = gym.make("zsrm/Pushing-v0", task="push_close", image_size=32)
>>> b = gym.make("zsrm/Pushing-v0", task="push_close", image_size=32)
>>> _ = a.reset(seed=0); _ = a.step(np.array([0.5, -0.5], np.float32))
>>> set_env_state(b, *env_state(a))
>>> action = np.array([0.3, 0.2], np.float32)
>>> np.array_equal(a.step(action)[0]["front"], b.step(action)[0]["front"])
True
"""
from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.wrappers import PassiveEnvChecker

# What a step may read before its first mj_step recomputes it (the kinematics of the last substep)
KINEMATICS = ("xpos", "xquat", "xmat", "xipos", "ximat", "geom_xpos", "geom_xmat", "site_xpos", "site_xmat")
# Model fields the scenes change while they run (tabletop: the box's place, the grasp welds' poses)
MODEL_FIELDS = ("body_pos", "body_quat", "eq_data")
# Python attributes of the scenes and wrappers that carry from one step to the next
ATTRIBUTES = ("held", "closed", "_hold_at_reset", "_elapsed_steps", "_has_reset")
INTEGRATION = mujoco.mjtState.mjSTATE_INTEGRATION


def _chain(env):
    """The env and each env it wraps, outermost first."""
    while True:
        yield env
        if not isinstance(env, gym.Wrapper):
            return
        env = env.env


def env_state(env: gym.Env, prefix: str = "") -> tuple[dict, dict[str, np.ndarray]]:
    """``(info, arrays)``: the env's state (see the module's docstring)."""
    info: dict = {}
    arrays: dict[str, np.ndarray] = {}
    for depth, layer in enumerate(_chain(env)):
        attrs = {k: getattr(layer, k) for k in ATTRIBUTES if k in vars(layer)}
        if attrs:
            info[f"{prefix}{depth}.attributes"] = attrs
    base = env.unwrapped
    rng = vars(base).get("_np_random")
    info[f"{prefix}np_random"] = None if rng is None else rng.bit_generator.state
    if isinstance(getattr(base, "data", None), mujoco.MjData):
        model, data = base.model, base.data
        state = np.empty(mujoco.mj_stateSize(model, INTEGRATION), np.float64)
        mujoco.mj_getState(model, data, state, INTEGRATION)
        arrays[f"{prefix}mj.state"] = state
        for name in KINEMATICS:
            arrays[f"{prefix}mj.data.{name}"] = np.array(getattr(data, name))
        for name in MODEL_FIELDS:
            arrays[f"{prefix}mj.model.{name}"] = np.array(getattr(model, name))
    inner = vars(base).get("_env")
    if isinstance(inner, gym.Env):  # a scene around a gymnasium env (the double pendulum)
        more_info, more_arrays = env_state(inner, f"{prefix}inner.")
        info.update(more_info)
        arrays.update(more_arrays)
    return info, arrays


def set_env_state(env: gym.Env, info: dict, arrays: dict[str, np.ndarray], prefix: str = "") -> None:
    """Write back what :func:`env_state` read (into an env built with the same arguments)."""
    for depth, layer in enumerate(_chain(env)):
        for k, v in info.get(f"{prefix}{depth}.attributes", {}).items():
            setattr(layer, k, v)
        if isinstance(layer, PassiveEnvChecker):  # it checked the first reset and steps before the save
            layer.checked_reset = layer.checked_step = layer.checked_data_reuse = True
            layer._previous_data = None
    base = env.unwrapped
    rng_state = info.get(f"{prefix}np_random")
    if rng_state is not None:
        rng = np.random.Generator(getattr(np.random, rng_state["bit_generator"])())
        rng.bit_generator.state = rng_state
        base._np_random = rng
    if f"{prefix}mj.state" in arrays:
        model, data = base.model, base.data
        state = np.asarray(arrays[f"{prefix}mj.state"], np.float64)
        if state.size != mujoco.mj_stateSize(model, INTEGRATION):
            raise ValueError(f"a saved scene state of {state.size} numbers does not fit this scene "
                             f"({mujoco.mj_stateSize(model, INTEGRATION)})")
        for name in MODEL_FIELDS:
            getattr(model, name)[...] = arrays[f"{prefix}mj.model.{name}"]
        mujoco.mj_setState(model, data, state, INTEGRATION)
        mujoco.mj_forward(model, data)  # everything derived from it ...
        mujoco.mj_setState(model, data, state, INTEGRATION)  # (the warm start as saved)
        # ... and over that the last substep's kinematics, as the last step left them
        for name in KINEMATICS:
            getattr(data, name)[...] = arrays[f"{prefix}mj.data.{name}"]
    inner = vars(base).get("_env")
    if isinstance(inner, gym.Env):
        set_env_state(inner, info, arrays, f"{prefix}inner.")

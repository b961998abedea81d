"""Making a scene by name and running it: the one rollout loop everything that rolls out uses.

>>> from zsrm.envs.rollout import make_env, run_episode
>>> from zsrm.envs.scripted import scripted_controller
>>> env = make_env("stack")
>>> run_episode(env, scripted_controller, seed=0)["success"]
True
"""
from __future__ import annotations

from typing import Callable, Iterator

import numpy as np

# A policy maker: given the env just reset, returns the callable that gives each action.
PolicyMaker = Callable[[object], Callable[[], np.ndarray]]


def make_env(name_or_goal: str, **kwargs):
    """A registered env for a catalogue name or a goal sentence."""
    import gymnasium as gym

    import zsrm.envs  # noqa: F401  (registers the ids)
    from zsrm.tasks.catalogue import PENDULUM_ID, resolve

    entry = resolve(name_or_goal)
    if entry.env_id == PENDULUM_ID:
        kwargs.pop("cameras", None)
        kwargs.pop("spread", None)
    return gym.make(entry.env_id, task=entry.goal, **kwargs)


def camera_strip(env, size: int) -> np.ndarray:
    """All cameras of a scene side by side, as one image."""
    return np.concatenate(list(env.unwrapped.render_cameras(size=size).values()), axis=1)


def random_policy(env) -> Callable[[], np.ndarray]:
    """Uniform random actions from the env's action space (seeded by :func:`episode_steps`)."""
    return env.action_space.sample


def episode_steps(env, policy: PolicyMaker, seed: int, max_steps: int | None = None
                  ) -> Iterator[tuple[int, dict, dict, bool]]:
    """One seeded episode, step by step: yields ``(t, observation, info, done)``, first for the
    reset frame (t = 0), then after each step, until the episode ends or ``max_steps`` steps.

    ``policy(env)`` is called once after the reset (a scripted controller reads the new
    scene); the action space is seeded with ``seed`` too, so random policies repeat. While
    a step is being handled the env shows that frame (e.g. for :func:`camera_strip`).
    """
    obs, info = env.reset(seed=seed)
    env.action_space.seed(seed)
    act = policy(env)
    t, done = 0, False
    yield t, obs, info, done
    while not done and (max_steps is None or t < max_steps):
        obs, _, terminated, truncated, info = env.step(act())
        t += 1
        done = bool(terminated or truncated)
        yield t, obs, info, done


def run_episode(env, policy: PolicyMaker, seed: int, max_steps: int | None = None) -> dict:
    """One episode; returns the oracle's verdict at the end and the steps the goal held."""
    steps_in_goal, steps, info = 0, 0, {}
    for t, _, info, _ in episode_steps(env, policy, seed, max_steps):
        if t:
            steps, steps_in_goal = t, steps_in_goal + int(info["is_success"])
    return {"success": bool(info["is_success"]), "steps_in_goal": steps_in_goal, "steps": steps}


def run_vec_episodes(venv, act: Callable[[dict], np.ndarray], key: str = "oracle_steps",
                     also: tuple[str, ...] = ()) -> dict:
    """One episode in each env of a vectorised env (SB3 ``VecEnv``), all stepped together:
    ``act`` maps a batch of observations to a batch of actions. Returns each episode's oracle
    reward (the sum of ``info[key]``: by default the control steps in the goal relation; the
    pendulum's env reward with ``key="oracle_reward"``) and whether the goal held at its end;
    with ``also``, each episode's sum of those info keys too (under their names).
    """
    n = venv.num_envs
    obs = venv.reset()
    totals, success, running = np.zeros(n), np.zeros(n, dtype=bool), np.ones(n, dtype=bool)
    extra = {k: np.zeros(n) for k in also}
    while running.any():
        obs, _, dones, infos = venv.step(act(obs))
        for i, info in enumerate(infos):
            if running[i]:
                totals[i] += info.get(key, int(info["is_success"]))
                for k in also:
                    extra[k][i] += info[k]
                if dones[i]:
                    success[i], running[i] = bool(info["is_success"]), False
    return {"episode_rewards": totals.tolist(), "successes": success.tolist(),
            **{k: v.tolist() for k, v in extra.items()}}

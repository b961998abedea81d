"""The training envs stepped in worker processes, so that one run uses a second core for its
scenes while the learner keeps one torch thread (``zsrm train --env-workers 2``).

:class:`WorkerVecEnv` splits the envs into contiguous groups, one per worker; each worker steps
its group as a :class:`~stable_baselines3.common.vec_env.DummyVecEnv` does, seeded with the
same per-env seeds. Observations, rewards, dones and infos come back concatenated in env order:
the same numbers as one DummyVecEnv of all the envs (a test checks a run's policy byte for
byte), so a run's results do not depend on how many workers stepped it.

SB3's SubprocVecEnv runs one process per env: with 16 envs on 2 cores its processes would
compete for the cores and its pipes would carry 16 messages per step instead of 2.
"""
from __future__ import annotations

import multiprocessing as mp
from typing import Any, Callable, Sequence

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv
from stable_baselines3.common.vec_env.base_vec_env import CloudpickleWrapper


def _work(remote, parent_remote, fns: CloudpickleWrapper) -> None:
    from zsrm.envs.state import env_state, set_env_state

    parent_remote.close()
    venv = DummyVecEnv(fns.var)
    try:
        while True:
            cmd, data = remote.recv()
            if cmd == "step":
                remote.send(venv.step(data))
            elif cmd == "reset":
                venv._seeds, venv._options = data  # as DummyVecEnv.seed / set_options leave them
                remote.send((venv.reset(), venv.reset_infos))
            elif cmd == "spaces":
                remote.send((venv.observation_space, venv.action_space))
            elif cmd == "get_attr":
                remote.send(venv.get_attr(data))
            elif cmd == "set_attr":
                remote.send(venv.set_attr(*data))
            elif cmd == "env_method":
                name, args, kwargs = data
                remote.send(venv.env_method(name, *args, **kwargs))
            elif cmd == "is_wrapped":
                remote.send(venv.env_is_wrapped(data))
            elif cmd == "states":
                remote.send([env_state(env) for env in venv.envs])
            elif cmd == "set_states":
                for env, (info, arrays) in zip(venv.envs, data):
                    set_env_state(env, info, arrays)
                remote.send(None)
            elif cmd == "close":
                venv.close()
                remote.send(None)
                break
    except (KeyboardInterrupt, EOFError, BrokenPipeError):  # the run stopped or its process died
        pass
    finally:
        remote.close()


class WorkerVecEnv(VecEnv):
    """``env_fns`` stepped by ``workers`` processes, each holding a contiguous group of the envs."""

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]], workers: int):
        n = len(env_fns)
        workers = max(1, min(int(workers), n))
        bounds = np.linspace(0, n, workers + 1).round().astype(int)
        self.groups = [range(a, b) for a, b in zip(bounds[:-1], bounds[1:])]
        # spawn, not fork: a forked child would share the parent's MuJoCo GL contexts
        ctx = mp.get_context("spawn")
        self.remotes, self.processes, self.closed = [], [], False
        for group in self.groups:
            remote, work_remote = ctx.Pipe()
            fns = CloudpickleWrapper([env_fns[i] for i in group])
            process = ctx.Process(target=_work, args=(work_remote, remote, fns), daemon=True)
            process.start()
            work_remote.close()
            self.remotes.append(remote)
            self.processes.append(process)
        self.remotes[0].send(("spaces", None))
        observation_space, action_space = self.remotes[0].recv()
        super().__init__(n, observation_space, action_space)

    def _gather(self, results: list) -> list:
        return [x for part in results for x in part]

    def _obs(self, parts: list) -> Any:
        if isinstance(self.observation_space, gym.spaces.Dict):
            return {k: np.concatenate([p[k] for p in parts]) for k in self.observation_space.spaces}
        return np.concatenate(parts)

    def reset(self):
        for remote, group in zip(self.remotes, self.groups):
            remote.send(("reset", ([self._seeds[i] for i in group], [self._options[i] for i in group])))
        results = [remote.recv() for remote in self.remotes]
        self.reset_infos = self._gather([infos for _, infos in results])
        self._reset_seeds()
        self._reset_options()
        return self._obs([obs for obs, _ in results])

    def step_async(self, actions: np.ndarray) -> None:
        for remote, group in zip(self.remotes, self.groups):
            remote.send(("step", actions[group.start:group.stop]))

    def step_wait(self):
        results = [remote.recv() for remote in self.remotes]
        obs, rewards, dones, infos = zip(*results)
        return self._obs(list(obs)), np.concatenate(rewards), np.concatenate(dones), self._gather(list(infos))

    def _ask(self, cmd: str, data, indices) -> list:
        wanted = set(self._get_indices(indices))
        asked = []
        for remote, group in zip(self.remotes, self.groups):
            if wanted & set(group):
                remote.send((cmd, data))
                asked.append((remote, group))
        return [value for remote, group in asked for i, value in zip(group, remote.recv()) if i in wanted]

    def get_attr(self, attr_name: str, indices=None) -> list:
        return self._ask("get_attr", attr_name, indices)

    def set_attr(self, attr_name: str, value, indices=None) -> None:
        wanted = set(self._get_indices(indices))
        for remote, group in zip(self.remotes, self.groups):
            remote.send(("set_attr", (attr_name, value, [i - group.start for i in group if i in wanted])))
            remote.recv()

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list:
        return self._ask("env_method", (method_name, method_args, method_kwargs), indices)

    def env_is_wrapped(self, wrapper_class, indices=None) -> list:
        return self._ask("is_wrapped", wrapper_class, indices)

    def env_states(self) -> list[tuple[dict, dict]]:
        """:func:`zsrm.envs.state.env_state` of every env, in env order (a checkpoint's)."""
        for remote in self.remotes:
            remote.send(("states", None))
        return self._gather([remote.recv() for remote in self.remotes])

    def set_env_states(self, states: Sequence[tuple[dict, dict]]) -> None:
        """Put back :meth:`env_states`' states (a resumed run's)."""
        for remote, group in zip(self.remotes, self.groups):
            remote.send(("set_states", [states[i] for i in group]))
        for remote in self.remotes:
            remote.recv()

    def close(self) -> None:
        if self.closed:
            return
        for remote in self.remotes:
            try:
                remote.send(("close", None))
                remote.recv()
            except (BrokenPipeError, EOFError):
                pass
        for process in self.processes:
            process.join(timeout=10)
            if process.is_alive():
                process.terminate()
        self.closed = True

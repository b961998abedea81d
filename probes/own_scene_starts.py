"""Why the example scene's goals train in its task scenes: the oracle episode reward of a random
policy, of PPO's starting policy (a unit Gaussian, clipped) and of forward-biased ones (its y
action drawn around +1 or +2) for each start layout and pusher step size of the example env.

PPO's policy starts as such a Gaussian of unit spread; where a bias toward pushing ahead scores
no better than no bias, its gradient has nothing to climb. Writes
results/side/own_scene/starts.json.

    python probes/own_scene_starts.py
"""
import argparse
import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # examples/ is not installed

from examples.own_scene.adapter import OwnScene  # noqa: E402
from zsrm.common.files import write_json  # noqa: E402
from zsrm.envs.rollout import episode_steps, random_policy  # noqa: E402
from zsrm.envs.scene_task import SceneTask  # noqa: E402
from zsrm.rl.goals import scene_goal  # noqa: E402

SPEC = "examples.own_scene.adapter:OwnScene"
SETTINGS = {"anywhere, 2 cm": {"start": "anywhere", "step_size": 0.02},
            "compact, 2 cm": {"start": "compact", "step_size": 0.02},
            "compact, 1 cm (the task scenes)": {"start": "compact", "step_size": 0.01}}
# None: uniform in [-1, 1]; a number: PPO's starting policy (unit Gaussian, clipped) with its y mean there.
POLICIES = {"uniform": None, "Gaussian (PPO's start)": 0.0, "forward-biased (y around +1)": 1.0,
            "forward-biased (y around +2)": 2.0}


def policy_maker(bias):
    """Uniform (None) or PPO's starting Gaussian with its y mean at ``bias``, drawn from the
    action space's generator, which :func:`episode_steps` seeds with each episode's seed."""
    if bias is None:
        return random_policy
    return lambda env: lambda: np.clip(env.action_space.np_random.normal((0.0, bias), 1.0), -1, 1)


def episode_rewards(env, bias, episodes: int) -> list[int]:
    """Each seeded episode's oracle episode reward: its control steps in the goal relation."""
    return [sum(info["oracle_steps"] for t, _, info, _ in episode_steps(env, policy_maker(bias), seed=ep) if t)
            for ep in range(episodes)]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goal", default="a red cylinder behind a purple cylinder")
    parser.add_argument("--episodes", type=int, default=300)
    parser.add_argument("--action-repeat", type=int, default=4)
    parser.add_argument("--out", default="results/side/own_scene/starts.json")
    args = parser.parse_args(argv)
    adapter, goal = OwnScene(), scene_goal(args.goal, SPEC)
    table = {}
    for name, kwargs in SETTINGS.items():
        adapter.task_env_kwargs = kwargs
        env = gym.wrappers.TimeLimit(SceneTask(adapter.make_env((adapter.roles["left"],), 16, goal.objects, task=True),
                                               adapter, goal, args.action_repeat), 100 // args.action_repeat)
        table[name] = {}
        for policy, bias in POLICIES.items():
            r = np.asarray(episode_rewards(env, bias, args.episodes), float)
            table[name][policy] = {"mean": float(r.mean()), "se": float(r.std(ddof=1) / np.sqrt(len(r))),
                                   "success_episodes": float((r > 0).mean())}
            print(f"{name:34s} {policy:30s} {r.mean():5.1f} +- {table[name][policy]['se']:.1f}", flush=True)
        env.close()
    write_json(args.out, {"goal": args.goal, "settings": SETTINGS, "oracle_episode_reward": table,
                          "meta": {"command": "python probes/own_scene_starts.py" + "".join(f" {a}" for a in sys.argv[1:]),
                                   "episodes": args.episodes, "action_repeat": args.action_repeat}}, indent=1)
    print(json.dumps({"wrote": args.out}))


if __name__ == "__main__":
    main()

"""How often random actions end an episode with an object off the table, and the fastest an
object moved (diagnostic for the scene fixes of issue 11; prints, writes nothing).

    python probes/scene_falls.py --task stack --episodes 200
"""
import argparse

import gymnasium as gym
import numpy as np

import zsrm.envs  # noqa: F401


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="stack")
    parser.add_argument("--episodes", type=int, default=200)
    args = parser.parse_args(argv)
    env_id = "zsrm/Pushing-v0" if args.task == "push_close" else "zsrm/Tabletop-v0"
    env = gym.make(env_id, task=args.task, image_size=16)
    base = env.unwrapped
    falls, fastest = 0, 0.0
    for ep in range(args.episodes):
        env.reset(seed=ep)
        rng = np.random.default_rng(ep)
        for _ in range(100):
            *_, terminated, truncated, _ = env.step(rng.uniform(-1, 1, env.action_space.shape))
            for colour in base.objects:
                adr = base.model.jnt_dofadr[base.model.body_jntadr[base._body(colour)]]
                fastest = max(fastest, float(np.linalg.norm(base.data.qvel[adr:adr + 3])))
            if terminated or truncated:
                falls += int(terminated)
                break
    print(f"{args.task}: {falls} of {args.episodes} random episodes ended with an object off the table; "
          f"fastest object {fastest:.2f} m/s")


if __name__ == "__main__":
    main()

"""The full model on the example scene of ``examples/own_scene``: a call of ``zsrm own-scene``
(the one command that runs the own-scene chain on any adapter) with the example's goals and its
PPO goal, writing ``results/own_scene.json``.

The chain's stages, its gates and its report: ``zsrm own-scene --help`` and docs/own-scene.md.
Every stage resumes or is skipped when its output is there.

    python benchmarks/own_scene.py                     # about 1 hour on 2 cores, PPO included
    python benchmarks/own_scene.py --until eval-reward # the reward model alone: about 25 min
    python benchmarks/own_scene.py --dry-run           # the stages
"""
from __future__ import annotations

import argparse
import sys

SCENE = "examples.own_scene.adapter:OwnScene"
GOALS = ("a red cylinder on the right of a purple cylinder", "an orange cylinder on the left of a red cylinder",
         "a red cylinder behind a purple cylinder")
# The goal PPO learns: in the adapter's task scenes the pusher starts in front of an object and
# moves in 1 cm steps, so pushing one back past another is a push straight ahead; pushing one
# sideways past another, the other goals' relations, needs the pusher to go round first
# (docs/own-scene.md).
PPO_GOAL = GOALS[2]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", default="runs/own-scene", help="folder of every stage's data, models and report")
    parser.add_argument("--out", default="results/own_scene.json")
    parser.add_argument("--steps", type=int, default=300_000, help="env steps of each PPO trial")
    parser.add_argument("--until", default=None, help="stop after this stage (e.g. eval-reward: no PPO)")
    parser.add_argument("--dry-run", action="store_true", help="print the stages and stop")
    args = parser.parse_args(argv)
    from zsrm.cli import main as zsrm

    command = ["own-scene", "--scene", SCENE, "--goals", *GOALS, "--out", args.work, "--results", args.out,
               "--ppo-goal", PPO_GOAL, "--ppo-steps", str(args.steps)]
    command += ["--until", args.until] if args.until else []
    command += ["--dry-run"] if args.dry_run else []
    return zsrm(command)


if __name__ == "__main__":
    sys.exit(main())

"""The ``zsrm`` command line: one subcommand per pipeline stage, argparse wiring only.

Each command is a dataclass of :mod:`zsrm.pipeline` (its fields are the options, its
``run()`` the stage); :mod:`zsrm.cli.options` turns the fields into arguments. To add a
command, add its dataclass to ``COMMANDS``. No library module imports this package.
"""
from __future__ import annotations

import argparse
import os
import sys

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

from zsrm.cli.options import add_command, from_namespace  # noqa: E402
from zsrm.pipeline import build, demo, distill, goals, learn, measure, own_scene, reproduce, results_page  # noqa: E402

COMMANDS = {
    "parse-goal": goals.ParseGoal,
    "render": measure.Render,
    "scripted-eval": measure.ScriptedEval,
    "demo": demo.Demo,
    "pretrain-vlm": build.PretrainVlm,
    "eval-vlm": measure.EvalVlm,
    "eval-pose": measure.EvalPose,
    "reward": measure.Reward,
    "reward-curve": measure.RewardCurve,
    "collect": build.Collect,
    "label": build.Label,
    "eval-grounding": measure.EvalGrounding,
    "reward-data": build.RewardData,
    "finetune": build.Finetune,
    "eval-reward": measure.EvalReward,
    "own-scene": own_scene.SceneChain,
    "eval-goals": goals.EvalGoals,
    "train": learn.Train,
    "rollout": learn.Rollout,
    "sweep": learn.Sweep,
    "plot": learn.Plot,
    "multitask-policies": distill.MultitaskPolicies,
    "multitask-rollouts": distill.MultitaskRollouts,
    "distill": distill.Distill,
    "eval-multitask": distill.EvalMultitask,
    "reproduce": reproduce.Reproduce,
    "results-page": results_page.ResultsPage,
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="zsrm", description="Zero-shot rewards from goal sentences and images.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, cls in COMMANDS.items():
        add_command(sub, name, cls)
    return parser


def main(argv=None) -> int:
    from zsrm.tasks.language import GoalError

    args = build_parser().parse_args(argv)
    try:
        return from_namespace(args.options_class, args).run() or 0
    except (GoalError, ValueError, OSError) as err:
        # Bad input, a bad or missing file, a path that cannot be written (zsrm.common.files.ZsrmFileError is a
        # ValueError): one clear line, no traceback (ZSRM_DEBUG=1 shows it).
        if os.environ.get("ZSRM_DEBUG"):
            raise
        print(f"zsrm {args.command}: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

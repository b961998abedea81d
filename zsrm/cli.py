"""The ``zsrm`` command line: one subcommand per pipeline stage.

Each stage module defines ``add_command(subparsers)``, which registers its subcommand and
sets ``func`` on it; add the module to ``COMMAND_MODULES`` to expose it.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

COMMAND_MODULES = [
    "zsrm.envs.commands",  # render, scripted-eval
    "zsrm.demo",  # demo
    "zsrm.vlm.commands",  # pretrain-vlm, eval-vlm
    "zsrm.rewards.commands",  # reward, reward-curve
    "zsrm.reward_model.commands",  # finetune, eval-reward
    "zsrm.grounding.commands",  # collect, label, eval-grounding
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="zsrm", description="Zero-shot rewards from goal sentences and images.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).add_command(sub)
    return parser


def main(argv=None) -> int:
    from zsrm.tasks.language import GoalError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args) or 0
    except (GoalError, ValueError, FileNotFoundError) as err:
        # Bad input or a missing file: one clear line, no traceback (ZSRM_DEBUG=1 shows it).
        if os.environ.get("ZSRM_DEBUG"):
            raise
        print(f"zsrm {args.command}: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

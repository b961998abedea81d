"""Which block do the distilled policies stack on in choice scenes? (Base or third block.)

In a choice scene (``zsrm train --choice``) the moved block starts between its base and a third
block, the base on either side at random. A policy that finds its base (by the goal's colours,
or by its primitive code) stacks on it; one that does not stacks on either about as often. On
the stacking goals of Table 2 (same seeds and scenes as ``zsrm eval-multitask`` of a
choice-scene distillation), per policy and split: the control steps of 100 with the moved
block on its base (the oracle episode reward) and on the third block.

    OMP_NUM_THREADS=1 python probes/choice_base_probe.py \\
        --policies runs/multitask/distill-choice --out results/side/multitask/choice/base_probe.json
"""
from __future__ import annotations

import argparse

from tqdm import tqdm

from zsrm.common.files import write_json
from zsrm.envs.tabletop import TabletopEnv
from zsrm.evaluation.multitask import EVAL_SEED, OnThirdBlock, split_goals, task_episodes, task_seed
from zsrm.policy.models import embed_goals
from zsrm.policy.training import load_distilled
from zsrm.rl.evaluate import mean_se_cell
from zsrm.tasks.language import parse_goal
from zsrm.vlm import load_vlm


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policies", default="runs/multitask/distill-choice", help="the folder zsrm distill wrote")
    parser.add_argument("--spread", default="seen", choices=("seen", "unseen"))
    parser.add_argument("--seeds", type=int, default=50, help="seeded episodes per goal")
    parser.add_argument("--tasks", type=int, default=None, help="only the first N stacking goals per split")
    parser.add_argument("--out", default="results/side/multitask/choice/base_probe.json")
    args = parser.parse_args()

    summary, policies = load_distilled(args.policies)
    vlm = load_vlm(summary["vlm"])
    stacking = {split: [(i, g) for i, g in enumerate(goals) if parse_goal(g).relation == "on_top_of"][:args.tasks]
                for split, goals in split_goals().items()}
    out = {"policies": args.policies, "spread": args.spread, "seeds": args.seeds, "eval_seed": EVAL_SEED,
           "metric": "control steps of 100 with the goal's moved block on its base (on_base) or on the third "
                     "block (on_third); mean and s.e. over the split's episodes"}
    for name, policy in policies.items():
        for split, goals in stacking.items():
            on_base, on_third, per_task = [], [], {}
            for i, goal in tqdm(goals, desc=f"{name} {split}", leave=False):
                mover = TabletopEnv.task_mover(parse_goal(goal))
                embedding = embed_goals(vlm, [goal], policy.cfg.text_embedding)
                result = task_episodes(policy, goal, embedding, args.seeds, args.spread, task_seed(i), choice=True,
                                       wrap=lambda venv, colour: OnThirdBlock(venv, mover, colour), also=("on_third",))
                on_base += result["episode_rewards"]
                on_third += result["on_third"]
                per_task[goal] = {"on_base": sum(result["episode_rewards"]) / args.seeds,
                                  "on_third": sum(result["on_third"]) / args.seeds}
            cell = {"on_base": mean_se_cell(on_base), "on_third": mean_se_cell(on_third)}
            out.setdefault(name, {})[split] = {**cell, "per_task": per_task}
            print(f"{name:>9} {split:>5}: on base {cell['on_base']['mean']:5.1f} +- {cell['on_base']['se']:.1f}, "
                  f"on the third block {cell['on_third']['mean']:5.1f} +- {cell['on_third']['se']:.1f}")
    write_json(args.out, out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

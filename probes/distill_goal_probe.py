"""What do the distilled policies need from their goal? (Why language ties primitive in Table 2.)

The tabletop's task scenes start the gripper above the block the goal moves, so the scene
already says which block to pick. On the stacking tasks (where all of Table 2's points are),
this runs each policy on a goal's scenes while it reads another sentence:

* ``own``: the goal itself (as ``zsrm eval-multitask``);
* ``swapped``: the goal's colours swapped ("a red block on top of a blue block" for "a blue
  block on top of a red block"): the other block is to be moved. A policy that follows the
  colours should now fail; one that reads only the relation scores as with ``own``;
* ``left_of``: the same colours in another relation ("... on the left of ..."), to check that
  the policy reads its goal at all.

The primitive policy reads each sentence's nearest training code, as in Table 2 (on training
goals, a swapped sentence is itself a training goal). Scored as ``zsrm eval-multitask``
scores (same seeds, oracle episode reward of the real goal).

    OMP_NUM_THREADS=1 python probes/distill_goal_probe.py \\
        --policies runs/multitask/distill --out results/side/multitask/goal_probe.json
"""
from __future__ import annotations

import argparse

from tqdm import tqdm

from zsrm.common.files import write_json
from zsrm.evaluation.multitask import EVAL_SEED, split_goals, task_rewards, task_seed
from zsrm.policy.models import embed_goals
from zsrm.policy.training import load_distilled
from zsrm.rl.evaluate import mean_se_cell
from zsrm.tasks.language import Task, parse_goal
from zsrm.vlm import load_vlm

PROBED = ("language", "primitive")


def readings(goal: str) -> dict[str, str]:
    """The sentences a policy reads on ``goal``'s scenes (a stacking goal)."""
    a, b = parse_goal(goal).objects
    return {"own": goal, "swapped": Task("on_top_of", (b, a)).text, "left_of": Task("left_of", (a, b)).text}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policies", default="runs/multitask/distill", help="the folder zsrm distill wrote")
    parser.add_argument("--spread", default="seen", choices=("seen", "unseen"))
    parser.add_argument("--seeds", type=int, default=50, help="seeded episodes per goal and reading")
    parser.add_argument("--tasks", type=int, default=None, help="only the first N stacking goals per split")
    parser.add_argument("--out", default="results/side/multitask/goal_probe.json")
    args = parser.parse_args()

    summary, policies = load_distilled(args.policies)
    policies = {name: policies[name] for name in PROBED if name in policies}
    if not policies:
        raise SystemExit(f"{args.policies} holds no {' or '.join(PROBED)} policy")
    vlm = load_vlm(summary["vlm"])
    every = split_goals()
    # Table 2's goal indices, so each goal's scenes are the ones eval-multitask scored.
    stacking = {split: [(i, g) for i, g in enumerate(goals) if parse_goal(g).relation == "on_top_of"][:args.tasks]
                for split, goals in every.items()}
    out = {"policies": args.policies, "spread": args.spread, "seeds": args.seeds, "eval_seed": EVAL_SEED,
           "metric": "oracle episode reward of the scenes' own goal; mean and s.e. over the split's episodes",
           "readings": {"own": "the goal", "swapped": "the goal with its two colours swapped",
                        "left_of": "the goal's colours in 'on the left of'"}}
    for name, policy in policies.items():
        for split, goals in stacking.items():
            cell = out.setdefault(name, {}).setdefault(split, {})
            for reading in ("own", "swapped", "left_of"):
                rewards, per_task = [], {}
                for i, goal in tqdm(goals, desc=f"{name} {split} {reading}", leave=False):
                    text = readings(goal)[reading]
                    embedding = embed_goals(vlm, [text], policy.cfg.text_embedding)
                    r = task_rewards(policy, goal, embedding, args.seeds, args.spread, task_seed(i))
                    rewards += r
                    per_task[goal] = {"reads": text, "mean": sum(r) / len(r)}
                cell[reading] = {**mean_se_cell(rewards), "per_task": per_task}
            print(f"{name:>9} {split:>5}: " + ", ".join(f"{k} {v['mean']:5.1f} +- {v['se']:.1f}"
                                                        for k, v in cell.items()))
    write_json(args.out, out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

"""Which block do the distilled policies stack on in choice scenes? (Base or third block.)

In a choice scene (``zsrm train --choice``) the moved block starts between its base and a third
block, the base on either side at random: colour decides which block is the base. A policy that
finds its base (by the goal's colours, or by its primitive code) stacks on it; one that does not
stacks on either about as often. On the stacking goals of Table 2 (the same seeds as ``zsrm
eval-multitask``, and the same choice scenes as its table of choice-scene rollouts), per policy
and split: the control steps of 100 with the moved block on its base (the oracle episode reward)
and on the third block.

With ``--best`` (a policy's name, or ``table`` for the one a Table 2 file names as zsrm's best),
``checks`` holds what issue 38 asks of it on the blue test goals: its test score over its
training score, its gap to the unconditioned policy against their two standard errors added, and
its steps on the third block over its steps on the base.

    OMP_NUM_THREADS=1 python benchmarks/choice_scenes.py --policies runs/multitask/distill \\
        runs/multitask/distill-dagger --names none grounded_dagger --best table --out results/multitask/choice_scenes.json
"""
from __future__ import annotations

import argparse
import json

from tqdm import tqdm

from zsrm.common.files import read_json, write_json
from zsrm.envs.tabletop import TabletopEnv
from zsrm.evaluation.multitask import EVAL_SEED, OnThirdBlock, split_goals, task_episodes, task_seed
from zsrm.policy.models import embed_goals
from zsrm.policy.training import load_distilled_runs
from zsrm.rl.evaluate import mean_se_cell
from zsrm.tasks.language import parse_goal
from zsrm.vlm import load_vlm


def score(policy, vlm, goals: list[tuple[int, str]], seeds: int, spread: str) -> dict:
    """On base and on the third block over the goals' seeded choice-scene episodes."""
    on_base, on_third, per_task = [], [], {}
    for i, goal in tqdm(goals, leave=False):
        mover = TabletopEnv.task_mover(parse_goal(goal))
        embedding = embed_goals(vlm, [goal], policy.cfg.text_embedding)
        result = task_episodes(policy, goal, embedding, seeds, spread, task_seed(i), choice=True,
                               wrap=lambda venv, colour: OnThirdBlock(venv, mover, colour), also=("on_third",))
        on_base += result["episode_rewards"]
        on_third += result["on_third"]
        per_task[goal] = {"on_base": sum(result["episode_rewards"]) / seeds, "on_third": sum(result["on_third"]) / seeds}
    return {"on_base": mean_se_cell(on_base), "on_third": mean_se_cell(on_third), "per_task": per_task}


def checks(out: dict, best: str) -> dict:
    """Issue 38's three checks of ``best`` on the blue test goals."""
    test, train = out[best]["test"]["on_base"], out[best]["train"]["on_base"]
    none = out["none"]["test"]["on_base"] if "none" in out else None
    return {"policy": best, "test_over_train": test["mean"] / train["mean"] if train["mean"] else None,
            # the gap's bar: twice the two standard errors added (added, not root-sum-squared: the wider)
            **({"gap_to_none": test["mean"] - none["mean"], "two_se_added": 2 * (test["se"] + none["se"])}
               if none else {}),
            "third_over_base": out[best]["test"]["on_third"]["mean"] / test["mean"] if test["mean"] else None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policies", nargs="+", default=["runs/multitask/distill-choice"],
                        help="the folders zsrm distill wrote")
    parser.add_argument("--names", nargs="+", default=None, help="only these policies (default: all)")
    parser.add_argument("--best", default=None, help="a policy's name, or table: the best named in --table")
    parser.add_argument("--table", default="results/table2.json", help="with --best table: the Table 2 file")
    parser.add_argument("--spread", default="seen", choices=("seen", "unseen"))
    parser.add_argument("--seeds", type=int, default=50, help="seeded episodes per goal")
    parser.add_argument("--tasks", type=int, default=None, help="only the first N stacking goals per split")
    parser.add_argument("--out", default="results/side/multitask/choice/base_probe.json")
    args = parser.parse_args()
    runs = load_distilled_runs(args.policies)
    policies = {n: p for _, run in runs for n, p in run.items() if args.names is None or n in args.names}
    best = read_json(args.table, "a Table 2 file")["best"]["policy"] if args.best == "table" else args.best
    if best is not None and best not in policies:
        raise SystemExit(f"--best {best}: no such policy in {args.policies} (have {', '.join(policies)})")
    vlm = load_vlm(runs[0][0]["vlm"])
    stacking = {split: [(i, g) for i, g in enumerate(goals) if parse_goal(g).relation == "on_top_of"][:args.tasks]
                for split, goals in split_goals().items()}
    out = {"policies": args.policies, "spread": args.spread, "seeds": args.seeds, "eval_seed": EVAL_SEED,
           "metric": "control steps of 100 with the goal's moved block on its base (on_base) or on the third "
                     "block (on_third); mean and s.e. over the split's episodes"}
    for name, policy in policies.items():
        for split, goals in stacking.items():
            cell = out.setdefault(name, {})[split] = score(policy, vlm, goals, args.seeds, args.spread)
            print(f"{name:>16} {split:>5}: on base {cell['on_base']['mean']:5.1f} +- {cell['on_base']['se']:.1f}, "
                  f"on the third block {cell['on_third']['mean']:5.1f} +- {cell['on_third']['se']:.1f}")
    if best is not None:
        out["checks"] = checks(out, best)
        print("checks:", json.dumps(out["checks"]))
    write_json(args.out, out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

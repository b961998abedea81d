"""Does a distilled policy place by the relation word, or by the start layout?

A placing task's scene starts the block to move on the far side of its base ("left of": the
moved block on the right), so the layout alone says which way to carry it. This runs each
policy on the placing goals' scenes twice: reading its goal (``own``, as ``zsrm eval-multitask``)
and reading the goal with left and right swapped (``mirrored``: "on the right of" for "on the
left of"), scored by the oracle reward of the scenes' own goal. A policy that follows the word
should fail when it reads the mirrored one; a policy that reads only the layout scores alike.

    OMP_NUM_THREADS=1 python probes/relation_word_probe.py --policies runs/multitask/distill-dagger \\
        runs/multitask/distill-mirror-teachers --names grounded_dagger grounded_mirror_teachers_dagger \\
        --seeds 20 --out results/side/multitask/relation_word_probe.json
"""
from __future__ import annotations

import argparse

from tqdm import tqdm

from zsrm.common.files import write_json
from zsrm.evaluation.multitask import EVAL_SEED, split_goals, task_rewards, task_seed
from zsrm.policy.models import embed_goals
from zsrm.policy.training import load_distilled_runs, runs_vlm
from zsrm.rl.evaluate import mean_se_cell
from zsrm.tasks.language import parse_goal
from zsrm.vlm import load_vlm

PLACING = ("left_of", "right_of")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policies", nargs="+", default=["runs/multitask/distill-mirror-teachers"],
                        help="folders zsrm distill wrote")
    parser.add_argument("--names", nargs="+", default=None, help="only these policies (default: all)")
    parser.add_argument("--spread", default="seen", choices=("seen", "unseen"))
    parser.add_argument("--seeds", type=int, default=20, help="seeded episodes per goal and reading")
    parser.add_argument("--tasks", type=int, default=None, help="only the first N placing goals per split")
    parser.add_argument("--out", default="results/side/multitask/relation_word_probe.json")
    args = parser.parse_args()

    runs = load_distilled_runs(args.policies)
    policies = {n: p for _, run in runs for n, p in run.items() if args.names is None or n in args.names}
    if not policies:
        raise SystemExit(f"no policy named {' or '.join(args.names)} in {' '.join(args.policies)}")
    vlm = load_vlm(runs_vlm(runs))
    # Table 2's goal indices, so each goal's scenes are the ones eval-multitask scored.
    placing = {split: [(i, g) for i, g in enumerate(goals) if parse_goal(g).relation in PLACING][:args.tasks]
               for split, goals in split_goals().items()}
    out = {"policies": args.policies, "spread": args.spread, "seeds": args.seeds, "eval_seed": EVAL_SEED,
           "metric": "oracle episode reward of the scenes' own goal; mean and s.e. over the split's episodes",
           "readings": {"own": "the goal", "mirrored": "the goal with left and right swapped"}}
    for name, policy in policies.items():
        for split, goals in placing.items():
            cell = out.setdefault(name, {}).setdefault(split, {})
            for reading in ("own", "mirrored"):
                rewards = []
                for i, goal in tqdm(goals, desc=f"{name} {split} {reading}", leave=False):
                    text = goal if reading == "own" else parse_goal(goal).mirrored().text
                    embedding = embed_goals(vlm, [text], policy.cfg.text_embedding)
                    rewards += task_rewards(policy, goal, embedding, args.seeds, args.spread, task_seed(i))
                cell[reading] = mean_se_cell(rewards)
            print(f"{name:>32} {split:>5}: " + ", ".join(f"{k} {v['mean']:5.1f} +- {v['se']:.1f}"
                                                         for k, v in cell.items()))
    write_json(args.out, out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

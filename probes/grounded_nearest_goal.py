"""Would a primitive code help on the grounded policy's perception? (Table 2's primitive row.)

The primitive policy is given, for a test goal, only the training task nearest to it in
text-embedding L2 distance. This runs the grounded policy the same way: each test goal's
scenes, but the policy reads the embedding of that nearest training goal instead of the goal
itself. Two mappings: nearest in the language embedding (the primitive policy's mapping in
``results/table2.json``) and nearest in the grounded embedding (which keeps each object's
role and swaps blue for a training colour). Scored as ``zsrm eval-multitask`` scores (same
seeds, oracle episode reward), with the goal's own embedding alongside for reference.

    OMP_NUM_THREADS=1 python probes/grounded_nearest_goal.py --spread seen \\
        --out results/side/multitask/grounded_nearest_goal_seen.json
"""
from __future__ import annotations

import argparse

import torch
from tqdm import tqdm

from zsrm.common.files import write_json
from zsrm.evaluation.multitask import EVAL_SEED, split_goals, task_rewards, task_seed
from zsrm.policy.models import embed_goals, load_policy
from zsrm.rl.evaluate import mean_se_cell
from zsrm.vlm import load_vlm

MAPPINGS = ("language", "grounded")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="runs/multitask/distill/grounded", help="a grounded policy's folder")
    parser.add_argument("--spread", default="seen", choices=("seen", "unseen"))
    parser.add_argument("--seeds", type=int, default=50, help="seeded episodes per test goal")
    parser.add_argument("--out", default="results/side/multitask/grounded_nearest_goal_seen.json")
    args = parser.parse_args()

    policy = load_policy(args.policy)
    if policy.cfg.conditioning != "grounded":
        raise SystemExit(f"{args.policy} holds a {policy.cfg.conditioning} policy; this probes the grounded one")
    vlm = load_vlm(policy.cfg.vlm)
    goals = split_goals()
    train, test = goals["train"], goals["test"]
    embedded = {space: (embed_goals(vlm, test, space), embed_goals(vlm, train, space)) for space in MAPPINGS}
    # What the policy reads per test goal: its own embedding, or its nearest training goal's.
    readings = {"own": embedded["grounded"][0]}
    nearest = {}
    for space in MAPPINGS:
        codes = torch.cdist(*embedded[space]).argmin(dim=1)
        nearest[space] = [train[int(c)] for c in codes]
        readings[space] = embedded["grounded"][1][codes]

    out = {"policy": args.policy, "spread": args.spread, "seeds": args.seeds, "eval_seed": EVAL_SEED}
    for name, embeddings in readings.items():
        per_task, rewards = {}, []
        for i, goal in enumerate(tqdm(test, desc=f"reads {name}")):
            r = task_rewards(policy, goal, embeddings[i:i + 1], args.seeds, args.spread, task_seed(i))
            rewards += r
            per_task[goal] = {"reads": nearest[name][i] if name in nearest else goal, "mean": sum(r) / len(r)}
        out[name] = {**mean_se_cell(rewards), "per_task": per_task}
        print(f"{name:>9}: {mean:6.2f} +- {se:.2f}")
    write_json(args.out, out)


if __name__ == "__main__":
    main()

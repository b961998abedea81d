"""Do the zsrm-trained task policies read which block to stack on? (What Table 2 can distil.)

Each stacking task policy (``results/multitask/task_policies``) runs seeded episodes on its
own two-block scenes and on the same scenes with the third training colour added as a
distractor. Per episode: the steps with the goal's block on the goal's base (the oracle
episode reward) and the steps with it on the distractor instead. The gripper starts above the
block to move. A policy that reads its base's colour keeps its score with the distractor; one
that stacks on whichever block is near moves points to the distractor; one the third block
merely confuses loses points without stacking on it. Distilling policies that must read
colours (the mechanism of the paper's Table 2) from three-block scenes needs the first kind.
The scenes are Table 2's (``zsrm eval-multitask``'s seeds for the task).

With ``--choice-policies`` (``zsrm multitask-policies --choice``'s), a third scene: the choice
scene, the third colour in line on the far side of the moved block from its base, where those
policies were trained (from the two-block ones) and act. There a policy that reads its base's
colour stacks on the base; one that does not, on either block about as often.

    OMP_NUM_THREADS=1 python probes/task_policy_distractor.py \\
        --out results/side/multitask/task_policy_distractor.json
    OMP_NUM_THREADS=1 python probes/task_policy_distractor.py \\
        --choice-policies results/multitask/choice/task_policies \\
        --out results/side/multitask/choice/task_policy_distractor.json
"""
from __future__ import annotations

import argparse

import numpy as np
import torch
from tqdm import tqdm

from zsrm.common.files import write_json
from zsrm.envs.rollout import run_vec_episodes
from zsrm.evaluation.multitask import OnThirdBlock, task_seed
from zsrm.policy.rollouts import policy_folder
from zsrm.rl.envs import make_vec
from zsrm.rl.evaluate import mean_se_cell
from zsrm.rl.features import policy_view
from zsrm.rl.policy import PolicyBundle
from zsrm.tasks.catalogue import TRAIN_TASKS, choice_colour
from zsrm.vlm import load_vlm


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policies", default="results/multitask/task_policies", help="the kept task policies")
    parser.add_argument("--episodes", type=int, default=20, help="seeded episodes per task and scene")
    parser.add_argument("--tasks", type=int, default=None, help="only the first N stacking tasks")
    parser.add_argument("--choice-policies", default=None,
                        help="the stacking policies trained in choice scenes (zsrm multitask-policies --choice): "
                             "also score them there")
    parser.add_argument("--out", default="results/side/multitask/task_policy_distractor.json")
    args = parser.parse_args()

    tasks = [t for t in TRAIN_TASKS if t.relation == "on_top_of"][:args.tasks]
    out = {"policies": args.policies, "episodes": args.episodes,
           **({"choice_policies": args.choice_policies} if args.choice_policies else {}),
           "metric": "control steps of 100 with the goal's moved block on its base (on_base, the oracle episode "
                     "reward) or on the distractor (on_distractor); mean and s.e. over episodes"}
    scenes = ("plain", "distractor", "choice") if args.choice_policies else ("plain", "distractor")
    totals = {scene: {"on_base": [], "on_distractor": []} for scene in scenes}
    for task in tqdm(tasks, desc="task policies"):
        two_block = PolicyBundle.load(policy_folder(args.policies, task.text))
        vlm, mover = load_vlm(two_block.cfg.vlm), task.objects[0]
        third = choice_colour(task)  # the one training colour the goal does not name
        seed = task_seed(TRAIN_TASKS.index(task))  # Table 2's scenes of this task
        row = {"third_colour": third}
        for scene in scenes:
            bundle = PolicyBundle.load(policy_folder(args.choice_policies, task.text)) if scene == "choice" \
                else two_block
            if scene == "choice" and not bundle.cfg.choice:
                raise SystemExit(f"{args.choice_policies}: the policy of {task.text!r} was not trained in choice scenes")
            torch.manual_seed(seed)
            distractors = (third,) if scene != "plain" else ()
            venv = OnThirdBlock(make_vec(bundle.cfg, args.episodes, seed, distractors=distractors), mover, third)
            try:
                result = run_vec_episodes(policy_view(venv, vlm, bundle.cfg),
                                          lambda obs: bundle.act(obs, deterministic=bundle.cfg.eval_deterministic),
                                          also=("on_third",))
            finally:
                venv.close()
            row[scene] = {"on_base": float(np.mean(result["episode_rewards"])),
                          "on_distractor": float(np.mean(result["on_third"]))}
            totals[scene]["on_base"] += result["episode_rewards"]
            totals[scene]["on_distractor"] += result["on_third"]
        out.setdefault("per_task", {})[task.text] = row
        print(f"{task.text:40s} plain {row['plain']['on_base']:5.1f}, with {third}: on base "
              f"{row['distractor']['on_base']:5.1f}, on {third} {row['distractor']['on_distractor']:5.1f}"
              + (f"; choice scene: on base {row['choice']['on_base']:5.1f}, on {third} "
                 f"{row['choice']['on_distractor']:5.1f}" if "choice" in row else ""))
    for scene, counts in totals.items():
        out[scene] = {}
        for key, values in counts.items():
            out[scene][key] = mean_se_cell(values)
    plain, mixed = out["plain"], out["distractor"]
    print(f"all: plain {plain['on_base']['mean']:.1f}; with a distractor on base {mixed['on_base']['mean']:.1f}, "
          f"on the distractor {mixed['on_distractor']['mean']:.1f}")
    write_json(args.out, out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

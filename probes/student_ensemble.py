"""Do students trained on different label sets err apart? Their mean margin as one reward, on an own scene.

Each named student (a ``zsrm finetune --student`` folder) scores the held-out frames of each goal
(``zsrm own-scene``'s ``eval-data``, labelled by the scene's oracle: evaluation only); the reward of
a set of students is 1 where their mean margin (goal over its best negative) is above 0. Prints
and writes the binarised F1 per goal of each student alone, each pair and each triple.

    python probes/student_ensemble.py --data runs/scenes/own_scene/eval-data \\
        --students z.5s2=runs/scenes/own_scene/student z0s0=runs/scenes/own_scene-seed0/student ... \\
        --out results/side/scenes/own_scene_student_ensembles.json
"""
from __future__ import annotations

import argparse
import itertools
import sys

import numpy as np

SCENE = "examples.own_scene.adapter:OwnScene"
GOALS = ("a red cylinder on the right of a purple cylinder", "an orange cylinder on the left of a red cylinder",
         "a red cylinder behind a purple cylinder")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default=SCENE)
    parser.add_argument("--goals", nargs="+", default=list(GOALS))
    parser.add_argument("--data", required=True, help="held-out data of the scene, labelled (zsrm label)")
    parser.add_argument("--students", nargs="+", required=True, metavar="NAME=FOLDER")
    parser.add_argument("--out", required=True)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 2, 3], help="ensemble sizes to score")
    args = parser.parse_args(argv)
    from zsrm.common.files import write_json
    from zsrm.envs.adapter import load_adapter
    from zsrm.evaluation.metrics import binary_metrics
    from zsrm.evaluation.reward_quality import scene_data_frames
    from zsrm.fullmodel import load_reward_backbone
    from zsrm.rewards.binarised import ZSRMReward
    from zsrm.tasks.scene_goals import parse_scene_goal

    students = dict(s.split("=", 1) for s in args.students)
    objects = load_adapter(args.scene).objects
    frames = {g: scene_data_frames(args.data, parse_scene_goal(g, objects, args.scene)) for g in args.goals}
    margins = {}
    for name, folder in students.items():
        reward = ZSRMReward(load_reward_backbone(folder), objects=objects)
        margins[name] = {g: reward.outputs(f.images, f.goal)["margin"] for g, f in frames.items()}
    rows = []
    for k in args.sizes:
        for group in itertools.combinations(students, k):
            f1 = {g: round(binary_metrics(np.mean([margins[n][g] for n in group], 0) > 0, f.success)["f1"], 4)
                  for g, f in frames.items()}
            rows.append({"students": list(group), "f1": f1})
            print(" + ".join(group), [f1[g] for g in args.goals])
    write_json(args.out, {"scene": args.scene, "goals": args.goals, "students": students, "rows": rows,
                          "meta": {"command": "python probes/student_ensemble.py " + " ".join(sys.argv[1:]),
                                   "label": "the scene's oracle on held-out frames (evaluation only)"}}, indent=1)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The full model on the example scene of ``examples/own_scene``: a call of ``zsrm own-scene``
(the one command that runs the own-scene chain on any adapter) with the example's goals and its
PPO goal, writing ``results/own_scene.json``.

The chain's stages, its gates and its report: ``zsrm own-scene --help`` and docs/own-scene.md.
Every stage resumes or is skipped when its output is there.

    python benchmarks/own_scene.py                     # about 1 hour on 2 cores, PPO included
    python benchmarks/own_scene.py --until eval-reward # the reward model alone: about 25 min
    python benchmarks/own_scene.py --dry-run           # the stages
    python benchmarks/own_scene.py --sideways --work runs/scenes/own_scene  # + ppo_sideways (about 1 h)

``--sideways`` trains the sideways goal instead (a red cylinder on the right of a purple one) in
the task scenes of ``OwnSceneSideways`` (the two cylinders one behind the other, the pusher on
the red one's left), with the ``v3`` learner and the chain's VLM and student in ``--work``
(which the chain must have reached eval-reward in), and adds ``ppo_sideways`` to ``--out`` (the
sweep's summary, curves and trials in ``results/own_scene/sideways/`` for the default ``--out``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

SCENE = "examples.own_scene.adapter:OwnScene"
GOALS = ("a red cylinder on the right of a purple cylinder", "an orange cylinder on the left of a red cylinder",
         "a red cylinder behind a purple cylinder")
# The goal PPO learns: in the adapter's task scenes the pusher starts in front of an object and
# moves in 1 cm steps, so pushing one back past another is a push straight ahead; pushing one
# sideways past another, the other goals' relations, needs the pusher to go round first
# (docs/own-scene.md).
PPO_GOAL = GOALS[2]
# The sideways goal, learnt from scenes that start the two cylinders in a column (OwnSceneSideways).
SIDEWAYS_SCENE, SIDEWAYS_GOAL, SIDEWAYS_CONFIG = "examples.own_scene.adapter:OwnSceneSideways", GOALS[0], "v3"


def sideways(work: Path, out: Path, steps: int, num_cpus: int) -> int:
    """PPO on the sideways goal with the oracle, zsrm and random rewards (3 seeds), gathered into
    ``out``'s ``ppo_sideways`` (the keys of its ``ppo``)."""
    from zsrm.common import files
    from zsrm.pipeline.learn import Sweep
    from zsrm.pipeline.own_scene import SceneChain, ppo_cells

    # the sweep's summary and trial files beside the results (results/own_scene/sideways/)
    # the chain's reward model: its students' ensemble (--students, default 3), else its one student
    ensemble = work / "students" / "config.json"
    student = work / "students" if ensemble.is_file() else work / "student"
    learning = out.with_suffix("") / "sideways" / "learning.json"
    if not (ensemble.is_file() or (student / "training.json").is_file()):
        raise SystemExit(f"{work} has no student: run the chain there first (python benchmarks/own_scene.py "
                         f"--work {work} --until eval-reward)")
    vlm = str(SceneChain.chosen_vlm(work))
    sweep = Sweep(scene=SIDEWAYS_SCENE, tasks=(SIDEWAYS_GOAL,), rewards=("oracle", "zsrm", "random"), seeds=(0, 1, 2),
                  steps=steps, vlm=vlm, reward_model=str(student), root=str(work / "rl-sideways"), num_cpus=num_cpus,
                  config=SIDEWAYS_CONFIG, out=str(learning))
    sweep.run()
    result = files.read_json(out, "the scene's results") if out.is_file() else {}
    gathered = files.read_json(learning, "the sideways sweep")
    result["ppo_sideways"] = {**ppo_cells(gathered, SIDEWAYS_GOAL), "scene": SIDEWAYS_SCENE,
                              "config": SIDEWAYS_CONFIG, "core_hours": gathered["meta"]["core_hours"]}
    meta = result.setdefault("meta", {})
    meta.setdefault("stages", {})["sweep sideways"] = (f"python benchmarks/own_scene.py --sideways --work {work} "
                                                       f"--out {out}" + (f" --steps {steps}" if steps != 300_000 else "")
                                                       + f" ({gathered['meta']['command']} --root {work / 'rl-sideways'})")
    files.write_json(out, result, indent=1)
    print(f"wrote ppo_sideways to {out}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", default="runs/own-scene", help="folder of every stage's data, models and report")
    parser.add_argument("--out", default="results/own_scene.json")
    parser.add_argument("--steps", type=int, default=300_000, help="env steps of each PPO trial")
    parser.add_argument("--config", default="cpu", help="the PPO goal's learner preset (zsrm train --config); "
                        "results/own_scene.json's ppo was made with v2, the default then")
    parser.add_argument("--until", default=None, help="stop after this stage (e.g. eval-reward: no PPO)")
    parser.add_argument("--dry-run", action="store_true", help="print the stages and stop")
    parser.add_argument("--sideways", action="store_true", help="train the sideways goal (see above) and add "
                                                                 "ppo_sideways to --out; the chain's stages are not run")
    parser.add_argument("--num-cpus", type=int, default=2, help="PPO trials side by side (--sideways)")
    args = parser.parse_args(argv)
    if args.sideways:
        return sideways(Path(args.work), Path(args.out), args.steps, args.num_cpus)
    from zsrm.cli import main as zsrm

    command = ["own-scene", "--scene", SCENE, "--goals", *GOALS, "--out", args.work, "--results", args.out,
               "--ppo-goal", PPO_GOAL, "--ppo-steps", str(args.steps), "--ppo-config", args.config]
    command += ["--until", args.until] if args.until else []
    command += ["--dry-run"] if args.dry_run else []
    return zsrm(command)


if __name__ == "__main__":
    sys.exit(main())

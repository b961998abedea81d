"""The full model on a scene zsrm was not built for: the example of ``examples/own_scene`` end to
end, each stage a ``zsrm`` command, then ``results/own_scene.json``.

Stages (each resumes or is skipped when its output is there, so a killed run loses no finished
work; ``--dry-run`` prints them):

1. ``zsrm pretrain-vlm --scene``: the scene stand-in VLM learns the objects' names from renders
   captioned with which objects are present (the one step that reads the simulator's object
   list; with real CLIP weights it is skipped);
2. ``zsrm reward-data --scene``: exploration with the adapter's actions, labelled by Grad-CAM;
3. ``zsrm collect --scene --seed 1`` and ``zsrm label``: held-out exploration, whose
   true-coordinate captions (the scene's oracle, evaluation only) label the evaluations;
4. ``zsrm eval-grounding``: the labeler's F1 against the scene's oracle, per relation;
5. ``zsrm finetune --student``: the reward model, on stage 2's Grad-CAM captions only;
6. ``zsrm eval-reward --scene``: the binarised reward's F1 against the oracle on three goals,
   the base VLM binarised the same way beside it;
7. ``zsrm sweep --scene``: PPO from pixels with the oracle, zsrm and random rewards on one goal,
   3 seeds, in the adapter's task scenes.

    python benchmarks/own_scene.py            # about 1.5 hours on 2 cores
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import subprocess
import sys
import time
from pathlib import Path

SCENE = "examples.own_scene.adapter:OwnScene"
GOALS = ("a red cylinder on the right of a purple cylinder", "an orange cylinder on the left of a red cylinder",
         "a red cylinder behind a purple cylinder")
# The goal PPO learns: in the adapter's task scenes the pusher starts in front of an object and
# moves in 1 cm steps, so pushing one back past another is a push straight ahead; pushing one
# sideways past another, the other goals' relations, needs the pusher to go round first
# (docs/own-scene.md, step 12).
PPO_GOAL = GOALS[2]


def stages(work: Path, args) -> list[tuple[str, list[str], Path]]:
    """(name, zsrm command, the file it leaves when finished). Data and models go to ``work``;
    the small measurements (and the sweep's trial summaries) to ``--side``, to be committed."""
    vlm, train, held_out, side = work / "vlm", work / "train-data", work / "eval-data", Path(args.side)
    scene = ["--scene", SCENE]
    return [
        ("pretrain-vlm", ["pretrain-vlm", *scene, "--out", str(vlm), "--workdir", str(work / "pretrain"),
                          "--arch", "tiny", "--scenes", "800", "--shard-size", "100", "--steps", "2000",
                          "--batch-size", "64", "--checkpoint-every", "500", "--warmup-steps", "50", "--threads", "1"],
         vlm / "config.json"),
        ("reward-data", ["reward-data", *scene, "--vlm", str(vlm), "--out", str(train), "--images", str(args.images),
                         "--shard-size", "250", "--quiet"], train / "labels" / "manifest.json"),
        ("collect held-out", ["collect", *scene, "--out", str(held_out), "--images", str(args.eval_images),
                              "--shard-size", "250", "--seed", "1"], held_out / "manifest.json"),
        ("label held-out", ["label", str(held_out), "--vlm", str(vlm), "--quiet"],
         held_out / "labels" / "manifest.json"),
        ("eval-grounding", ["eval-grounding", str(held_out), "--out", str(side / "grounding.json")],
         side / "grounding.json"),
        ("finetune", ["finetune", "--data", str(train), "--student", "--vlm", str(vlm), "--out", str(work / "student"),
                      "--steps", str(args.finetune_steps), "--threads", "1", "--quiet"],
         work / "student" / "training.json"),
        ("eval-reward", ["eval-reward", *scene, "--data", str(held_out), "--zsrm", str(work / "student"),
                         "--base", str(vlm), "--tasks", *GOALS, "--out", str(side / "reward_eval.json"),
                         "--curves", "", "--quiet"], side / "reward_eval.json"),
        ("sweep", ["sweep", *scene, "--tasks", PPO_GOAL, "--rewards", "oracle", "zsrm", "random",
                   "--seeds", "0", "1", "2", "--steps", str(args.steps), "--vlm", str(vlm),
                   "--reward-model", str(work / "student"), "--root", str(work / "rl"),
                   "--num-cpus", str(args.num_cpus), "--out", str(side / "learning.json")],
         side / "learning.json"),
    ]


def gather(work: Path, args, seconds: dict) -> dict:
    side = Path(args.side)
    grounding = json.loads((side / "grounding.json").read_text())
    reward = json.loads((side / "reward_eval.json").read_text())
    learning = json.loads((side / "learning.json").read_text()) if (side / "learning.json").is_file() else None
    from zsrm.envs.adapter import load_adapter
    from zsrm.tasks.scene_goals import parse_scene_goal

    objects = load_adapter(SCENE).objects
    used = sorted({parse_scene_goal(g, objects).relation for g in GOALS})
    labeler = {rel: {k: grounding["relations"]["vs_world"][rel][k] for k in ("precision", "recall", "f1", "support")}
               for rel in grounding["relations"]["vs_world"]}
    rewards = {g: {name: {k: reward[name][g][k] for k in ("f1", "precision", "recall", "auroc", "positives", "frames")}
                    for name in ("zsrm", "base")} for g in GOALS}
    ppo = {r: cells_for(learning, PPO_GOAL, r) for r in ("oracle", "zsrm", "random")} if learning else None
    return {
        "scene": SCENE, "goals": list(GOALS),
        "labeler_f1": {rel: labeler[rel]["f1"] for rel in used},
        "labeler": {"relations_the_goals_use": used, "by_relation": labeler,
                    "against": "the scene's oracle (privileged positions along each role camera's axes), held-out "
                               "exploration", "images": grounding.get("meta", {}).get("images")},
        "reward_f1": {g: {name: rewards[g][name]["f1"] for name in ("zsrm", "base")} for g in GOALS},
        "reward": rewards,
        "ppo": {"goal": PPO_GOAL, "steps": args.steps, **ppo,
                "zsrm_over_oracle": ppo["zsrm"]["mean"] / ppo["oracle"]["mean"] if ppo["oracle"]["mean"] else None}
        if ppo else None,
        "meta": {"command": "python benchmarks/own_scene.py" + "".join(f" {a}" for a in sys.argv[1:]),
                 "stages": {name: "zsrm " + shlex.join(cmd) for name, cmd, _ in stages(work, args)},
                 "stage_seconds": seconds, "machine": f"{platform.machine()}, {os.cpu_count()} cores, no GPU",
                 "side_files": str(side)},
    }


def cells_for(learning: dict, goal: str, reward: str) -> dict:
    """Final mean, standard error and per-seed finals of one (goal, reward) of a sweep's summary."""
    cell = learning[goal][reward]
    return {"mean": cell["final_mean"], "se": cell["final_se"], "seeds": cell["seeds"],
            "final_per_seed": cell["final_per_seed"], "steps": cell["steps"]}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", default="runs/own-scene", help="folder of every stage's data and models")
    parser.add_argument("--images", type=int, default=4000, help="exploration images the reward model trains on")
    parser.add_argument("--eval-images", type=int, default=1000, help="held-out exploration images")
    parser.add_argument("--finetune-steps", type=int, default=3000)
    parser.add_argument("--steps", type=int, default=300_000, help="env steps of each PPO trial")
    parser.add_argument("--num-cpus", type=int, default=2)
    parser.add_argument("--until", default=None, help="run no stage after this one, then gather what is there")
    parser.add_argument("--dry-run", action="store_true", help="print the stages' commands and stop")
    parser.add_argument("--side", default="results/own_scene", help="folder of the stages' measurements")
    parser.add_argument("--out", default="results/own_scene.json")
    args = parser.parse_args(argv)
    work = Path(args.work)
    times_file = Path(args.side) / "stage_seconds.json"
    seconds = json.loads(times_file.read_text()) if times_file.is_file() else {}
    for name, cmd, done in stages(work, args):
        print(f"[{name}] zsrm {shlex.join(cmd)}", flush=True)
        if args.dry_run:
            continue
        if done.is_file():
            print(f"[{name}] done ({done})", flush=True)
        else:
            t = time.time()
            subprocess.run([sys.executable, "-m", "zsrm.cli", *cmd], check=True)
            seconds[name] = round(time.time() - t, 1)
            times_file.parent.mkdir(parents=True, exist_ok=True)
            times_file.write_text(json.dumps(seconds, indent=1))
        if name == args.until:
            break
    if args.dry_run:
        return 0
    from zsrm.common.files import write_json

    result = gather(work, args, seconds)
    write_json(args.out, result, indent=1)
    print(json.dumps({k: result[k] for k in ("labeler_f1", "reward_f1")}, indent=1))
    if result["ppo"]:
        print(f"PPO on {PPO_GOAL!r}: " + ", ".join(f"{r} {result['ppo'][r]['mean']:.1f}" for r in ("oracle", "zsrm", "random")))
    else:
        print("PPO: the sweep has not run (--until stopped before it)")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

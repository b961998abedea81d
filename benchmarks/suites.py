"""zsrm on benchmarks it was not built for, judged by their own success checks (docs/benchmarks.md).

Runs in the benchmarks' environment (``make bench-setup``: ``.venv-bench``, MuJoCo 3.9):

    .venv-bench/bin/python benchmarks/suites.py robosuite   # results/benchmarks/robosuite.json

1. ``zsrm own-scene`` on the suite's adapter and goals (the one command: stand-in VLM, exploration
   data labelled by Grad-CAM, the student, each judged against zsrm's oracle), in ``--work``.
2. Held-out frames judged by the benchmark's own check (the adapter module's ``predicate``):
   half with the objects placed as the goal's region says (``place_goal``), half from zsrm's
   exploration layouts, each followed by a few random actions; seeds none of the training saw.
   Evaluation data only.
3. zsrm's binarised reward (the chain's students) and the base reward (the kept stand-in VLM, binarised
   by the same argmax rule) on those frames: F1 and AUROC against the predicate.
4. What each stage cost, and what a PPO run there would cost.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import time
from pathlib import Path

import numpy as np

SUITES = {
    "robosuite": {
        "scene": "examples.robosuite.adapter:StackScene",
        "goals": ("a red cube on top of a green cube", "a green cube on top of a red cube"),
        "chain": ("--students", "1"),  # one student: rendering the Panda makes these chains the slowest
    },
    # Two LIBERO-Spatial tasks (the same objects in other layouts): the chain on the first, held-out
    # frames from both. LIBERO renders 12 frames/s at 64 px here: fewer VLM seeds and images, one student.
    "libero": {
        "scene": "examples.libero.adapter:SpatialBetween",
        "frame_scenes": ("examples.libero.adapter:SpatialBetween", "examples.libero.adapter:SpatialNextToCookies"),
        "goals": ("a black bowl on top of a plate", "a ramekin on top of a plate"),
        "chain": ("--vlm-seeds", "0", "1", "2", "--images", "2000", "--eval-images", "600", "--students", "1"),
    },
}
EVAL_SEED = 50_000  # held-out frames: seeds apart from every stage of the chain


def goal_frames(adapter, module, goal: str, frames: int, seed: int) -> dict:
    """``frames`` frames and the benchmark's predicate on each: half placed as the goal says, half
    zsrm's exploration layouts; 0 to 5 random actions after either. ``images_<role>``: each role's
    frames (the reward reads the goal's, the labeler all three); ``present``: (N, K) which of the
    adapter's objects each holds; ``pixels_<role>``: (N, K, 2) their true pixels (NaN where
    absent), for the labeler's ceiling only."""
    from zsrm.envs.cameras import project

    env = adapter.make_env(tuple(adapter.roles.values()), 64)
    truth, source, present = [], [], []
    roles = {r: [] for r in adapter.roles}
    pixels = {r: [] for r in adapter.roles}
    try:
        for i in range(frames):
            rng = np.random.default_rng([seed, i])
            obs, _ = env.reset(seed=int(rng.integers(2**31 - 1)))
            placed = i % 2 == 0
            if placed:
                obs = module.place_goal(env, goal, rng)
            for _ in range(int(rng.integers(0, 6))):
                obs, *_ = env.step(adapter.exploration_action(env, rng))
            seen = adapter.observe(obs)
            for r in roles:
                roles[r].append(seen[r])
            held = adapter.object_positions(env)
            present.append([o in held for o in adapter.objects])
            for r, cam in adapter.roles.items():
                pixels[r].append([project(env, cam, held[o], 64) if o in held else (np.nan, np.nan)
                                  for o in adapter.objects])
            truth.append(module.predicate(env, goal))
            source.append("placed" if placed else "random")
    finally:
        env.close()
    return {"success": np.array(truth), "source": np.array(source), "present": np.array(present),
            **{f"images_{r}": np.stack(v) for r, v in roles.items()},
            **{f"pixels_{r}": np.asarray(v, np.float32) for r, v in pixels.items()}}


class Labeler:
    """zsrm's labeler as ``zsrm label`` captioned the chain's held-out data (Grad-CAM points of the
    kept VLM through Table 1, with its centres and calibration), built once for every goal."""

    def __init__(self, chain: Path):
        from dataclasses import fields

        from zsrm.common import files
        from zsrm.data.dataset import ExplorationData
        from zsrm.grounding.annotate import Grounder, LabelConfig
        from zsrm.vlm import load_vlm

        self.data = ExplorationData(chain / "eval-data")
        manifest = files.read_json(chain / "eval-data" / "labels" / "manifest.json", "labels manifest")
        self.cfg = LabelConfig(**{k.name: manifest["config"][k.name] for k in fields(LabelConfig)
                                  if k.name in manifest["config"]})
        self.grounder = Grounder(load_vlm(self.cfg.vlm), self.cfg, self.data, manifest.get("centres"),
                                 manifest.get("fine_centres"), silhouettes=manifest.get("silhouettes"))

    def holds(self, f: dict, goal: str) -> np.ndarray:
        """Whether the labeler says ``goal`` on each frame of :func:`goal_frames`."""
        from zsrm.grounding.annotate import gradcam_objects

        arrays = {"scene": np.zeros(len(f["present"]), np.int64),
                  **{f"images_{c}": f[f"images_{c}"] for c in self.data.cameras}}
        return self.holds_at(gradcam_objects(self.data, self.grounder.shard(arrays)), f["present"], goal)

    def holds_at(self, pixels: dict, present: np.ndarray, goal: str) -> np.ndarray:
        """Whether Table 1 says ``goal`` of objects at ``pixels`` ({camera: (N, K, 2)}, the
        data's object order): the labeler's reading without its Grad-CAM (true pixels: its ceiling)."""
        from zsrm.grounding.annotate import captions_from_pixels

        captions = captions_from_pixels(self.data, self.cfg, pixels, present, np.zeros(len(present), np.int64))
        return np.array([goal in c for c in captions])

    def holds_true(self, f: dict, objects, goal: str) -> np.ndarray:
        """:meth:`holds_at` on :func:`goal_frames`' true pixels (its ``objects``' order): the
        labeler's ceiling on these frames."""
        order = [list(objects).index(o) for o in self.data.colours]
        return self.holds_at({c: f[f"pixels_{c}"][:, order] for c in self.data.cameras}, f["present"][:, order], goal)


def _language(scene: str) -> str | None:
    """A benchmark task's instruction, as the benchmark ships it (LIBERO's task ``language``)."""
    from zsrm.envs.adapter import load_adapter

    task = getattr(load_adapter(scene), "task", None)
    if task is None:
        return None
    from examples.libero.env import libero_task

    return libero_task(task)[1].language


def speeds(adapter, steps: int = 60) -> dict:
    """Env steps/s on one core: physics alone, and rendering the three roles' cameras each step."""
    env = adapter.make_env(tuple(adapter.roles.values()), 64)
    rng = np.random.default_rng(0)
    try:
        out = {}
        for name, render in (("physics_steps_per_s", False), ("steps_per_s_3_cameras_64px", True)):
            env.reset(seed=0)
            t = time.perf_counter()
            for _ in range(steps):
                obs, *_ = env.step(adapter.exploration_action(env, rng))
                if render:
                    adapter.observe(obs)
            out[name] = round(steps / (time.perf_counter() - t), 1)
    finally:
        env.close()
    one_camera = 1 / (1 / out["physics_steps_per_s"] + (1 / out["steps_per_s_3_cameras_64px"]
                                                         - 1 / out["physics_steps_per_s"]) / 3)
    out["steps_per_s_1_camera_64px"] = round(one_camera, 1)
    # A PPO run of zsrm's default budget: one camera rendered per env step, the reward model beside
    # it (about 2,000 frames/s, results/reward_speed.json), the policy's updates not counted.
    out["ppo_300k_steps_core_hours_at_least"] = round(300_000 / one_camera / 3600, 1)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("suite", choices=sorted(SUITES))
    parser.add_argument("--work", default=None, help="folder of the chain and frames (default runs/benchmarks/SUITE)")
    parser.add_argument("--out", default=None, help="default results/benchmarks/SUITE.json")
    parser.add_argument("--frames", type=int, default=400, help="held-out frames per goal (half placed)")
    args = parser.parse_args(argv)
    suite = SUITES[args.suite]
    work = Path(args.work or f"runs/benchmarks/{args.suite}")
    out = args.out or f"results/benchmarks/{args.suite}.json"
    sys.path.insert(0, os.getcwd())  # examples.* as with python -m

    from zsrm.cli import main as zsrm
    from zsrm.common import files
    from zsrm.common.machine import describe
    from zsrm.envs.adapter import load_adapter
    from zsrm.evaluation.metrics import binary_metrics
    from zsrm.evaluation.reward_quality import EvalFrames, evaluate_rewards
    from zsrm.fullmodel import load_reward_backbone
    from zsrm.rewards.base import BaseReward
    from zsrm.rewards.binarised import ZSRMReward
    from zsrm.tasks.relations import RELATIONS
    from zsrm.tasks.scene_goals import parse_scene_goal

    t0 = time.perf_counter()
    chain = work / "chain"
    rc = zsrm(["own-scene", "--scene", suite["scene"], "--goals", *suite["goals"], "--out", str(chain),
               *suite.get("chain", ()), "--keep-going", "--quiet"])
    if not (chain / "summary.json").is_file():  # refused before any stage ended (its line is above)
        return rc or 1
    summary = files.read_json(chain / "summary.json", "summary.json")
    adapter = load_adapter(suite["scene"])
    module = importlib.import_module(suite["scene"].split(":")[0])
    base_vlm = load_reward_backbone(files.read_json(chain / "vlm.json", "vlm.json")["chosen"])
    # the chain's reward model: its students' ensemble (zsrm own-scene --students), else its one student
    students = chain / "students" if (chain / "students" / "config.json").is_file() else chain / "student"
    models = {"zsrm": ZSRMReward(load_reward_backbone(str(students)), name="zsrm", objects=adapter.objects),
              "base": ZSRMReward(base_vlm, name="base_binary", objects=adapter.objects)}

    t1 = time.perf_counter()
    frames, by_scene, labeler, ceiling = {}, {}, {}, {}
    scenes = suite.get("frame_scenes", (suite["scene"],))
    zsrm_labeler = Labeler(chain)
    for j, goal in enumerate(suite["goals"]):
        camera = RELATIONS[parse_scene_goal(goal, adapter.objects, suite["scene"]).relation].camera
        parts = [goal_frames(load_adapter(name), module, goal, args.frames // len(scenes), EVAL_SEED + 100 * j + k)
                 for k, name in enumerate(scenes)]
        by_scene[goal] = [len(p["success"]) for p in parts]
        f = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
        labeler[goal] = binary_metrics(zsrm_labeler.holds(f, goal), f["success"])
        ceiling[goal] = binary_metrics(zsrm_labeler.holds_true(f, adapter.objects, goal), f["success"])
        frames[goal] = EvalFrames(goal, goal, camera, f[f"images_{camera}"], f["success"], f["source"],
                                  np.arange(len(f["success"])), np.zeros(len(f["success"]), int))
    frames_s = time.perf_counter() - t1

    def base_raw(f):
        return BaseReward(base_vlm, camera=f.camera).score(f.images, f.goal)

    scores = evaluate_rewards(models, frames, raw_scores={"base": base_raw})
    reward = {}
    for goal, f in frames.items():
        reward[goal] = {name: {k: scores[name][goal][k] for k in ("f1", "precision", "recall", "auroc")}
                        for name in models}
        reward[goal].update(positives=int(f.success.sum()), frames=len(f),
                            positives_placed=int(f.success[f.source == "placed"].sum()),
                            positives_random=int(f.success[f.source == "random"].sum()),
                            predicate=module.PREDICATE_NAMES[goal], camera=f.camera,
                            labeler={k: round(float(v), 4) for k, v in labeler[goal].items()},
                            labeler_true_pixels={k: round(float(v), 4) for k, v in ceiling[goal].items()})
        if len(scenes) > 1:  # each benchmark task's frames on their own
            cut = np.cumsum([0, *by_scene[goal]])
            reward[goal]["by_task"] = {}
            for k, name in enumerate(scenes):
                part = EvalFrames(goal, goal, f.camera, f.images[cut[k]:cut[k + 1]], f.success[cut[k]:cut[k + 1]],
                                  f.source[cut[k]:cut[k + 1]], f.episode[cut[k]:cut[k + 1]], f.step[cut[k]:cut[k + 1]])
                s = evaluate_rewards(models, {goal: part}, raw_scores={"base": base_raw})
                reward[goal]["by_task"][name] = {
                    "language": _language(name),
                    "frames": len(part), "positives": int(part.success.sum()),
                    **{m: {"f1": s[m][goal]["f1"], "auroc": s[m][goal]["auroc"]} for m in models}}
    import mujoco

    result = {
        "suite": args.suite, "scene": suite["scene"], "goals": list(suite["goals"]), "reward": reward,
        "chain": {k: summary.get(k) for k in ("labeler_f1", "localisation", "reward_f1", "vlm", "gates", "usable")},
        "cost": {"chain_stage_seconds": summary["meta"]["stage_seconds"], "predicate_frames_s": round(frames_s, 1),
                 **speeds(adapter)},
        "meta": {"command": f".venv-bench/bin/python benchmarks/suites.py {' '.join(argv if argv is not None else sys.argv[1:])}",
                 "chain_command": summary["meta"]["command"], "chain_exit": rc, "reward_model": students.name,
                 "frames": f"{args.frames} per goal, seeds from {EVAL_SEED}: half placed as the goal says "
                           "(place_goal), half zsrm's exploration layouts; 0-5 random actions after; "
                           "truth: the benchmark's own check",
                 "binary": "1 when the goal text beats every negative on the goal relation's camera; base: the "
                           "kept stand-in VLM by the same rule",
                 "labeler": "zsrm's labeler on the same frames (Grad-CAM of the kept VLM on all three cameras, "
                            "Table 1, the chain's label settings): the goal among its captions, against the predicate",
                 "labeler_true_pixels": "the same labeler on the objects' true pixels instead of Grad-CAM's: "
                                        "what Table 1's reading of the goal can reach on these frames",
                 "mujoco": mujoco.__version__, "machine": describe(),
                 "wall_s": round(time.perf_counter() - t0, 1)},
    }
    try:
        import robosuite

        result["meta"]["robosuite"] = robosuite.__version__
    except ImportError:
        pass
    files.write_json(out, result, indent=1, default=float)
    for goal, r in reward.items():
        print(f"{goal}: zsrm F1 {r['zsrm']['f1']:.3f} AUROC {r['zsrm']['auroc']:.3f} | base F1 {r['base']['f1']:.3f} "
              f"| {r['positives']}/{r['frames']} frames hold ({r['predicate']})")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

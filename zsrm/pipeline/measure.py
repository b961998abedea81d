"""Stages that measure: ``zsrm render``, ``scripted-eval``, ``eval-vlm``, ``eval-pose``, ``reward``,
``reward-curve``, ``eval-grounding`` and ``eval-reward``. Each writes its figures as a table
(JSON or CSV) and, where there is one, a plot.

Heavy imports (torch, the models, MuJoCo) happen inside ``run``, so ``zsrm --help`` stays fast.
"""
from __future__ import annotations

import json
import platform
import shlex
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from zsrm.common import files
from zsrm.data.dataset import LABELS
from zsrm.evaluation.curves import FIGURE5_GOAL
from zsrm.tasks.catalogue import REPORT_TASKS, SPATIAL_TASKS
from zsrm.vlm.factory import DEFAULT_VLM


def write_json(obj: dict, out: str | Path, **dump) -> Path:
    return files.write_json(out, obj, **dump)


@dataclass
class Render:
    """Write a PNG of the three cameras side by side for a task."""

    task: str = field(metadata={"positional": True})  # a catalogue name (stack, place_left, place_right, push_close, pendulum) or a goal sentence
    out: str | None = None  # PNG path (default: TASK.png)
    size: int = 128  # image size in pixels
    seed: int = 0  # seed of the scene's start state

    def run(self) -> int:
        from PIL import Image

        from zsrm.envs.rollout import camera_strip, make_env

        out = files.check_writable(self.out or f"{self.task.replace(' ', '_')}.png")
        env = make_env(self.task, image_size=self.size)
        env.reset(seed=self.seed)
        with files.atomic_path(out) as tmp:
            Image.fromarray(camera_strip(env, self.size)).save(tmp)
        env.close()
        print(f"wrote {out}")
        return 0


@dataclass
class ScriptedEval:
    """Success of the true-state scripted controllers (proves every task achievable)."""

    tasks: tuple[str, ...] = SPATIAL_TASKS  # catalogue tasks (default: every spatial task)
    episodes: int = 20  # seeded episodes per task (seeds 0..EPISODES-1)
    out: str | None = None  # JSON path, e.g. results/scripted_success.json

    def run(self) -> int:
        from zsrm.evaluation.scripted_success import scripted_success

        if self.out:
            files.check_writable(self.out)
        rates = scripted_success(self.tasks, self.episodes)
        result = dict(rates)
        result["meta"] = {
            "episodes": self.episodes,
            "seeds": f"0-{self.episodes - 1}",
            "metric": "fraction of episodes whose last step satisfies the oracle (true state)",
            "command": f"zsrm scripted-eval --episodes {self.episodes} --out {self.out}",
            "machine": platform.platform(),
        }
        print(json.dumps(rates, indent=2))
        if self.out:
            print(f"wrote {write_json(result, self.out)}")
        return 0


@dataclass
class EvalVlm:
    """Zero-shot presence AUROC of each colour on held-out renders.

    Score 'a C block' / 'a C puck' against the other colours' probes on held-out renders and
    report AUROC per colour against true visibility.
    """

    vlm: str = DEFAULT_VLM  # VLM spec: scene, a saved folder, open_clip:MODEL[:TAG|:FILE|:none]
    images: int = 500  # held-out images
    seed: int = 0  # seed of the held-out (eval) stream
    out: str | None = None  # JSON path, e.g. results/vlm_presence.json (a PNG is written beside it)
    min_auroc: float = 0.95  # exit 1 if any colour falls below this
    scene: str = ""  # your own scene (module:Class or a registered id): its objects on its held-out renders
    quiet: bool = False  # no progress bars

    def run(self) -> int:
        from zsrm.evaluation.vlm_presence import own_presence_eval, presence_eval, write_presence_results
        from zsrm.vlm import load_vlm

        if self.images < 10:
            raise ValueError("--images must be at least 10")
        if self.out:
            files.check_writable(self.out)
        if self.scene:
            result, arrays = own_presence_eval(load_vlm(self.vlm), self.scene, n_images=self.images, seed=self.seed,
                                               progress=not self.quiet)
        else:
            result, arrays = presence_eval(load_vlm(self.vlm), n_images=self.images, seed=self.seed,
                                           progress=not self.quiet)
        command = ["zsrm", "eval-vlm", "--vlm", self.vlm, "--images", str(self.images), "--seed", str(self.seed)]
        command += ["--scene", self.scene] if self.scene else []
        result["meta"]["command"] = shlex.join(command + (["--out", str(self.out)] if self.out else []))
        print(json.dumps({k: v for k, v in result.items() if k.startswith("auroc.")}, indent=2))
        if self.out:
            json_path, png_path = write_presence_results(result, arrays, self.out)
            print(f"wrote {json_path} and {png_path}")
        unmeasured = result["meta"].get("unmeasured", {})
        for obj, why in unmeasured.items():
            print(f"{obj}: {why}: no AUROC, and the VLM cannot have learnt it from presence captions (let the "
                  "scenes hold subsets of the objects)", file=sys.stderr)
        failing = [k for k, v in result.items() if k.startswith("auroc.") and k[6:] not in unmeasured
                   and not v >= self.min_auroc]
        if failing:
            print(f"below {self.min_auroc}: {', '.join(failing)}", file=sys.stderr)
        if failing or unmeasured:
            return 1
        return 0


@dataclass
class EvalPose:
    """Whether a VLM knows the pendulum's pose in words: the pose each held-out render's sentences
    pick, against its true pose, and "upright" as the pendulum's base reward decides it."""

    vlm: str  # the pendulum VLM: a folder of zsrm pretrain-vlm --pendulum-scenes
    images: int = 400  # held-out renders (poses drawn evenly)
    seed: int = 1  # seed of the renders (pretraining renders its --seed, 0 by default)
    out: str | None = None  # JSON path, e.g. results/pendulum_pose.json
    quiet: bool = False  # no progress bars

    def run(self) -> int:
        from zsrm.evaluation.pendulum_pose import pose_eval
        from zsrm.vlm import load_vlm

        if self.images < 4:
            raise ValueError("--images must be at least 4 (one per pose on average)")
        if self.out:
            files.check_writable(self.out)
        result = pose_eval(load_vlm(self.vlm), n_images=self.images, seed=self.seed, progress=not self.quiet)
        command = ["zsrm", "eval-pose", "--vlm", self.vlm, "--images", str(self.images), "--seed", str(self.seed)]
        result["meta"]["command"] = shlex.join(command + (["--out", str(self.out)] if self.out else []))
        print(json.dumps({k: v for k, v in result.items() if k != "meta"}, indent=2))
        if self.out:
            print(f"wrote {write_json(result, self.out)}")
        return 0


@dataclass
class BaseRewardOptions:
    vlm: str = DEFAULT_VLM  # VLM spec: scene, open_clip:RN50, a model folder, ...
    mode: Literal["dot", "cosine", "projection"] = "dot"  # dot: E_I(image) . E_L(goal) (paper 2.1); cosine: normalised; projection: VLM-RMs goal-baseline regularisation
    baseline: str | None = None  # baseline sentence for --mode projection, e.g. 'two pucks on a table'
    alpha: float = 0.5  # projection strength in [0, 1]

    def base_reward(self, camera: str):
        from zsrm.rewards.files import make_base_reward

        return make_base_reward(self.vlm, camera, self.mode, self.baseline, self.alpha)


@dataclass(kw_only=True)
class Reward(BaseRewardOptions):
    """Score image files (PNG/JPG) for a goal sentence with the base reward."""

    images: tuple[str, ...] = field(metadata={"positional": True, "metavar": "IMAGE", "split": False})  # image files
    goal: str  # the goal sentence, e.g. 'a yellow block on top of a red block'
    json: bool = False  # print JSON instead of 'score<TAB>path' lines

    def run(self) -> int:
        from zsrm.rewards.files import read_image, score_files
        from zsrm.rewards.interface import check_goal

        goal = check_goal(self.goal)
        for p in self.images:  # fail on a bad path before loading the model
            read_image(p)
        scores = score_files(self.images, goal, self.base_reward("image"))
        if self.json:
            print(json.dumps({"goal": goal, "vlm": self.vlm, "mode": self.mode,
                              "scores": dict(zip(map(str, self.images), scores))}, indent=2))
        else:
            for path, s in zip(self.images, scores):
                print(f"{s:.6f}\t{path}")
        return 0


@dataclass(kw_only=True)
class RewardCurve(BaseRewardOptions):
    """Base reward along a scripted trajectory: CSV + PNG (the paper's Figure 5)."""

    goal: str = FIGURE5_GOAL  # a goal with a scripted controller (the first object is pushed toward the second)
    camera: Literal["front", "left", "tilted"] = "tilted"  # the camera the reward reads
    steps: int = 30  # control steps after the reset frame
    seed: int = 0  # seed of the scene's start state
    image_size: int = 64  # image side in pixels
    out: str = "results/figure5"  # output prefix: writes PREFIX.csv and PREFIX.png

    def run(self) -> int:
        from zsrm.evaluation.curves import plot_curve, record_trajectory, reward_curve, summarise, write_csv
        from zsrm.rewards.interface import check_goal

        goal = check_goal(self.goal)
        files.check_writable(Path(self.out).with_suffix(".csv"))
        reward = self.base_reward(self.camera)
        traj = record_trajectory(goal, cameras=(self.camera,), steps=self.steps, seed=self.seed,
                                 image_size=self.image_size)
        rows = reward_curve(traj, {"base": reward})
        out = Path(self.out)
        csv_path = write_csv(rows, out.with_suffix(".csv"))
        title = (f"base reward ({self.mode}, vlm {self.vlm}) for {goal!r}, {self.camera} camera, "
                 f"seed {self.seed}\ngreen: oracle says the goal holds")
        png_path = plot_curve(rows, traj, out.with_suffix(".png"), camera=self.camera, title=title)
        print(json.dumps(summarise(rows), indent=2))
        print(f"wrote {csv_path} and {png_path}")
        return 0


@dataclass
class EvalGrounding:
    """Localisation error, caption P/R/F1, Figure 3."""

    data: str = field(metadata={"positional": True})  # a collected and labelled dataset folder
    labels: str = LABELS  # labels folder (relative to DATA unless absolute)
    out: str = "results/grounding.json"  # JSON report
    figure: str | None = None  # Figure 3 style PNG to write
    index: int | None = None  # image of the figure (default: first with red+yellow)
    csv: str | None = None  # also write PREFIX_cameras.csv and PREFIX_relations.csv

    def run(self) -> int:
        from zsrm.evaluation.grounding_quality import evaluate_grounding, figure3, save_report, write_tables

        if not Path(self.data).is_dir():
            raise FileNotFoundError(f"no dataset folder {self.data}: run zsrm collect and zsrm label first")
        if self.figure:
            from zsrm.data.dataset import ExplorationData

            if ExplorationData(self.data).scene_adapter:  # Figure 3 shows zsrm's red and yellow blocks
                raise ValueError(f"--figure draws zsrm's red and yellow blocks; {self.data} holds your own scene's data")
        for path in (self.out, self.figure, self.csv and f"{self.csv}_cameras.csv"):
            if path:
                files.check_writable(path)
        report = evaluate_grounding(self.data, labels=self.labels)
        report["meta"]["command"] = "zsrm eval-grounding " + " ".join(
            [self.data, "--labels", str(self.labels), "--out", str(self.out)]
            + (["--figure", str(self.figure)] if self.figure else []))
        out = save_report(report, self.out)
        if self.csv:
            write_tables(report, self.csv)
        if self.figure:
            figure3(self.data, self._labelling_vlm(), self.figure, labels=self.labels, index=self.index)
        for cam in report["median_px_error"]:
            print(f"{cam:7s} median error {report['median_px_error'][cam]:.2f} px "
                  f"(block {report['block_width_px'][cam]:.1f} px), p90 {report['p90_px_error'][cam]:.2f} px")
        for rel, f1 in report["f1"].items():
            oracle = report["f1_vs_world"][rel]
            print(f"{rel:12s} F1 {'n/a' if f1 is None else f'{f1:.3f}'}  (support {report['support'][rel]}); "
                  f"against the oracle {'n/a' if oracle is None else f'{oracle:.3f}'}  "
                  f"(support {report['support_world'][rel]})")
        for note in report["notes"]:
            print("note:", note)
        print(f"wrote {out}" + (f" and {self.figure}" if self.figure else ""))
        return 0

    def _labelling_vlm(self):
        """The VLM the labels were made with (named in their manifest)."""
        from zsrm.data.dataset import ExplorationData
        from zsrm.data.shards import read_manifest
        from zsrm.vlm import load_vlm

        return load_vlm(read_manifest(ExplorationData(self.data).labels_folder(self.labels))["config"]["vlm"])


@dataclass
class EvalReward:
    """zsrm vs base reward against the oracle on held-out frames; curves."""

    zsrm: str = "runs/zsrm/student"  # the full reward model reported as 'zsrm': a student or fine-tuned VLM folder, or 'student' (the shipped one)
    compare: tuple[str, ...] = field(default=(), metadata={"metavar": "NAME=FOLDER", "split": False})  # more models to report beside it, e.g. finetuned_vlm=runs/zsrm/vlm
    base: str = DEFAULT_VLM  # the base VLM (spec)
    base_mode: Literal["dot", "cosine"] = "dot"  # the base reward's raw score (dot: paper 2.1)
    tasks: tuple[str, ...] = REPORT_TASKS  # catalogue tasks
    distractor_tasks: tuple[str, ...] = ("stack",)  # also with one distractor of each other colour, as TASK_distractor
    scripted_episodes: int = 10  # scripted episodes per task
    random_episodes: int = 10  # random-action episodes per task
    every: int = 2  # keep every this many steps' frame
    seed: int = 10_000  # first episode seed
    out: str = "results/reward_eval.json"  # JSON report
    curves: str = "auto"  # folder for curve CSV/PNG; auto: results/reward_curves with the default --out, else <out>_curves/ beside --out ('' to skip)
    curve_steps: int = 80  # steps of each scripted curve
    scene: str = ""  # your own scene (module:Class or a registered id): --tasks are goal sentences over its objects, scored on --data
    data: str = ""  # with --scene: held-out data of it (zsrm collect --scene, then zsrm label), labelled by its oracle
    quiet: bool = False  # no progress bars

    def run(self) -> int:
        import numpy as np

        from zsrm.evaluation.reward_quality import distractor_frames, evaluate_rewards, rollout_frames
        from zsrm.rewards.base import BaseReward

        if self.scene:
            return self.run_scene()
        files.check_writable(self.out)
        self.curves = self.curves_folder()
        if self.curves:
            files.check_writable(self.curves, folder=True)
        names, models, base_vlm = self._models()
        frames = {t: rollout_frames(t, self.scripted_episodes, self.random_episodes, self.seed, self.every,
                                    progress=not self.quiet) for t in self.tasks}
        for t in self.distractor_tasks:
            frames[f"{t}_distractor"] = distractor_frames(t, self.scripted_episodes, self.random_episodes, self.seed,
                                                          self.every, progress=not self.quiet)

        def base_raw(f):
            return BaseReward(base_vlm, camera=f.camera, mode=self.base_mode).score(f.images, f.goal)

        results = evaluate_rewards(models, frames, raw_scores={"base": base_raw})
        results["meta"] = self._meta(names, frames)
        out = write_json(results, self.out, indent=1, default=float)
        if self.curves:
            self._write_curves(models, base_vlm, frames)
        self._print_table(results, models, [*self.tasks, *(f"{d}_distractor" for d in self.distractor_tasks)])
        print(f"wrote {out}")
        return 0 if np.isfinite([results[k][t]["f1"] for k in models for t in self.tasks]).all() else 1

    def curves_folder(self) -> str:
        """Where the curves go: ``auto`` keeps a report written elsewhere from overwriting the
        committed ``results/reward_curves``."""
        if self.curves != "auto":
            return self.curves
        if Path(self.out) == Path(type(self).out):
            return "results/reward_curves"
        return str(Path(self.out).with_suffix("")) + "_curves"

    def run_scene(self) -> int:
        """eval-reward on an own scene: its goals, its held-out collected frames, its oracle."""
        from zsrm.envs.adapter import load_adapter
        from zsrm.evaluation.reward_quality import evaluate_rewards, scene_data_frames
        from zsrm.rewards.base import BaseReward
        from zsrm.tasks.scene_goals import parse_scene_goal

        if self.tasks == REPORT_TASKS or not self.data:
            raise ValueError("with --scene, give --tasks (goal sentences over its objects) and --data (held-out data "
                             "of it: zsrm collect --scene, then zsrm label)")
        if self.distractor_tasks not in ((), ("stack",)) or self.compare:
            raise ValueError("--distractor-tasks and --compare are for zsrm's scenes")
        adapter = load_adapter(self.scene)
        goals = {t: parse_scene_goal(t, adapter.objects, self.scene) for t in self.tasks}
        files.check_writable(self.out)
        names, models, base_vlm = self._models(objects=adapter.objects)
        frames = {g.text: scene_data_frames(self.data, g) for g in goals.values()}

        def base_raw(f):
            return BaseReward(base_vlm, camera=f.camera, mode=self.base_mode).score(f.images, f.goal)

        results = evaluate_rewards(models, frames, raw_scores={"base": base_raw})
        for per_task in results.values():
            for m in per_task.values():  # every frame is of exploration: no scripted split
                m.pop("f1_scripted", None)
        results["meta"] = {
            "command": "zsrm " + " ".join(sys.argv[1:]), "scene": self.scene, "data": self.data, "models": names,
            "training": {"zsrm": _training_summary(self.zsrm)},
            "frames": {t: {"n": len(f), "positives": int(f.success.sum()), "camera": f.camera}
                       for t, f in frames.items()},
            "label": "the scene's oracle: the goal's sentence among the image's true-coordinate captions (zsrm label's "
                     "labels/oracle: the privileged positions along the role camera's axes, as SceneTask judges)",
            "frames_kept": "the held-out images that hold the goal's objects (the goal's scene, as training sees it)",
            "binary": "1 when the goal text beats every negative on the camera the relation is read on; the base "
                      "VLM binarised by the same rule",
            "machine": platform.platform(),
        }
        out = write_json(results, self.out, indent=1, default=float)
        self._print_table(results, models, list(frames))
        print(f"wrote {out}")
        return 0

    def _models(self, objects=None) -> tuple[dict, dict, object]:
        """(name -> spec, name -> ZSRMReward, the base VLM); ``objects``: an own scene's phrases."""
        from zsrm.common.registry import SHIPPED
        from zsrm.fullmodel import load_reward_backbone
        from zsrm.rewards.binarised import ZSRMReward

        names = {"zsrm": self.zsrm}
        for item in self.compare:
            key, sep, folder = item.partition("=")
            if not sep or not key or not folder or key in ("zsrm", "base", "meta"):
                raise ValueError(f"--compare takes NAME=FOLDER with a new NAME, got {item!r}")
            names[key] = folder
        for folder in names.values():
            if not Path(folder).is_dir() and folder not in SHIPPED:
                raise FileNotFoundError(f"no model folder {folder}: train it with zsrm finetune")
        models = {key: ZSRMReward(load_reward_backbone(folder), name=key, objects=objects)
                  for key, folder in names.items()}
        base_vlm = load_reward_backbone(self.base)
        models["base"] = ZSRMReward(base_vlm, name="base_binary", objects=objects)
        names["base"] = self.base
        return names, models, base_vlm

    def _meta(self, names: dict, frames: dict) -> dict:
        from zsrm.common.registry import SHIPPED

        return {
            "command": "zsrm " + " ".join(sys.argv[1:]),
            "models": names,
            "training": {k: _training_summary(SHIPPED.get(v, v)) for k, v in names.items() if k != "base"},
            "frames": {t: {"n": len(f), "positives": int(f.success.sum()), "camera": f.camera, "goal": f.goal,
                           "scripted": int((f.source == "scripted").sum()),
                           "random": int((f.source == "random").sum())} for t, f in frames.items()},
            "episodes": {"scripted": self.scripted_episodes, "random": self.random_episodes,
                         "seeds": f"{self.seed}-{self.seed + self.scripted_episodes + self.random_episodes - 1}",
                         "every": self.every},
            "label": "info['is_success'] of the task's scene (the oracle, true state)",
            "binary": "1 when the goal text beats every negative (other relations over the same objects, swapped "
                      "order) on the camera the relation is read on; the base reward is binarised by the same rule",
            "auroc": f"of the raw score: zsrm cosine(frame, goal); base: BaseReward mode {self.base_mode!r}",
            "f1_best_threshold": "F1 of the raw score at its best threshold on these labels (privileged upper bound)",
            "machine": platform.platform(),
        }

    def _write_curves(self, models: dict, base_vlm, frames: dict) -> None:
        from zsrm.evaluation.reward_quality import write_curves
        from zsrm.rewards.base import BaseReward
        from zsrm.rewards.binarised import ZSRMReward

        for t in self.tasks:
            curve_models = {k: m for k, m in models.items() if k != "base"}
            curve_models["zsrm_raw"] = ZSRMReward(models["zsrm"].model, output="raw")
            # The base reward as the paper plots it (Figure 5: the raw score), and binarised.
            curve_models["base"] = BaseReward(base_vlm, camera=frames[t].camera, mode=self.base_mode)
            curve_models["base_binary"] = models["base"]
            csv_path, png_path, _ = write_curves(t, curve_models, self.curves, steps=self.curve_steps,
                                                 seed=self.seed + 999)
            print(f"wrote {csv_path} and {png_path}")

    def _print_table(self, results: dict, models: dict, tasks: list[str]) -> None:
        width, first = max(14, *(len(k) + 8 for k in models)), max(12, *(len(t) + 2 for t in tasks))
        header = f"{'task':<{first}}" + "".join(f"{k + ' F1':>{width}}" for k in models)
        print(header + "".join(f"{k + ' AUROC':>{width}}" for k in models))
        for t in tasks:
            row = f"{t:<{first}}" + "".join(f"{results[k][t]['f1']:>{width}.3f}" for k in models)
            print(row + "".join(f"{results[k][t]['auroc']:>{width}.3f}" for k in models))


def _training_summary(folder: str) -> dict | None:
    """What ``zsrm finetune`` recorded about a model: its settings and held-out accuracy (of each
    member, for an ensemble)."""
    from zsrm.common.registry import folder_kind, read_config
    from zsrm.fullmodel.ensemble import KIND

    if folder_kind(folder) == KIND:
        return {"members": {m: _training_summary(str(Path(folder) / m)) for m in read_config(folder)["members"]}}
    path = Path(folder) / "training.json"
    if not path.is_file():
        return None
    d = json.loads(path.read_text())
    val = d.get("validation", {})
    return {"config": d.get("config"), "train_pairs": d.get("train_pairs"), "train_seconds": d.get("train_seconds"),
            "val_pairs_scored": val.get("pairs"),
            "val_argmax_accuracy_vs_gradcam_labels": val.get("argmax_accuracy")}

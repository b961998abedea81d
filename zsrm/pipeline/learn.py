"""Stages that learn policies: ``zsrm train``, ``zsrm rollout``, ``zsrm sweep``.

Heavy imports (torch, SB3, Ray, MuJoCo) happen inside ``run``, so ``zsrm --help`` stays fast.
"""
from __future__ import annotations

import dataclasses
import json
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from zsrm.common.files import check_writable, write_json
from zsrm.common.machine import describe
from zsrm.rl.config import REWARDS, PresetName, TrainConfig, preset_settings
from zsrm.tasks.catalogue import LEARNING_TASKS


def with_preset(options, name: str) -> TrainConfig:
    """The TrainConfig of ``options``; a preset's value fills each field left at its default."""
    defaults = TrainConfig()
    values = {f.name: getattr(options, f.name) for f in dataclasses.fields(TrainConfig)}
    for key, value in preset_settings(name, options.goal, options.scene).items():
        if values[key] == getattr(defaults, key):
            values[key] = value
    return TrainConfig(**values)


@dataclass
class Train(TrainConfig):
    """Train a policy from pixels with PPO (or SAC: --config sac) and a reward from the goal sentence."""

    out: str | None = None  # run folder (default: runs/rl/<goal>-<reward>-<seed>)
    config: PresetName = "cpu"  # preset: cpu (300k steps, 2 cores), paper (200k steps, more envs), v3 (issue 52's learner, the default's values since 2026-12-06: less action noise, mean-action evaluation), v2 (before then), v1 (before 2026-12-04), sac (SAC on keypoints pretrained on random actions' frames: 64 px, 4 envs, 500k steps), per-task (issue 52's learner by the goal's relation: sac for close to (push_close), 500k steps and the online correction for in between and in front of, 500k for behind, else the default)
    fresh: bool = False  # start over instead of resuming the run folder's checkpoint
    device: str = "cpu"  # where the VLM trunk and PPO run: cpu, cuda, cuda:N or auto (not part of the run's config)
    env_workers: int = 0  # processes that step the scenes (0: 2 with 8+ envs and 2+ cores, else 1; the same numbers either way); give 1 when runs share the cores

    def run(self) -> int:
        from zsrm.rl.learners import train
        from zsrm.rl.ppo import auto_env_workers

        cfg = with_preset(self, self.config)
        out = Path(self.out or f"runs/rl/{cfg.goal.replace(' ', '_')}-{cfg.reward}-{cfg.seed}")
        check_writable(out, folder=True)
        summary = train(cfg, out, fresh=self.fresh, device=self.device,
                        env_workers=self.env_workers or auto_env_workers(cfg))
        print(f"{cfg.goal} with the {cfg.reward} reward, {summary['env_steps']} env steps: oracle episode reward "
              f"{summary['final_mean']:.1f} +- {summary['final_se']:.1f}, success {summary['final_success_rate']:.2f} "
              f"over {summary['final_episodes']} episodes")
        print(f"wrote {out}/ (policy/, eval.csv, summary.json, {'keypoints/' if cfg.learner == 'sac' else 'tb/'})")
        return 0


@dataclass
class Rollout:
    """Run a trained policy (or 'random:GOAL') and report the oracle episode reward."""

    policy: str = field(metadata={"positional": True})  # a policy folder written by zsrm train, or random:GOAL
    episodes: int = 10  # seeded episodes
    seed: int = 0  # evaluation seed
    spread: Literal["seen", "unseen"] = "seen"  # start-state spread: one block width (seen) or two (unseen)
    gif: str | None = None  # write a GIF of the first episode here
    out: str | None = None  # JSON path for the result
    scene: str | None = None  # with random:GOAL, your own scene (module:Class or a registered id) whose objects GOAL names
    actions: Literal["trained", "mean", "sampled"] = "trained"  # the policy's mean action, a sampled one, or as its run evaluated (eval_deterministic)

    def run(self) -> int:
        from zsrm.rl.evaluate import rollout

        for path in (self.out, self.gif):
            if path:
                check_writable(path)
        deterministic = {"trained": None, "mean": True, "sampled": False}[self.actions]
        result = rollout(self.policy, self.episodes, self.seed, self.spread, self.gif, self.scene, deterministic)
        print(f"oracle episode reward {result['mean']:.1f} +- {result['se']:.1f}, "
              f"success {result['success_rate']:.2f} over {self.episodes} episodes")
        if self.gif:
            print(f"wrote {self.gif}")
        if self.out:
            print(f"wrote {write_json(self.out, result)}")
        return 0


def parse_settings(settings) -> dict:
    """``KEY=VALUE`` strings (KEY as zsrm train's option or its field: zsrm-correct-every or
    zsrm_correct_every) to TrainConfig settings, each VALUE read as JSON where it is (numbers, true,
    false), else as a string.

    >>> parse_settings(["gamma=0.99", "zsrm-correct-every=5000", "start=around"])
    {'gamma': 0.99, 'zsrm_correct_every': 5000, 'start': 'around'}
    """
    known, out = {f.name for f in dataclasses.fields(TrainConfig)}, {}
    for item in settings:
        key, sep, value = item.partition("=")
        key = key.strip().lstrip("-").replace("-", "_")
        if not sep or key not in known:
            raise ValueError(f"--settings takes KEY=VALUE with KEY a zsrm train setting, got {item!r}")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def absolute_if_folder(spec: str) -> str:
    """A model spec that names an existing folder, made absolute; any other spec unchanged."""
    return str(Path(spec).resolve()) if spec and Path(spec).is_dir() else spec


@dataclass
class Sweep:
    """Train tasks x rewards x seeds on Ray Tune (resumable), then gather the summary and plot."""

    tasks: tuple[str, ...] = LEARNING_TASKS  # catalogue tasks or goal sentences (default: the nine relations' tasks)
    rewards: tuple[str, ...] = ("oracle", "zsrm", "random")  # rewards, of: oracle, zsrm, base, vice, curiosity, random
    seeds: tuple[int, ...] = (0, 1, 2)  # seeds per task and reward
    root: str = "runs/rl"  # one folder per trial under here (shared storage on a cluster)
    steps: int | None = None  # env steps per trial (default: the preset's for the task, else 300k)
    num_cpus: int = 2  # CPUs of the local Ray (one trial per CPU)
    address: str | None = None  # a Ray cluster to join instead (auto, or ray://HOST:PORT)
    reward_model: str = "student"  # the zsrm reward's model folder, or student (the shipped one)
    out: str = "results/rl/learning.json"  # the gathered summary; the plot beside it (.png), trials in trials/
    trials_dir: str | None = None  # where the finished trials' summaries are kept (default: trials/ beside --out)
    gather_only: bool = False  # train nothing: gather the trials finished so far (e.g. while a sweep runs)
    vlm: str = "scene"  # the VLM whose image trunk the policies read (a folder pretrained by zsrm pretrain-vlm)
    init_root: str | None = None  # start each trial from the policy of the trial of its name under here
    config: PresetName = "cpu"  # TrainConfig preset of every trial (cpu, the default: v3, issue 52's learner, since 2026-12-06; v2: before then; v1: before 2026-12-04; sac; per-task: each task's own, as zsrm train --config per-task)
    scene: str | None = None  # your own scene (module:Class or a registered id) whose objects --tasks name (docs/own-scene.md)
    settings: tuple[str, ...] = ()  # other TrainConfig settings of every trial, KEY=VALUE each as zsrm train takes them (gamma=0.99 zsrm-correct-every=5000)
    train: dict = field(default_factory=dict, metadata={"cli": False})  # other TrainConfig settings (tiny scales)

    def run(self) -> int:
        from zsrm.evaluation.learning_curves import plot_learning_curves
        from zsrm.rl.sweep import core_hours, gather, keep_trial_summaries, sweep

        unknown = set(self.rewards) - set(REWARDS)
        if unknown:
            raise ValueError(f"unknown rewards {', '.join(sorted(unknown))}; choose from {', '.join(REWARDS)}")
        check_writable(self.root, folder=True)
        check_writable(self.out)
        out = Path(self.out)
        kept_dir = Path(self.trials_dir) if self.trials_dir else out.parent / "trials"
        if not self.gather_only:
            ran = sweep(self.root, self.tasks, self.rewards, self.seeds, self.overrides, num_cpus=self.num_cpus,
                        address=self.address, kept=kept_dir, init_root=self.init_root)
            print(f"ran {len(ran)} trial(s); the others were finished already")
        trials = self.trials()
        kept = keep_trial_summaries(self.root, kept_dir, trials)
        if not kept:
            print("no finished trials yet")
            return 0
        summary = gather(kept)
        write_json(out, {**summary, "meta": {**self.meta(len(kept), len(trials)), "core_hours": core_hours(kept)}})
        plot_learning_curves(summary, out.with_suffix(".png"))
        for task, rewards in summary.items():
            print(task + ": " + ", ".join(f"{r} {v['final_mean']:.1f}+-{v['final_se']:.1f} ({v['seeds']} seeds)"
                                          for r, v in rewards.items()))
        print(f"wrote {out} and {out.with_suffix('.png')}")
        return 0

    def overrides(self, task: str | None = None) -> dict:
        """The TrainConfig settings of ``task``'s trials (the preset's for the task, then the command's)."""
        # A model folder by its absolute path: Ray Tune runs each trial in its own working directory.
        return {**preset_settings(self.config, task, self.scene), **parse_settings(self.settings), **self.train,
                **({"steps": self.steps} if self.steps else {}), "reward_model": absolute_if_folder(self.reward_model),
                "vlm": absolute_if_folder(self.vlm), **({"scene": self.scene} if self.scene else {})}

    def trials(self) -> list[dict]:
        """The sweep's trials: name and TrainConfig (as a dict) of each."""
        from zsrm.rl.sweep import trial_grid

        return trial_grid(self.tasks, self.rewards, self.seeds, self.overrides, self.init_root)

    def meta(self, finished: int, planned: int) -> dict:
        return {"trials_finished": finished, "trials_planned": planned,
                "metric": "oracle episode reward: control steps of 100 in the goal relation, mean over 30 "
                          "evaluation episodes per seed, then mean and s.e. over seeds"
                          + ("; pendulum: the oracle episode return, the env's reward summed over an episode of at "
                             "most 100 control steps" if "pendulum" in self.tasks else ""),
                "command": f"zsrm sweep --tasks {shlex.join(self.tasks)} --rewards {' '.join(self.rewards)} "
                           f"--seeds {' '.join(map(str, self.seeds))}" + (f" --steps {self.steps}" if self.steps else "")
                           + f" --out {self.out}" + (f" --trials-dir {self.trials_dir}" if self.trials_dir else "")
                           + (f" --config {self.config}" if self.config != "cpu" else "")
                           + (f" --settings {shlex.join(self.settings)}" if self.settings else "")
                           + (f" --root {self.root}" if self.root != "runs/rl" else "")
                           + (f" --scene {self.scene}" if self.scene else "")
                           + (f" --vlm {self.vlm}" if self.vlm != "scene" else "")
                           + (f" --reward-model {self.reward_model}" if self.reward_model != "student" else ""),
                "machine": describe() + ", no GPU"}


@dataclass
class Plot:
    """Figures 6 and 4 of the paper from a sweep's gathered summary.

    Figure 6: one panel per manipulation task, one line per reward. Figure 4 (with --figure4):
    the double pendulum with the base and oracle rewards, e.g. from the pendulum's own sweep:
    zsrm plot --summary results/rl/pendulum.json --figure4 results/rl/figure4.png
    """

    summary: str = "results/rl/learning.json"  # a summary written by zsrm sweep
    figure6: str = "results/rl/figure6.png"  # where to write Figure 6 (when the summary holds manipulation tasks)
    figure4: str | None = None  # where to write Figure 4, the pendulum's base vs oracle (needs pendulum runs)

    def run(self) -> int:
        from zsrm.common.files import read_json
        from zsrm.evaluation.learning_curves import PENDULUM, plot_figure4, plot_learning_curves

        check_writable(self.figure4 or self.figure6)  # before any work
        summary = {task: rewards for task, rewards in read_json(self.summary).items() if task != "meta"}
        if not summary:
            raise ValueError(f"{self.summary} holds no finished trials; run zsrm sweep first")
        manipulation = {task: rewards for task, rewards in summary.items() if task != PENDULUM}
        if not self.figure4 and not manipulation:
            raise ValueError(f"{self.summary} holds only the {PENDULUM}: plot it with --figure4 PATH")
        if self.figure4:
            print(f"wrote {plot_figure4(summary, self.figure4)}")
        if manipulation:
            check_writable(self.figure6)
            written = plot_learning_curves(manipulation, self.figure6, title="oracle episode reward while training")
            print(f"wrote {written}")
        return 0

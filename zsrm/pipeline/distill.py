"""Stages of the multi-task policy (paper 2.3, 3.3, Table 2), run in this order:

1. ``zsrm multitask-policies``: the 18 training tasks' policies, zsrm reward, one Ray sweep;
2. ``zsrm multitask-rollouts``: 50 rollouts of each, with the goal text (no blue anywhere);
3. ``zsrm distill``: behaviour cloning of the language, primitive-code and unconditioned policies;
4. ``zsrm eval-multitask``: Table 2 (JSON, markdown, bar plot).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from zsrm.common.files import check_writable
from zsrm.common.machine import describe
from zsrm.pipeline import narrow
from zsrm.pipeline.learn import Sweep
from zsrm.policy.training import DistillConfig
from zsrm.rl.config import STACKING, PresetName, goal_relation
from zsrm.tasks.catalogue import TRAIN_TASKS

POLICIES_ROOT = "runs/multitask/policies"
POLICIES_SUMMARY = "results/multitask/policies.json"


def kept_policies(summary: str | Path) -> Path:
    """Where ``zsrm multitask-policies --out summary`` keeps the finished policies (under version control)."""
    return Path(summary).parent / "task_policies"


KEPT_POLICIES = str(kept_policies(POLICIES_SUMMARY))
# The stacking tasks' policies in choice scenes (zsrm multitask-policies --choice).
CHOICE_ROOT = "runs/multitask/policies-choice"
CHOICE_SUMMARY = "results/multitask/choice/policies.json"
ROLLOUTS = "data/multitask/rollouts"
DISTILLED = "runs/multitask/distill"


def train_goals(tasks: tuple[str, ...] = ()) -> list[str]:
    """The named training tasks' canonical sentences in TRAIN_TASKS order (all 18 when none)."""
    from zsrm.policy.rollouts import train_task_index

    indices = sorted({train_task_index(t) for t in tasks}) if tasks else range(len(TRAIN_TASKS))
    return [TRAIN_TASKS[i].text for i in indices]


@dataclass
class MultitaskPolicies:
    """Train the 18 training tasks' policies with the zsrm reward as one Ray sweep (resumable)."""

    tasks: tuple[str, ...] = ()  # training tasks (goal sentences) to train; default: all 18
    seed: int = 0  # the policies' seed
    steps: int = 200_000  # env steps per task (the paper's 200k)
    root: str = POLICIES_ROOT  # one run folder per task under here
    num_cpus: int = 2  # CPUs of the local Ray (one trial per CPU)
    address: str | None = None  # a Ray cluster to join instead (auto, or ray://HOST:PORT)
    reward_model: str = "student"  # the zsrm reward's model folder, or student (the shipped one)
    out: str = POLICIES_SUMMARY  # the gathered summary (trials kept beside it in trials/)
    vlm: str = "scene"  # the VLM whose image trunk the policies read
    choice: bool = False  # the stacking tasks in choice scenes (zsrm train --choice), each from its --init-root policy
    init_root: str = KEPT_POLICIES  # with --choice: the two-block task policies to start from
    config: PresetName = "cpu"  # TrainConfig preset of the policies (cpu, the default: v3, issue 52's learner, since 2026-12-06; v2: before then; v1: before 2026-12-04)
    train: dict = field(default_factory=dict, metadata={"cli": False})  # other TrainConfig settings (tiny scales)

    def run(self) -> int:
        from zsrm.policy.rollouts import keep_task_policies

        goals, train, init_root = train_goals(self.tasks), self.train, None
        if self.choice:
            if Path(self.out) == Path(POLICIES_SUMMARY) or Path(self.root) == Path(POLICIES_ROOT):
                raise ValueError("--choice trains other policies of the same names: give it a --root and an --out "
                                 f"of its own (e.g. --root {CHOICE_ROOT} --out {CHOICE_SUMMARY})")
            goals = [g for g in goals if goal_relation(g) in STACKING]
            train, init_root = {**train, "choice": True}, self.init_root
        sweep = Sweep(tasks=tuple(goals), rewards=("zsrm",), seeds=(self.seed,), root=self.root,
                      steps=self.steps, num_cpus=self.num_cpus, address=self.address, vlm=self.vlm,
                      reward_model=self.reward_model, out=self.out, init_root=init_root, config=self.config,
                      train=train)
        status = sweep.run()
        # Beside the kept trial summaries, as the sweep keeps them: the rollouts need the weights.
        keep = kept_policies(self.out)
        kept = keep_task_policies(self.root, keep, sweep.trials())
        print(f"{len(kept)} of {len(sweep.tasks)} task policies kept in {keep}/")
        return status


@dataclass
class MultitaskRollouts:
    """Roll out each training task's policy (seeded episodes, goal text kept): the distillation data."""

    tasks: tuple[str, ...] = ()  # training tasks (goal sentences); default: all 18
    policies: str = KEPT_POLICIES  # the task policies kept by zsrm multitask-policies (at its default --out)
    seed: int = 0  # the task policies' seed (their folder names)
    episodes: int = 50  # episodes of 100 control steps per task
    envs: int = 10  # episodes stepped together
    choice_policies: str | None = None  # the stacking tasks' choice-scene policies instead (multitask-policies --choice)
    out: str = ROLLOUTS  # dataset folder (shards + manifest; resumes)

    def run(self) -> int:
        from zsrm.policy.rollouts import RolloutConfig, collect_rollouts, policy_folder

        check_writable(self.out, folder=True)
        goals = train_goals(self.tasks)
        # Each policy rolls out in the scenes it was trained in: a choice policy in choice scenes.
        roots = [self.choice_policies if self.choice_policies and goal_relation(g) in STACKING else self.policies
                 for g in goals]
        folders = [str(policy_folder(root, g, self.seed)) for root, g in zip(roots, goals)]
        missing = [f for f in folders if not os.path.isdir(f)]
        if missing:
            raise FileNotFoundError(f"no task policy in {missing[0]} ({len(missing)} of {len(folders)} missing); "
                                    "run zsrm multitask-policies first")
        data = collect_rollouts(RolloutConfig(tuple(goals), tuple(folders), self.episodes, self.envs), self.out)
        rewards = data.episode_rewards
        print(f"{len(goals)} tasks, {len(rewards)} episodes; task policies' oracle episode reward "
              f"{sum(rewards) / len(rewards):.1f}")
        print(f"wrote {self.out}/")
        return 0


@dataclass
class Distill(DistillConfig):
    """Behaviour cloning of the language-conditioned, primitive-code and unconditioned policies (and
    zsrm's grounded variant with --policies ... grounded)."""

    data: str = ROLLOUTS  # rollouts written by zsrm multitask-rollouts
    out: str = DISTILLED  # one folder per policy under here, and distill.json
    fresh: bool = False  # start over instead of resuming or skipping finished policies
    dagger_rounds: int = 0
    """zsrm's method, not the paper's: after behaviour cloning, rounds of DAgger-style relabelling (the
    student's own frames labelled by the task policies, aggregated, trained on; OUT/dagger/); 0: the
    paper's plain behaviour cloning"""
    dagger_episodes: int = 10  # with --dagger-rounds: the student's episodes per training task per round
    dagger_epochs: int = 2  # with --dagger-rounds: epochs over the aggregated data per round
    teachers: str | None = None  # with --dagger-rounds: the task policies' folder (default: those the rollouts name)

    def run(self) -> int:
        from zsrm.policy.dagger import Dagger, DaggerConfig
        from zsrm.policy.training import distill

        check_writable(self.out, folder=True)
        dagger = Dagger(DaggerConfig(self.dagger_rounds, self.dagger_episodes, self.dagger_epochs), self.teachers) \
            if self.dagger_rounds else None
        summary = distill(narrow(self, DistillConfig), self.data, self.out, fresh=self.fresh, dagger=dagger)
        for name, p in summary["policies"].items():
            rounds = "".join(f"; round {r['round']}: {r['relabelled']} frames relabelled, student's oracle episode "
                             f"reward {r['student_reward']:.1f}, loss {r['final_loss']:.4f}"
                             for r in p.get("rounds", []))
            print(f"{name}: final L2 loss {p['final_loss']:.4f}{rounds}")
        print(f"{summary['schedule']} schedule, {summary['tower']} tower, {summary['epochs']} epochs over "
              f"{summary['frames']} frames of {len(summary['goals'])} tasks; wrote {self.out}/")
        return 0


def language_text(policies: dict) -> dict:
    """How the language policy reads its goal embeddings, for the table (nothing when raw)."""
    cfg = policies["language"].cfg if "language" in policies else None
    how = [word for word, on in (("centred", cfg and cfg.centre_text), ("span", cfg and cfg.text_span)) if on]
    return {"language_text": ", ".join(how)} if how else {}


@dataclass
class EvalMultitask:
    """Table 2: the distilled policies on the training and test tasks, seen and unseen start spread."""

    policies: tuple[str, ...] = (DISTILLED,)  # the folders zsrm distill wrote (one table; a name once)
    data: str = ROLLOUTS  # the rollouts distilled from (the task policies' own oracle reward)
    seeds: int = 50  # seeded episodes per task
    tasks: int | None = None  # only the first N training and N test tasks (default: all 18 and 18)
    out: str = "results/table2.json"  # the table; .md and .png beside it
    threads: int = 2  # torch threads
    text_span: bool = False  # the language policy reads each goal's embedding projected onto the training goals' span
    fresh: bool = False  # score every cell again instead of reusing those saved under POLICIES/eval/

    def __post_init__(self):
        if isinstance(self.policies, (str, Path)):  # one folder
            self.policies = (str(self.policies),)

    def run(self) -> int:
        import shutil

        import torch

        from zsrm.evaluation.multitask import (best_policy, ceiling, evaluate_policies, primitive_mapping,
                                               split_goals, taught_ceiling, write_table)
        from zsrm.policy.rollouts import RolloutData
        from zsrm.policy.training import load_distilled_runs, runs_vlm
        from zsrm.vlm import load_vlm

        check_writable(self.out)
        torch.set_num_threads(self.threads)
        runs = load_distilled_runs(self.policies)
        summaries, policies = [s for s, _ in runs], {n: p for _, ps in runs for n, p in ps.items()}
        # The first run's settings; the grounded policy's view from the run that has one.
        summary = {**summaries[0], **next(({"keypoint_view": s["keypoint_view"]} for s in summaries
                                           if "keypoint_view" in s), {})}
        runs_vlm(runs)  # one VLM for them all
        if self.text_span:
            if "language" not in policies:
                raise ValueError(f"--text-span is the language policy's; {self.policies} has none")
            policies["language"].cfg.text_span = True
        data, vlm = RolloutData(self.data), load_vlm(summary["vlm"])
        splits = split_goals(self.tasks)
        choice = bool(data.choice_goals)  # scored in the scenes the stacking tasks were rolled out in
        table: dict = {}
        for folder, (_, run) in zip(self.policies, runs):
            cache = Path(folder) / "eval"
            if self.fresh:
                shutil.rmtree(cache, ignore_errors=True)
            table.update(evaluate_policies(run, vlm, splits, self.seeds, cache=cache, choice=choice))
        # What the paper's policies read, from the policies themselves (one distill run: one view).
        views = {p.cfg.keypoint_view for p in policies.values() if p.cfg.conditioning != "grounded"}
        dagger = next((s["dagger"] for s in summaries if s.get("distillation") == "dagger"), None)
        taught = next((s["mirror_teachers"] for s in summaries if "mirror_teachers" in s), None)
        table.update(schedule=summary["schedule"], tower=summary["tower"], **({"scenes": "choice"} if choice else {}),
                     **({"image_view": ", ".join(sorted(views))} if views else {}),
                     **language_text(policies), **({"dagger": dagger} if dagger else {}),
                     **({"mirror_teachers": taught} if taught is not None else {}),
                     oracle_task_policies=ceiling(data),
                     **({"oracle_teachers": taught_ceiling(data, taught)} if taught is not None else {}),
                     meta=self.meta(summary, splits, primitive_mapping(policies["primitive"], vlm, splits["test"])
                                    if "primitive" in policies else None))
        best = best_policy(table)
        if best:
            table["best"] = best
        for path in write_table(table, self.out):
            print(f"wrote {path}")
        return 0

    def meta(self, summary: dict, splits: dict, mapping: dict | None) -> dict:
        return {"seeds": self.seeds, "tasks_per_split": len(splits["train"]), "spreads": ["seen", "unseen"],
                "epochs": summary["epochs"], "pretrained": summary["pretrained"], "vlm": summary["vlm"],
                "text_embedding": summary["text_embedding"], "distill_seed": summary.get("seed"),
                "distilled_tasks": summary["goals"],
                **({"keypoint_view": summary["keypoint_view"]} if "keypoint_view" in summary else {}),
                "primitive_mapping_test": mapping,
                "metric": "oracle episode reward: control steps of 100 in the goal relation; mean and s.e. over "
                          "all episodes of the split (seeds x tasks), and over its tasks of each relation (relations)",
                "command": f"zsrm eval-multitask --policies {' '.join(self.policies)} --data {self.data} --seeds {self.seeds}"
                           + (f" --tasks {self.tasks}" if self.tasks else "")
                           + (" --text-span" if self.text_span else "") + f" --out {self.out}",
                "machine": describe()}

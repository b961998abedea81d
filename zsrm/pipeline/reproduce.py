"""``zsrm reproduce --scale {demo,cpu,paper}``: the whole pipeline, stage by stage, and its report.

Each stage's output is cached in ``WORKDIR/<stage>/`` with a ``stage.json`` holding the stage's
configuration: a stage finished with the same configuration is skipped, a killed one resumes
(every long stage below resumes from its own checkpoints). One progress view lists the stages
and the time each took.

* ``demo`` (``make demo``, offline, under 10 minutes on 2 cores): the shipped scene VLM and
  student reward model; one policy trained with the zsrm reward on one task against a random
  policy; the committed results of the ``cpu`` scale beside it.
* ``cpu``: builds every model from scratch on this machine (pretrain the scene VLM, collect and
  label exploration data, fine-tune, the RL sweep on Ray); hours on 2 cores.
* ``paper``: the ``cpu`` stages with the paper's model (``--vlm open_clip:RN50``, weights
  downloaded by open_clip on the user's machine) and RL settings; for a GPU machine or a Ray
  cluster (``--address``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Literal

from zsrm.common.files import check_writable, read_json, write_json

SCALES: dict[str, dict] = {
    # place_right: a random policy almost never succeeds there (0.1 of 100), so learning shows;
    # push_close's pucks start close enough that random actions already score 13.
    "demo": {"task": "place_right", "steps": 300_000, "seeds": (0,), "episodes": 30},
    # the demo's stages in seconds, for tests
    "tiny": {"task": "push_close", "steps": 256, "seeds": (0,), "episodes": 2,
             "train": dict(n_envs=2, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=2, eval_every=128,
                           checkpoint_every=128, keypoints=4)},
    "cpu": {"tasks": ("stack", "place_right", "push_close"), "steps": 300_000, "seeds": (0, 1, 2), "episodes": 30,
            "multitask": {"steps": 200_000, "episodes": 50, "seeds": 50, "schedule": "cpu"}},
    "paper": {"tasks": ("stack", "place_right", "push_close"), "steps": 200_000, "seeds": (0, 1, 2), "episodes": 50,
              "multitask": {"steps": 200_000, "episodes": 50, "seeds": 50, "schedule": "paper"}},
    # every cpu stage in a few minutes, for tests
    "tiny-cpu": {"tasks": ("place_right",), "steps": 256, "seeds": (0,), "episodes": 2,
                 "pretrain": dict(arch="tiny", scenes=24, shard_size=24, steps=4, batch_size=16, warmup_steps=1,
                                  checkpoint_every=2),
                 "data": dict(images=48, shard_size=24),
                 "student": dict(steps=4, batch_size=8, student_arch="tiny", eval_every=2, checkpoint_every=2,
                                 val_pairs=16),
                 "train": dict(n_envs=2, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=2, eval_every=128,
                               checkpoint_every=128, keypoints=4),
                 "multitask": {"steps": 256, "episodes": 2, "seeds": 2, "tasks": 2, "epochs": 1, "schedule": "cpu"}},
}


def is_demo(scale: str) -> bool:
    """Demo-kind scales (demo, tiny) train one task with the shipped models; the others build everything."""
    return "task" in SCALES[scale]


@dataclass
class Stage:
    name: str
    what: str  # one line for the progress view and the report
    config: dict  # what defines the stage's output (a change reruns it)
    run: Callable[[Path], dict]  # does the work in its folder, returns a small result (JSON)
    command: str  # the command that reproduces it alone


def run_stages(stages: list[Stage], workdir: Path) -> list[dict]:
    """Run the stages in order, skipping those finished with the same configuration."""
    log = []
    for i, stage in enumerate(stages, 1):
        folder = workdir / stage.name
        marker = folder / "stage.json"
        done = read_json(marker) if marker.is_file() else None
        if done is not None and done.get("config") == stage.config:
            print(f"[{i}/{len(stages)}] {stage.name}: cached ({done['seconds']:.0f} s when it ran)")
            log.append({**done, "cached": True})
            continue
        print(f"[{i}/{len(stages)}] {stage.name}: {stage.what} ...", flush=True)
        start = time.time()
        folder.mkdir(parents=True, exist_ok=True)
        result = stage.run(folder)
        entry = {"stage": stage.name, "what": stage.what, "config": stage.config, "result": result,
                 "seconds": round(time.time() - start, 1), "command": stage.command}
        write_json(marker, entry)
        print(f"[{i}/{len(stages)}] {stage.name}: done in {entry['seconds']:.0f} s")
        log.append({**entry, "cached": False})
    return log


def demo_stages(scale: dict, vlm: str, config: str = "cpu") -> list[Stage]:
    """The demo scale: shipped models, one zsrm-trained policy and a random one on one task, with
    the learner preset ``config`` (zsrm train --config)."""
    from zsrm.rl.config import PRESETS, TrainConfig

    task, steps, extra = scale["task"], scale["steps"], {**PRESETS[config], **scale.get("train", {})}
    flag = f" --config {config}" if config != "cpu" else ""
    train_cfg = TrainConfig(goal=task, reward="zsrm", seed=0, steps=steps, vlm=vlm, **extra)
    random_cfg = TrainConfig(goal=task, reward="random", seed=0, vlm=vlm, **extra)

    def shipped(_folder: Path) -> dict:
        from zsrm.fullmodel import load_reward_backbone
        from zsrm.vlm import load_vlm

        return {"vlm": type(load_vlm(vlm)).__name__, "reward_model": type(load_reward_backbone("student")).__name__}

    def train_policy(folder: Path) -> dict:
        from zsrm.rl.learners import train
        from zsrm.rl.ppo import auto_env_workers

        return _brief(train(train_cfg, folder, progress=True, env_workers=auto_env_workers(train_cfg)))

    def random_policy(folder: Path) -> dict:
        from zsrm.rl.learners import train

        return _brief(train(random_cfg, folder, progress=False))

    def gifs(folder: Path) -> dict:
        from zsrm.rl.evaluate import rollout

        # Show the trained policy reaching its goal: the first of ten seeded episodes in which it does.
        for seed in range(10):
            trained = rollout(str(folder.parent / "policy_zsrm" / "policy"), 1, seed=seed,
                              gif=folder / "zsrm_policy.gif")
            if trained["mean"] > 0:
                break
        rand = rollout(f"random:{task}", 1, seed=seed, gif=folder / "random_policy.gif")
        return {"zsrm_episode_reward": trained["mean"], "random_episode_reward": rand["mean"], "seed": seed}

    return [
        Stage("models", "load the shipped scene VLM and student reward model", {"vlm": vlm, "reward_model": "student"},
              shipped, f"zsrm eval-reward --zsrm student  # the shipped student; zsrm pretrain-vlm builds the VLM"),
        Stage("policy_zsrm", f"train PPO with the zsrm reward on {task} for {steps} env steps",
              train_cfg.to_dict(), train_policy, f"zsrm train --goal {task} --reward zsrm --seed 0 --steps {steps}{flag}"),
        Stage("policy_random", f"a uniform random policy on {task}", random_cfg.to_dict(), random_policy,
              f"zsrm train --goal {task} --reward random --seed 0{flag}"),
        Stage("gifs", "one episode of each policy as a GIF (the trained one's first success of seeds 0-9)",
              {"task": task, "steps": steps, "pick": "first success"}, gifs,
              f"zsrm rollout RUN/policy --episodes 1 --gif zsrm_policy.gif"),
    ]


def _brief(summary: dict) -> dict:
    return {k: summary[k] for k in ("final_mean", "final_se", "final_success_rate", "final_episodes", "env_steps")}


def cpu_stages(scale: dict, vlm: str, address: str | None) -> list[Stage]:
    """The cpu and paper scales: every model built here, the RL sweep on Ray, then the multi-task
    policy. With ``vlm="scene"`` the scene VLM is pretrained from scratch first; any other spec
    (open_clip) is used as given."""
    return model_stages(scale, vlm) + policy_stages(scale, vlm, address)


def model_stages(scale: dict, vlm: str) -> list[Stage]:
    """Pretrain the scene VLM (unless one is given), label exploration data, train the student."""
    from zsrm.pipeline.build import Finetune, PretrainVlm, RewardData

    sizes = {k: scale.get(k, {}) for k in ("pretrain", "data", "student")}

    def pretrain(folder: Path) -> dict:
        PretrainVlm(out=str(folder / "model"), workdir=str(folder / "work"), **sizes["pretrain"]).run()
        return {"vlm": str(folder / "model")}

    def data(folder: Path) -> dict:
        RewardData(out=str(folder), vlm=run_vlm(folder, vlm), **sizes["data"]).run()  # this run's Grad-CAM
        return {"data": str(folder)}

    student_size = {"steps": 4000, **sizes["student"]}

    def student(folder: Path) -> dict:
        Finetune(data=str(folder.parent / "data"), out=str(folder / "model"), student=True,
                 vlm=run_vlm(folder, vlm), **student_size).run()
        return {"model": str(folder / "model")}

    stages = [
        Stage("data", "random exploration frames, Grad-CAM captions", {"vlm": vlm, **sizes["data"]}, data,
              "zsrm reward-data"),
        Stage("student", "the student reward model on the captions", {"vlm": vlm, **student_size},
              student, "zsrm finetune --student --steps 4000"),
    ]
    if vlm == "scene":
        stages.insert(0, Stage("vlm", "pretrain the scene VLM on presence-captioned renders", sizes["pretrain"],
                               pretrain, "zsrm pretrain-vlm"))
    return stages


def run_vlm(folder: Path, vlm: str) -> str:
    """The VLM of this run: the one its ``vlm`` stage pretrained, or the spec the user gave."""
    return str(folder.parent / "vlm" / "model") if vlm == "scene" else vlm


def policy_stages(scale: dict, vlm: str, address: str | None) -> list[Stage]:
    """Figure 6's sweep (oracle, zsrm, random), then Table 2: the training tasks' zsrm policies,
    their rollouts, the three distilled policies and their evaluation."""
    from zsrm.pipeline.distill import Distill, EvalMultitask, MultitaskPolicies, MultitaskRollouts, train_goals
    from zsrm.pipeline.learn import Sweep

    multi, train = scale["multitask"], scale.get("train", {})
    goals = tuple(train_goals())[:multi.get("tasks")]

    def common(folder: Path) -> dict:
        return {"vlm": run_vlm(folder, vlm), "reward_model": str(folder.parent / "student" / "model"),
                "address": address, "train": train}

    def sweep(folder: Path) -> dict:
        Sweep(tasks=scale["tasks"], rewards=("oracle", "zsrm", "random"), seeds=scale["seeds"], root=str(folder),
              steps=scale["steps"], out=str(folder / "learning.json"), **common(folder)).run()
        return {"summary": str(folder / "learning.json")}

    def task_policies(folder: Path) -> dict:
        MultitaskPolicies(tasks=goals, steps=multi["steps"], root=str(folder), out=str(folder / "policies.json"),
                          **common(folder)).run()
        return {"policies": str(folder), "tasks": len(goals)}

    def rollouts(folder: Path) -> dict:
        MultitaskRollouts(tasks=goals, policies=str(folder.parent / "task_policies"), episodes=multi["episodes"],
                          out=str(folder)).run()
        return {"rollouts": str(folder)}

    def distill(folder: Path) -> dict:
        Distill(schedule=multi["schedule"], epochs=multi.get("epochs"), vlm=run_vlm(folder, vlm),
                data=str(folder.parent / "rollouts"), out=str(folder)).run()
        return {"policies": str(folder)}

    def table2(folder: Path) -> dict:
        EvalMultitask(policies=str(folder.parent / "distill"), data=str(folder.parent / "rollouts"),
                      seeds=multi["seeds"], tasks=multi.get("tasks"), out=str(folder / "table2.json")).run()
        return {"table": str(folder / "table2.json")}

    grid = {"tasks": list(scale["tasks"]), "steps": scale["steps"], "seeds": list(scale["seeds"]), "train": train}
    return [
        Stage("policies", "PPO with oracle, zsrm and random on the tasks (Ray sweep, Figure 6)", grid, sweep,
              "zsrm sweep"),
        Stage("task_policies", f"PPO with the zsrm reward on {len(goals)} training tasks (Ray sweep)",
              {"goals": list(goals), "steps": multi["steps"], "train": train}, task_policies,
              "zsrm multitask-policies"),
        Stage("rollouts", "rollouts of the task policies with their goal text", {"episodes": multi["episodes"]},
              rollouts, "zsrm multitask-rollouts"),
        Stage("distill", "behaviour cloning: language, primitive-code and unconditioned policies",
              {"schedule": multi["schedule"], "epochs": multi.get("epochs")}, distill, "zsrm distill"),
        Stage("table2", "the distilled policies on training and held-out tasks (Table 2)",
              {"seeds": multi["seeds"], "tasks": multi.get("tasks")}, table2, "zsrm eval-multitask"),
    ]


@dataclass
class Reproduce:
    """Run the whole pipeline at a scale (demo, cpu, paper) and write its report."""

    scale: Literal["demo", "cpu", "paper"] = "demo"  # how much to build and train
    workdir: str | None = None  # stage outputs, cached by configuration (default: runs/reproduce/SCALE)
    report: str = "reports/demo"  # the report folder (index.html and README.md)
    vlm: str = "scene"  # the VLM: scene (offline), or open_clip:RN50 etc. when you have the weights
    address: str | None = None  # a Ray cluster for the sweep (cpu and paper scales)
    config: Literal["cpu", "v3", "v2"] = "cpu"  # demo scales: the policy's learner preset (cpu, the default: v3 since 2026-12-06; v2: the demo before then)

    def run(self) -> int:
        from zsrm.pipeline.report import write_report

        if self.config != "cpu" and not is_demo(self.scale):
            raise ValueError(f"--config is for the demo scales; the {self.scale} scale builds with the default learner")
        workdir = Path(self.workdir or f"runs/reproduce/{self.scale}")
        check_writable(workdir, folder=True)
        check_writable(Path(self.report), folder=True)
        scale = SCALES[self.scale]
        start = time.time()
        stages = (demo_stages(scale, self.vlm, self.config) if is_demo(self.scale)
                  else cpu_stages(scale, self.vlm, self.address))
        log = run_stages(stages, workdir)
        wall = time.time() - start
        demo_task = SCALES[self.scale]["task"] if is_demo(self.scale) else None
        index = write_report(Path(self.report), self.scale, self.vlm, log, workdir, wall, demo_task, self.config)
        print(f"report: {index.resolve()}")
        return 0

"""``zsrm reproduce --scale {demo,cpu,paper}``: the whole pipeline, stage by stage, and its report.

Each stage's output is cached in ``WORKDIR/<stage>/`` with a ``stage.json`` holding the stage's
configuration: a stage finished with the same configuration is skipped, a killed one resumes
(every long stage below resumes from its own checkpoints). One progress view lists the stages
and the time each took.

* ``demo`` (``make demo``, offline, about 10-20 minutes on 2 cores): the shipped scene VLM and
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

from zsrm.vlm.files import check_writable, read_json, write_json

SCALES: dict[str, dict] = {
    "demo": {"task": "push_close", "steps": 120_000, "seeds": (0,), "episodes": 30},
    # the demo's stages in seconds, for tests
    "tiny": {"task": "push_close", "steps": 256, "seeds": (0,), "episodes": 2,
             "train": dict(n_envs=2, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=2, eval_every=128,
                           checkpoint_every=128, keypoints=4)},
    "cpu": {"tasks": ("stack", "place_right", "push_close"), "steps": 300_000, "seeds": (0, 1, 2), "episodes": 30},
    "paper": {"tasks": ("stack", "place_right", "push_close"), "steps": 200_000, "seeds": (0, 1, 2), "episodes": 50},
}


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


def demo_stages(scale: dict, vlm: str) -> list[Stage]:
    """The demo scale: shipped models, one zsrm-trained policy and a random one on one task."""
    from zsrm.rl.config import TrainConfig

    task, steps, extra = scale["task"], scale["steps"], scale.get("train", {})
    train_cfg = TrainConfig(goal=task, reward="zsrm", seed=0, steps=steps, vlm=vlm, **extra)
    random_cfg = TrainConfig(goal=task, reward="random", seed=0, vlm=vlm, **extra)

    def shipped(_folder: Path) -> dict:
        from zsrm.fullmodel import load_reward_backbone
        from zsrm.vlm import load_vlm

        return {"vlm": type(load_vlm(vlm)).__name__, "reward_model": type(load_reward_backbone("student")).__name__}

    def train_policy(folder: Path) -> dict:
        from zsrm.rl.ppo import train

        return _brief(train(train_cfg, folder, progress=True))

    def random_policy(folder: Path) -> dict:
        from zsrm.rl.ppo import train

        return _brief(train(random_cfg, folder, progress=False))

    def gifs(folder: Path) -> dict:
        from zsrm.rl.evaluate import rollout

        trained = rollout(str(folder.parent / "policy_zsrm" / "policy"), 1, seed=0, gif=folder / "zsrm_policy.gif")
        rand = rollout(f"random:{task}", 1, seed=0, gif=folder / "random_policy.gif")
        return {"zsrm_episode_reward": trained["mean"], "random_episode_reward": rand["mean"]}

    return [
        Stage("models", "load the shipped scene VLM and student reward model", {"vlm": vlm, "reward_model": "student"},
              shipped, f"zsrm eval-reward --zsrm student  # the shipped student; zsrm pretrain-vlm builds the VLM"),
        Stage("policy_zsrm", f"train PPO with the zsrm reward on {task} for {steps} env steps",
              train_cfg.to_dict(), train_policy, f"zsrm train --goal {task} --reward zsrm --seed 0 --steps {steps}"),
        Stage("policy_random", f"a uniform random policy on {task}", random_cfg.to_dict(), random_policy,
              f"zsrm train --goal {task} --reward random --seed 0"),
        Stage("gifs", "one episode of each policy as a GIF", {"task": task, "steps": steps}, gifs,
              f"zsrm rollout RUN/policy --episodes 1 --gif zsrm_policy.gif"),
    ]


def _brief(summary: dict) -> dict:
    return {k: summary[k] for k in ("final_mean", "final_se", "final_success_rate", "final_episodes", "env_steps")}


def cpu_stages(scale: dict, vlm: str, address: str | None) -> list[Stage]:
    """The cpu and paper scales: every model built here, then the RL sweep on Ray. With
    ``vlm="scene"`` the scene VLM is pretrained from scratch first; any other spec (open_clip)
    is used as given."""
    from zsrm.pipeline.build import Finetune, PretrainVlm, RewardData
    from zsrm.pipeline.learn import Sweep

    def pretrain(folder: Path) -> dict:
        PretrainVlm(out=str(folder / "model"), workdir=str(folder / "work")).run()
        return {"vlm": str(folder / "model")}

    def data(folder: Path) -> dict:
        labeller = str(folder.parent / "vlm" / "model") if vlm == "scene" else vlm
        RewardData(out=str(folder), vlm=labeller).run()  # Grad-CAM of the VLM of this run
        return {"data": str(folder)}

    def student(folder: Path) -> dict:
        text_vlm = str(folder.parent / "vlm" / "model") if vlm == "scene" else vlm
        Finetune(data=str(folder.parent / "data"), out=str(folder / "model"), student=True, steps=4000,
                 vlm=text_vlm).run()
        return {"model": str(folder / "model")}

    def sweep(folder: Path) -> dict:
        Sweep(tasks=scale["tasks"], rewards=("oracle", "zsrm", "random"), seeds=scale["seeds"], root=str(folder),
              steps=scale["steps"], address=address, reward_model=str(folder.parent / "student" / "model"),
              out=str(folder / "learning.json")).run()
        return {"summary": str(folder / "learning.json")}

    stages = [
        Stage("data", "random exploration frames, Grad-CAM captions", {"vlm": vlm}, data, "zsrm reward-data"),
        Stage("student", "the student reward model on the captions", {"vlm": vlm, "steps": 4000}, student,
              "zsrm finetune --student --steps 4000"),
        Stage("policies", "PPO with oracle, zsrm and random on the tasks (Ray sweep)",
              {"tasks": list(scale["tasks"]), "steps": scale["steps"], "seeds": list(scale["seeds"])}, sweep,
              "zsrm sweep"),
    ]
    if vlm == "scene":
        stages.insert(0, Stage("vlm", "pretrain the scene VLM on presence-captioned renders", {}, pretrain,
                               "zsrm pretrain-vlm"))
    return stages


@dataclass
class Reproduce:
    """Run the whole pipeline at a scale (demo, cpu, paper) and write its report."""

    scale: Literal["demo", "cpu", "paper"] = "demo"  # how much to build and train
    workdir: str | None = None  # stage outputs, cached by configuration (default: runs/reproduce/SCALE)
    report: str = "reports/demo"  # the report folder (index.html and README.md)
    vlm: str = "scene"  # the VLM: scene (offline), or open_clip:RN50 etc. when you have the weights
    address: str | None = None  # a Ray cluster for the sweep (cpu and paper scales)

    def run(self) -> int:
        from zsrm.pipeline.report import write_report

        workdir = Path(self.workdir or f"runs/reproduce/{self.scale}")
        check_writable(workdir, folder=True)
        check_writable(Path(self.report), folder=True)
        scale = SCALES[self.scale]
        start = time.time()
        demo = self.scale in ("demo", "tiny")
        stages = demo_stages(scale, self.vlm) if demo else cpu_stages(scale, self.vlm, self.address)
        log = run_stages(stages, workdir)
        wall = time.time() - start
        index = write_report(Path(self.report), self.scale, self.vlm, log, workdir, wall)
        print(f"report: {index.resolve()}")
        return 0


def demo_result(log: list[dict], wall_s: float, task: str) -> dict:
    """``results/demo.json``: the demo's learning signal (zsrm-trained policy against random)."""
    by_stage = {entry["stage"]: entry["result"] for entry in log}
    trained, rand = by_stage["policy_zsrm"], by_stage["policy_random"]
    return {"wall_s": round(wall_s, 1), "task": task,
            "zsrm_policy_mean": trained["final_mean"], "zsrm_policy_se": trained["final_se"],
            "random_policy_mean": rand["final_mean"], "random_policy_se": rand["final_se"],
            "zsrm_policy_env_steps": trained["env_steps"], "episodes": trained["final_episodes"],
            "stage_seconds": {e["stage"]: e["seconds"] for e in log},
            "stages_cached": [e["stage"] for e in log if e.get("cached")]}


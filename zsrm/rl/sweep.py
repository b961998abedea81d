"""``zsrm sweep``: tasks x rewards x seeds of ``zsrm train`` on Ray Tune.

Each trial is one :func:`~zsrm.rl.ppo.train` run in its own folder
``ROOT/<task>-<reward>-<seed>/`` (the run's own checkpoints, curve and summary), so:

* a finished trial (its ``summary.json`` made with the same settings) is skipped;
* a killed trial resumes from its last checkpoint with the same step count;
* trials run in parallel on a local Ray (``ray.init(num_cpus=N)``) or spread over a cluster
  (``address="auto"`` or ``ray://HOST:PORT``); on a cluster ROOT must be shared storage.

:func:`gather` then reads the runs' summaries into one: per task and reward the mean and
standard error over seeds of each run's final oracle episode reward, and the curves.

>>> from zsrm.rl.sweep import trial_grid
>>> [t["name"] for t in trial_grid(["stack"], ["oracle", "zsrm"], [0])]
['stack-oracle-0', 'stack-zsrm-0']
>>> trial_name("a red block on the right of a green block", "zsrm", 0)
'a_red_block_on_the_right_of_a_green_block-zsrm-0'
"""
from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np

from zsrm.common.files import write_text
from zsrm.rl.config import TrainConfig, takes_reward
from zsrm.rl.evaluate import mean_se


def trial_name(task: str, reward: str, seed: int) -> str:
    """A trial's folder name: ``<task>-<reward>-<seed>``, the task (a catalogue name or a goal
    sentence) made filesystem-safe: each run of characters other than letters, digits and
    ``_`` becomes one ``_`` (as ``zsrm train`` names its default folder), so catalogue names
    such as ``stack`` keep their names."""
    return f"{re.sub(r'[^A-Za-z0-9_]+', '_', task.strip())}-{reward}-{seed}"


def trial_grid(tasks, rewards, seeds, overrides: dict | None = None, init_root: str | None = None) -> list[dict]:
    """One trial per task x reward x seed that the task takes (the pendulum takes no zsrm or vice
    reward): its name and its TrainConfig as a dict. Seed-major, so a sweep cut short has every
    task and reward on its first seeds. ``init_root``: each trial starts from the policy of the
    trial of its name there (``<init_root>/<name>/policy``, TrainConfig's ``init``)."""
    trials = []
    for seed in seeds:
        for task in tasks:
            for reward in rewards:
                if not takes_reward(task, reward):
                    continue
                name = trial_name(task, reward, seed)
                init = {"init": str(Path(init_root) / name / "policy")} if init_root else {}
                cfg = TrainConfig(**{**(overrides or {}), **init, "goal": task, "reward": reward, "seed": int(seed)})
                trials.append({"name": name, "config": cfg.to_dict()})
    return trials


def is_finished(path: Path, config: dict) -> bool:
    """Does ``path`` (a run folder, or a kept ``<name>.json`` summary) hold a finished run of ``config``?"""
    path = path / "summary.json" if path.is_dir() else path
    if not path.is_file():
        return False
    try:
        return json.loads(path.read_text()).get("config") == config
    except json.JSONDecodeError:
        return False


def run_trial(trial: dict) -> dict:
    """Ray Tune's trainable: train (or resume) one run, reporting each evaluation to Tune."""
    import torch
    from ray import tune

    from zsrm.rl.ppo import train

    torch.set_num_threads(1)
    os.chdir(trial["cwd"])  # Ray Tune runs a trial in a folder of its own: relative paths are the sweep's
    cfg = TrainConfig.from_dict(trial["config"])
    summary = train(cfg, Path(trial["root"]) / trial["name"], progress=False,
                    on_eval=lambda row: tune.report({**row, "final": 0}))
    result = {"env_steps": summary["env_steps"], "mean": summary["final_mean"], "final": 1}
    tune.report(result)
    return result


def sweep(root: str | Path, tasks, rewards, seeds, overrides: dict | None = None, num_cpus: int = 2,
          address: str | None = None, cpus_per_trial: float = 1.0, kept: str | Path | None = None,
          init_root: str | None = None) -> list[str]:
    """Run every unfinished trial of the grid on Ray Tune; returns the names that ran. A trial
    is finished when its run folder under ``root``, or its kept summary ``kept/<name>.json``
    (see :func:`keep_trial_summaries`), holds a finished run with the same settings."""
    import ray
    from ray import tune

    root = Path(root).resolve()
    root.mkdir(parents=True, exist_ok=True)
    todo = [t for t in trial_grid(tasks, rewards, seeds, overrides, init_root)
            if not is_finished(root / t["name"], t["config"])
            and not (kept and is_finished(Path(kept) / f"{t['name']}.json", t["config"]))]
    if not todo:
        return []
    for t in todo:
        t["root"], t["cwd"] = str(root), os.getcwd()
    start_ray(ray, num_cpus, address)
    try:
        trainable = tune.with_resources(run_trial, {"cpu": cpus_per_trial})
        tuner = tune.Tuner(trainable, param_space=tune.grid_search(todo),
                           tune_config=tune.TuneConfig(max_concurrent_trials=max(1, int(num_cpus // cpus_per_trial))),
                           run_config=tune.RunConfig(name="zsrm-sweep", storage_path=str(root / "_ray"),
                                                     verbose=1))
        tuner.fit()
    finally:
        ray.shutdown()
    return [t["name"] for t in todo]


def start_ray(ray, num_cpus: int, address: str | None, tries: int = 3) -> None:
    """``ray.init`` on a cluster (``address``) or a local Ray of ``num_cpus``. Ray gives a local
    node 30 s to start, which a loaded machine can overrun: such a timeout is tried again."""
    for attempt in range(1, tries + 1):
        try:
            if address:
                ray.init(address=address, ignore_reinit_error=True, log_to_driver=False)
            else:
                ray.init(num_cpus=num_cpus, include_dashboard=False, ignore_reinit_error=True, log_to_driver=False)
            return
        except Exception as e:  # Ray raises a bare Exception for this
            if "timed out during startup" not in str(e) or attempt == tries:
                raise
            print(f"Ray did not start in time ({attempt} of {tries} tries); trying again", flush=True)
            ray.shutdown()


def gather(summaries) -> dict:
    """``<task>.<reward>.{final_mean, final_se, seeds, steps, curve}`` from run summaries (paths
    of ``summary.json`` files or their dicts); the curve is the mean and s.e. over seeds at each
    evaluation step that every seed reached."""
    runs: dict[tuple[str, str], list[dict]] = {}
    for summary in summaries:
        if not isinstance(summary, dict):
            summary = json.loads(Path(summary).read_text())
        cfg = summary["config"]
        runs.setdefault((cfg["goal"], cfg["reward"]), []).append(summary)
    out: dict = {}
    for (task, reward), group in sorted(runs.items()):
        finals = [s["final_mean"] for s in group]
        mean, se = mean_se(finals)
        out.setdefault(task, {})[reward] = {
            "final_mean": mean, "final_se": se, "seeds": len(group),
            "steps": max(s["env_steps"] for s in group),
            "final_per_seed": finals,
            "final_success_rate": float(np.mean([s["final_success_rate"] for s in group])),
            "curve": mean_curve([s["curve"] for s in group]),
        }
    return out


def core_hours(summaries) -> float:
    """Core-hours of finished runs (one core each): each summary's ``wall_s``, or for a summary
    written before it was recorded, the time of its last evaluation (a few percent short)."""
    seconds = 0.0
    for summary in summaries:
        if not isinstance(summary, dict):
            summary = json.loads(Path(summary).read_text())
        seconds += summary.get("wall_s", summary["curve"][-1]["wall_s"] if summary.get("curve") else 0.0)
    return round(seconds / 3600, 2)


def keep_trial_summaries(root: str | Path, dest: str | Path, trials) -> list[Path]:
    """Copy the finished trials' ``summary.json`` (curve included, a few kB) to
    ``dest/<name>.json``, the small files a results folder keeps under version control; returns
    the kept summaries of the grid's ``trials`` (those finished with the trial's settings)."""
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    kept = []
    for trial in trials:
        src, copy = Path(root) / trial["name"] / "summary.json", dest / f"{trial['name']}.json"
        if is_finished(src, trial["config"]):
            write_text(copy, src.read_text())
        if is_finished(copy, trial["config"]):
            kept.append(copy)
    return kept


def mean_curve(curves: list[list[dict]]) -> list[dict]:
    """Mean and s.e. over runs at each evaluation step that every run reached."""
    steps = sorted(set.intersection(*[{row["env_steps"] for row in c} for c in curves])) if curves else []
    rows = []
    for step in steps:
        values = [next(r["mean"] for r in c if r["env_steps"] == step) for c in curves]
        mean, se = mean_se(values)
        rows.append({"env_steps": step, "mean": mean, "se": se})
    return rows

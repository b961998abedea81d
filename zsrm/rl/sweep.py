"""``zsrm sweep``: tasks x rewards x seeds of ``zsrm train`` on Ray Tune.

Each trial is one :func:`~zsrm.rl.ppo.train` run in its own folder
``ROOT/<task>-<reward>-<seed>/`` (the run's own checkpoints, curve and summary), so:

* a finished trial (its ``summary.json`` made with the same settings) is skipped;
* a killed trial resumes from its last checkpoint with the same step count;
* SAC trials that differ only in their reward share their keypoints' pretraining (``ROOT/_keypoints/``);
* trials run in parallel on a local Ray (``ray.init(num_cpus=N)``) or spread over a cluster
  (``address`` HOST:PORT as ``ray start --head`` prints it, ``ray://HOST:PORT`` or ``auto``); on
  a cluster ROOT must be shared storage, and before any trial starts every node is asked
  whether it imports zsrm and writes ROOT and sees what this machine wrote there (one line
  naming the node when not, :func:`check_nodes`);
* a trial whose node dies is run again on another node (Ray Tune's ``max_failures``) and
  resumes from its last checkpoint; each start of a trial is a line of its folder's
  ``attempts.jsonl`` (node, host, the env steps it started from).

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
import logging
import os
import re
import socket
import time
import uuid
from pathlib import Path
from typing import Callable

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


def trial_grid(tasks, rewards, seeds, overrides: dict | Callable[[str], dict] | None = None,
               init_root: str | None = None) -> list[dict]:
    """One trial per task x reward x seed that the task takes (the pendulum takes no zsrm or vice
    reward): its name and its TrainConfig as a dict. ``overrides``: TrainConfig settings of every
    trial, or a function of the task giving its trials' (a per-task preset). Seed-major, so a sweep
    cut short has every task and reward on its first seeds. ``init_root``: each trial starts from the
    policy of the trial of its name there (``<init_root>/<name>/policy``, TrainConfig's ``init``)."""
    settings_of = overrides if callable(overrides) else (lambda task: overrides or {})
    trials = []
    for seed in seeds:
        for task in tasks:
            settings = settings_of(task)
            for reward in rewards:  # an own scene's goals: TrainConfig refuses a reward it cannot take
                if not settings.get("scene") and not takes_reward(task, reward):
                    continue
                name = trial_name(task, reward, seed)
                init = {"init": str(Path(init_root) / name / "policy")} if init_root else {}
                cfg = TrainConfig(**{**settings, **init, "goal": task, "reward": reward, "seed": int(seed)})
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

    from zsrm.rl.learners import train

    torch.set_num_threads(1)
    if os.path.isdir(trial["cwd"]):  # Ray Tune runs a trial in a folder of its own: relative paths are the sweep's
        os.chdir(trial["cwd"])
    cfg = TrainConfig.from_dict(trial["config"])
    root = Path(trial["root"])
    record_attempt(root / trial["name"])
    summary = train(cfg, root / trial["name"], progress=False, env_workers=1,  # one core per trial
                    on_eval=lambda row: tune.report({**row, "final": 0}), shared_keypoints=root / "_keypoints")
    result = {"env_steps": summary["env_steps"], "mean": summary["final_mean"], "final": 1}
    tune.report(result)
    return result


def record_attempt(folder: Path) -> dict:
    """Append this start of a trial to ``folder/attempts.jsonl``: the Ray node and host it runs
    on, its process and the env steps its checkpoint starts it from."""
    import ray

    from zsrm.common.files import ZsrmFileError, read_json

    state = folder / "checkpoint" / "state.json"
    try:
        start = int(read_json(state, "a checkpoint's state")["env_steps"]) if state.is_file() else 0
    except (ZsrmFileError, KeyError, TypeError, ValueError):
        start = None  # train() will say what is wrong with it
    line = {"node_id": ray.get_runtime_context().get_node_id(), "host": socket.gethostname(), "pid": os.getpid(),
            "start_env_steps": start, "time": round(time.time(), 3)}
    folder.mkdir(parents=True, exist_ok=True)
    with (folder / "attempts.jsonl").open("a") as f:
        f.write(json.dumps(line) + "\n")
    return line


def sweep(root: str | Path, tasks, rewards, seeds, overrides: dict | Callable[[str], dict] | None = None,
          num_cpus: int = 2, address: str | None = None, cpus_per_trial: float = 1.0, kept: str | Path | None = None,
          init_root: str | None = None, max_failures: int = 3) -> list[str]:
    """Run every unfinished trial of the grid on Ray Tune; returns the names that ran. A trial
    is finished when its run folder under ``root``, or its kept summary ``kept/<name>.json``
    (see :func:`keep_trial_summaries`), holds a finished run with the same settings. A trial
    that fails (its node died) is started again up to ``max_failures`` times, from its checkpoint."""
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
    check_address(address)
    try:
        start_ray(ray, num_cpus, address)
    except Exception as err:  # Ray's own errors are several lines and types
        if not address:
            raise
        raise ValueError(f"--address {address}: could not join the Ray cluster there "
                         f"({str(err).strip().splitlines()[0][:200] if str(err).strip() else type(err).__name__})") from None
    try:
        if address:
            nodes = check_nodes(ray, root)
            num_cpus = ray.cluster_resources().get("CPU", num_cpus)
            print(f"Ray cluster at {address}: {len(nodes)} nodes with CPUs ({num_cpus:g} CPUs), each imports zsrm "
                  f"and writes {root}", flush=True)
        trainable = tune.with_resources(run_trial, {"cpu": cpus_per_trial})
        tuner = tune.Tuner(trainable, param_space=tune.grid_search(todo),
                           tune_config=tune.TuneConfig(max_concurrent_trials=max(1, int(num_cpus // cpus_per_trial))),
                           run_config=tune.RunConfig(name="zsrm-sweep", storage_path=str(root / "_ray"), verbose=1,
                                                     failure_config=tune.FailureConfig(max_failures=max_failures)))
        tuner.fit()
    finally:
        ray.shutdown()
    return [t["name"] for t in todo]


def check_address(address: str | None, timeout: float = 5.0) -> None:
    """Fail now, with one line, when nothing answers at a HOST:PORT (or ray://HOST:PORT) address
    (Ray itself would wait a minute, then print a page)."""
    if not address or address == "auto":
        return
    host, _, port = address.split("://", 1)[-1].rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"--address {address!r}: expected HOST:PORT (as `ray start --head` prints it), "
                         "ray://HOST:PORT or auto")
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as err:
        raise ValueError(f"--address {address}: no Ray cluster answers there ({err.strerror or err}); start one "
                         "with `ray start --head` on its head node and pass the address it prints") from None


def node_probe():
    """The check :func:`check_nodes` runs on each node. Defined here, pickled by value (a nested
    function): it must run on a node where zsrm does not import, to say so."""

    def probe(root: str, mark: str, token: str) -> dict:
        import os
        import socket

        out = {"host": socket.gethostname()}
        try:
            import zsrm  # noqa: F401
        except Exception as err:
            out["zsrm"] = f"{type(err).__name__}: {err}"
        try:
            with open(os.path.join(root, mark)) as f:
                seen = f.read() == token
        except OSError:
            seen = False
        if not seen:
            out["shared"] = "it does not see the file this machine wrote there"
        path = os.path.join(root, f"{mark}-{os.getpid()}-{socket.gethostname()}")
        try:
            with open(path, "w") as f:
                f.write(token)
            os.remove(path)
        except OSError as err:
            out["write"] = err.strerror or str(err)
        return out

    return probe


def check_nodes(ray, root: Path, timeout: float = 180.0) -> list[dict]:
    """Ask every alive node with CPUs, before any trial starts, whether it imports zsrm and can
    write ``root`` and sees what this machine wrote there; a ValueError of one line naming each
    node that cannot. Returns the nodes' answers."""
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    nodes = [n for n in ray.nodes() if n.get("Alive") and n.get("Resources", {}).get("CPU", 0) > 0]
    token = uuid.uuid4().hex
    mark = root / f".zsrm-node-check-{token[:12]}"
    mark.write_text(token)
    try:
        probe = ray.remote(node_probe())
        refs = [probe.options(num_cpus=0, max_retries=0, scheduling_strategy=NodeAffinitySchedulingStrategy(
            n["NodeID"], soft=False)).remote(str(root), mark.name, token) for n in nodes]
        answers = ray.get(refs, timeout=timeout)
    finally:
        mark.unlink(missing_ok=True)
    problems = []
    for node, answer in zip(nodes, answers):
        where = f"node {node.get('NodeManagerAddress')} ({node['NodeID'][:8]}, host {answer['host']})"
        if "zsrm" in answer:
            problems.append(f"{where} cannot import zsrm ({answer['zsrm']}): install zsrm, the same version, "
                            "on every node")
        if "write" in answer:
            problems.append(f"{where} cannot write the trial root {root} ({answer['write']}): --root must be "
                            "storage every node sees and can write")
        elif "shared" in answer:
            problems.append(f"{where} does not share the trial root {root} with this machine ({answer['shared']}): "
                            "--root must be the same shared folder on every node")
    if problems:
        raise ValueError("; ".join(problems))
    return [{"node_id": n["NodeID"], **a} for n, a in zip(nodes, answers)]


def start_ray(ray, num_cpus: int, address: str | None, tries: int = 3) -> None:
    """``ray.init`` on a cluster (``address``) or a local Ray of ``num_cpus``. Ray gives a local
    node 30 s to start, which a loaded machine can overrun: such a timeout is tried again."""
    for attempt in range(1, tries + 1):
        try:
            if address:
                # Ray's INFO lines on joining go: a bad setup is then one line (zsrm's own)
                ray.init(address=address, ignore_reinit_error=True, log_to_driver=False, logging_level=logging.WARNING)
            else:
                ray.init(num_cpus=num_cpus, include_dashboard=False, ignore_reinit_error=True, log_to_driver=False)
            return
        except Exception as e:  # Ray raises a bare Exception for this
            if "timed out during startup" not in str(e) or attempt == tries:
                raise
            print(f"Ray did not start in time ({attempt} of {tries} tries); trying again", flush=True)
            ray.shutdown()


def gather(summaries) -> dict:
    """``<task>.<reward>.{final_mean, final_se, seeds, steps, core_hours, curve}`` (and
    ``final_by_actions``: the policies' mean and sampled actions) from run summaries (paths
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
            "core_hours": core_hours(group),
            "curve": mean_curve([s["curve"] for s in group]),
        }
        if all("final_by_actions" in s for s in group):  # runs since 2026-12-06: both ways of acting
            out[task][reward]["final_by_actions"] = {
                way: over_seeds([s["final_by_actions"][way] for s in group]) for way in ("mean", "sampled")}
    return out


def over_seeds(finals: list[dict]) -> dict:
    """Mean and s.e. over seeds of final evaluations ``{"mean", "success_rate"}``, and their mean success rate."""
    mean, se = mean_se([f["mean"] for f in finals])
    return {"final_mean": mean, "final_se": se, "final_success_rate": float(np.mean([f["success_rate"] for f in finals]))}


def core_hours(summaries) -> float:
    """Core-hours of finished runs (one core each): each summary's ``wall_s``, or for a summary
    written before it was recorded, the time of its last evaluation (a few percent short)."""
    seconds = 0.0
    for summary in summaries:
        if not isinstance(summary, dict):
            summary = json.loads(Path(summary).read_text())
        last = summary["curve"][-1] if summary.get("curve") else {}
        seconds += summary["wall_s"] if "wall_s" in summary else last.get("wall_s", 0.0)
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

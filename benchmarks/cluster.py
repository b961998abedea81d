"""results/cluster.json: a sweep on a Ray cluster of several nodes loses nothing when a node dies.

A small sweep (tiny ``zsrm train`` trials) runs with ``zsrm.rl.sweep.sweep(address=...)`` on a
cluster of ``ray start`` nodes on this machine (:class:`zsrm.testing.ray_cluster.LocalRayCluster`:
a head and worker nodes with one CPU each, their own ports, the trial root on storage every node
sees). When the trial on worker ``w1`` has passed its first checkpoint and collected at least one
rollout more, every process of ``w1`` is killed (SIGKILL, as a machine that dies). Ray Tune
starts that trial again on a surviving node, where it resumes from its checkpoint. The same
sweep then runs on a single node (one ``ray start`` head with as many CPUs), and each trial's
final figures (final evaluation episodes, curve, policy weights) are compared.

Written: ``nodes``, ``node_failures``, trials planned / finished / lost, which trials moved
node, the env steps each moved trial redid (the killed attempt's last collected rollout, read
from its TensorBoard log, minus the checkpoint the new attempt started from; at most the
checkpoint interval), and ``identical_to_single_node``.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/cluster.py --out results/cluster.json
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from zsrm.common.files import write_json
from zsrm.rl.sweep import is_finished, trial_grid
from zsrm.testing.ray_cluster import ENV, LocalRayCluster

TASK, REWARD = "push_close", "oracle"
TINY = dict(steps=2048, n_envs=2, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=2, keypoints=4,
            eval_every=512, checkpoint_every=512, threads=1)
SWEEP = ("import json, sys; from zsrm.rl.sweep import sweep; "
         "sweep(sys.argv[1], [sys.argv[2]], [sys.argv[3]], json.loads(sys.argv[4]), json.loads(sys.argv[5]), "
         "address=sys.argv[6])")


def driver(root: Path, seeds, address: str, cwd: Path) -> subprocess.Popen:
    """``sweep(root, ..., address=address)`` in a process of its own (the sweep's driver)."""
    args = [sys.executable, "-c", SWEEP, str(root), TASK, REWARD, json.dumps(list(seeds)), json.dumps(TINY), address]
    return subprocess.Popen(args, cwd=cwd, env={**os.environ, **ENV, "OMP_NUM_THREADS": "1"})


def attempts(folder: Path) -> list[dict]:
    path = folder / "attempts.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.is_file() else []


def collected_env_steps(folder: Path, pid: int) -> int:
    """Env steps the attempt of process ``pid`` had collected: its last rollout in TensorBoard."""
    from tensorboard.backend.event_processing.event_file_loader import EventFileLoader

    steps = 0
    for path in (folder / "tb").glob(f"events.out.tfevents.*.{pid}.*"):
        try:
            for event in EventFileLoader(str(path)).Load():
                if any(v.tag == "time/fps" for v in event.summary.value):
                    steps = max(steps, int(event.step))
        except Exception:  # a record being written: read again later
            pass
    return steps * TINY.get("action_repeat", 4)


def checkpoint_steps(folder: Path) -> int:
    state = folder / "checkpoint" / "state.json"
    try:
        return int(json.loads(state.read_text())["env_steps"])
    except (OSError, ValueError, KeyError):
        return 0


def kill_when_past_checkpoint(cluster: LocalRayCluster, root: Path, names: list[str], node: str,
                              proc: subprocess.Popen, timeout: float = 1800) -> dict:
    """Kill ``node`` once its trial has checkpointed and collected a rollout past the checkpoint."""
    deadline = time.time() + timeout
    while time.time() < deadline and proc.poll() is None:
        ids = {nid for nid, name in cluster.node_names().items() if name == node}
        for name in names:
            tried = attempts(root / name)
            if tried and tried[-1]["node_id"] in ids and len(tried) == 1:
                done = checkpoint_steps(root / name)
                collected = collected_env_steps(root / name, tried[-1]["pid"])
                if done > 0 and collected > done:
                    killed = cluster.kill_node(node)
                    return {"trial": name, "checkpoint_env_steps": done, "collected_env_steps": collected,
                            "processes_killed": killed, "time": time.time()}
        time.sleep(0.5)
    raise RuntimeError(f"no trial on {node} passed a checkpoint before the sweep ended")


def final_figures(folder: Path) -> dict:
    from safetensors.numpy import load_file

    summary = json.loads((folder / "summary.json").read_text())
    weights = load_file(str(folder / "policy" / "model.safetensors"))
    return {"final_episode_rewards": summary["final_episode_rewards"], "env_steps": summary["env_steps"],
            "curve": [{k: v for k, v in row.items() if k != "wall_s"} for row in summary["curve"]],
            "weights": weights}


def same(a: dict, b: dict) -> bool:
    return (a["final_episode_rewards"] == b["final_episode_rewards"] and a["curve"] == b["curve"]
            and a["env_steps"] == b["env_steps"] and a["weights"].keys() == b["weights"].keys()
            and all(np.array_equal(a["weights"][k], b["weights"][k]) for k in a["weights"]))


def main(out: str, seeds, workers: int) -> dict:
    t0 = time.time()
    work = Path(tempfile.mkdtemp(prefix="zsrm-cluster-"))
    trials = trial_grid([TASK], [REWARD], seeds, TINY)
    names = [t["name"] for t in trials]

    root = work / "root"  # the shared trial root: every node of this machine sees it
    root.mkdir()
    with LocalRayCluster(work / "nodes", head_cpus=1) as cluster:
        for i in range(1, workers + 1):
            cluster.add_node(f"w{i}", cpus=1)
        node_count = len([n for n in cluster.nodes() if n["alive"]])
        proc = driver(root, seeds, cluster.address, work)
        kill = kill_when_past_checkpoint(cluster, root, names, "w1", proc)
        print(f"killed node w1 ({kill['processes_killed']} processes) while {kill['trial']} was at "
              f"{kill['collected_env_steps']} env steps, checkpoint {kill['checkpoint_env_steps']}", flush=True)
        code = proc.wait()
        node_names = cluster.node_names()
    cluster_s = time.time() - t0

    single = work / "single"
    single.mkdir()
    with LocalRayCluster(work / "single-node", head_cpus=1 + workers) as one:
        code_single = driver(single, seeds, one.address, work).wait()

    per_trial, moved = {}, []
    for t in trials:
        name, folder = t["name"], root / t["name"]
        tried = attempts(folder)
        nodes = [node_names.get(a["node_id"], a["node_id"]) for a in tried]
        finished = is_finished(folder, t["config"])
        equal = finished and is_finished(single / name, t["config"]) and same(final_figures(folder),
                                                                               final_figures(single / name))
        per_trial[name] = {"nodes": nodes, "finished": finished, "same_as_single_node": bool(equal),
                           "final_mean": json.loads((folder / "summary.json").read_text())["final_mean"]
                           if finished else None}
        for before, after in zip(tried, tried[1:]):
            reached = collected_env_steps(folder, before["pid"])
            moved.append({"trial": name, "from_node": node_names.get(before["node_id"]),
                          "to_node": node_names.get(after["node_id"]), "killed_attempt_collected_env_steps": reached,
                          "resumed_from_env_steps": after["start_env_steps"],
                          "redone_env_steps": reached - after["start_env_steps"]})
    finished = sum(v["finished"] for v in per_trial.values())
    result = {
        "nodes": node_count, "cpus_per_node": 1, "node_failures": 1, "killed_node": "w1",
        "trials_planned": len(trials), "trials_finished": finished, "trials_lost": len(trials) - finished,
        "moved_trials": moved, "checkpoint_every": TINY["checkpoint_every"],
        "rollout_env_steps": TINY["n_envs"] * TINY["n_steps"] * 4,
        "redone_within_checkpoint_interval": all(m["redone_env_steps"] <= TINY["checkpoint_every"] for m in moved),
        "identical_to_single_node": all(v["same_as_single_node"] for v in per_trial.values()),
        "trials": per_trial, "kill": {k: v for k, v in kill.items() if k != "time"},
        "driver_exit_status": code, "single_node_driver_exit_status": code_single,
        "settings": {"task": TASK, "reward": REWARD, "seeds": list(seeds), **TINY},
        "compared": "each trial's final evaluation episodes, eval curve (wall time aside), env steps and policy "
                    "weights against the same sweep on one node of the same CPU count; same machine, 1 thread",
        "redone_measure": "the killed attempt's last rollout collected (its TensorBoard log) minus the checkpoint "
                          "its next attempt started from; the attempt may have been up to one rollout further",
        "wall_s": {"cluster_sweep": round(cluster_s, 1), "total": round(time.time() - t0, 1)},
        "command": f"OMP_NUM_THREADS=1 .venv/bin/python benchmarks/cluster.py --out {out}",
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
    }
    write_json(out, result)
    shutil.rmtree(work, ignore_errors=True)
    return result


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/cluster.json")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--workers", type=int, default=2, help="worker nodes beside the head (one CPU each)")
    args = parser.parse_args()
    r = main(args.out, args.seeds, args.workers)
    print(json.dumps({k: r[k] for k in ("nodes", "node_failures", "trials_planned", "trials_finished", "trials_lost",
                                        "moved_trials", "identical_to_single_node")}, indent=1))

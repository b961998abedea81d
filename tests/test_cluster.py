"""zsrm sweep on a Ray cluster of two nodes on this machine (zsrm.testing.ray_cluster: separate
``ray start`` nodes with their own CPUs, ports and temporary folders): trials placed on both
nodes and finished, finished trials skipped on a rerun; the bad setups (no cluster at the
address, a node without zsrm, a root a node cannot write) each one line and exit status 2,
before any trial starts. About 3 minutes on a busy 2-core machine (two tiny trials)."""
import json
import os
import subprocess
import sys

import pytest

from zsrm.rl.sweep import is_finished, trial_grid
from zsrm.testing.ray_cluster import ENV, LocalRayCluster, free_port

TINY = dict(steps=512, n_envs=2, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=2, keypoints=4,
            eval_every=256, checkpoint_every=256)
DRIVER_ENV = {**os.environ, **ENV, "OMP_NUM_THREADS": "1"}


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    with LocalRayCluster(tmp_path_factory.mktemp("ray-nodes"), head_cpus=1) as c:
        c.add_node("w1", cpus=1)
        yield c


def zsrm_sweep(cwd, *args, timeout=300):
    """``zsrm sweep ARGS`` in ``cwd`` (not the repository: a node's workers see the driver's paths)."""
    return subprocess.run([sys.executable, "-m", "zsrm.cli", "sweep", "--tasks", "push_close", "--rewards", "oracle",
                           "--seeds", "0", "--out", str(cwd / "out.json"), *args], cwd=cwd, env=DRIVER_ENV,
                          capture_output=True, text=True, timeout=timeout)


def assert_one_line_error(proc, words, root):
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("zsrm sweep: error: ") and words in lines[0], proc.stderr[-2000:]
    assert not (root / "push_close-oracle-0").exists()  # no trial started


def test_two_trial_sweep_runs_on_both_nodes(cluster, tmp_path):
    root = tmp_path / "root"
    code = ("import json, sys; from zsrm.rl.sweep import sweep; "
            "print(sweep(sys.argv[1], ['push_close'], ['oracle'], [0, 1], json.loads(sys.argv[2]), address=sys.argv[3]))")
    args = [sys.executable, "-c", code, str(root), json.dumps(TINY), cluster.address]
    subprocess.run(args, cwd=tmp_path, env=DRIVER_ENV, check=True, timeout=900)
    names = cluster.node_names()
    ran_on = set()
    for t in trial_grid(["push_close"], ["oracle"], [0, 1], TINY):
        assert is_finished(root / t["name"], t["config"])
        attempts = [json.loads(line) for line in (root / t["name"] / "attempts.jsonl").read_text().splitlines()]
        assert len(attempts) == 1 and attempts[0]["start_env_steps"] == 0
        ran_on.add(names[attempts[0]["node_id"]])
    assert ran_on == {"head", "w1"}  # one trial on each node

    mtimes = [p.stat().st_mtime_ns for p in sorted(root.glob("*/summary.json"))]
    rerun = subprocess.run(args, cwd=tmp_path, env=DRIVER_ENV, check=True, timeout=300, capture_output=True, text=True)
    assert rerun.stdout.strip().endswith("[]")  # finished trials skipped
    assert mtimes == [p.stat().st_mtime_ns for p in sorted(root.glob("*/summary.json"))]


def test_an_address_without_a_cluster_is_one_line(tmp_path):
    proc = zsrm_sweep(tmp_path, "--address", f"127.0.0.1:{free_port()}", "--root", str(tmp_path / "root"), timeout=120)
    assert_one_line_error(proc, "no Ray cluster answers there", tmp_path / "root")


def test_a_node_without_zsrm_is_one_line(cluster, tmp_path):
    fake = tmp_path / "no-zsrm" / "zsrm"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ModuleNotFoundError(\"No module named 'zsrm'\", name='zsrm')\n")
    cluster.add_node("nozsrm", env={"PYTHONPATH": str(fake.parent)})  # its workers find this zsrm first
    try:
        proc = zsrm_sweep(tmp_path, "--address", cluster.address, "--root", str(tmp_path / "root"))
    finally:
        cluster.remove_node("nozsrm")
    assert_one_line_error(proc, "cannot import zsrm", tmp_path / "root")


def test_a_root_a_node_cannot_write_is_one_line(cluster, tmp_path):
    root = tmp_path / "root"
    root.mkdir()
    cluster.add_node("readonly", read_only=[root])  # this node sees the root read-only
    try:
        proc = zsrm_sweep(tmp_path, "--address", cluster.address, "--root", str(root))
    finally:
        cluster.remove_node("readonly")
    assert_one_line_error(proc, "cannot write the trial root", root)

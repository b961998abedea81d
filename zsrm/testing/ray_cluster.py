"""A Ray cluster of several nodes on this one machine, the way Ray tests itself: each node is its
own ``ray start --block`` process tree with its own CPUs and ports, joined to
the head's address as a node on another machine would be. Shared by ``tests/test_cluster.py``
and ``benchmarks/cluster.py``.

* :class:`LocalRayCluster`: start a head, add nodes (one without zsrm, one that sees a folder
  read-only, for the bad-setup cases), kill a node at once (every process of it, as a machine
  that dies) or remove it cleanly, list the nodes the head knows, stop everything it started.

Every process of a node carries an environment variable naming its cluster and node
(:data:`MARK`), so a node is killed, and the cluster stopped, by those processes alone: no
``ray stop``, which would stop every Ray on the machine. Nothing here writes Ray's default
temporary folder, so a ``ray.init()`` elsewhere on the machine never finds this cluster.
"""
from __future__ import annotations

import json
import os
import signal
import socket
import shutil
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

MARK = "ZSRM_TEST_RAY_NODE"
# The nodes, and the drivers and clients of this cluster, run without Ray's token authentication
# (on by default for `ray start` clusters; docs/ray.md says how to carry the token to real nodes)
ENV = {"RAY_AUTH_MODE": "disabled"}
NODE_RESOURCE = "zsrm_node_"  # a custom resource "zsrm_node_<name>": 1 names each node


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def marked_processes(prefix: str) -> list[int]:
    """Process ids whose environment has ``MARK`` starting with ``prefix``."""
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            env = (entry / "environ").read_bytes().split(b"\0")
        except OSError:
            continue
        if any(item.startswith(f"{MARK}={prefix}".encode()) for item in env):
            pids.append(int(entry.name))
    return pids


class LocalRayCluster:
    """``with LocalRayCluster(folder) as cluster: cluster.add_node("w1"); ... cluster.address``"""

    def __init__(self, folder: str | Path, head_cpus: int = 1):
        from ray.util import get_node_ip_address

        self.folder, self.head_cpus, self.ip = Path(folder), head_cpus, get_node_ip_address()
        self.id = uuid.uuid4().hex[:8]
        self.port = free_port()
        self.processes: dict[str, subprocess.Popen] = {}
        self.ray = str(Path(sys.executable).with_name("ray"))
        # Ray's sockets live under its temporary folder, whose path must stay short (107 bytes)
        self.temp = Path(tempfile.mkdtemp(prefix="zsrm-ray-"))
        os.environ.update(ENV)  # this process reads the cluster's node table

    @property
    def address(self) -> str:
        return f"{self.ip}:{self.port}"

    def __enter__(self) -> "LocalRayCluster":
        try:
            self.start()
        except BaseException:
            self.shutdown()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.shutdown()

    def _start(self, name: str, args: list[str], cpus: int, env: dict | None, read_only=()) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        ports = {flag: free_port() for flag in ("--node-manager-port", "--object-manager-port", "--metrics-export-port",
                                                "--dashboard-agent-listen-port", "--dashboard-agent-grpc-port",
                                                "--runtime-env-agent-port")}
        cmd = [self.ray, "start", "--block", *args, "--num-cpus", str(cpus),
               "--num-gpus", "0", "--resources", json.dumps({f"{NODE_RESOURCE}{name}": 1}),
               "--object-store-memory", str(100 * 2**20), "--min-worker-port", "0", "--max-worker-port", "0",
               "--disable-usage-stats", *[str(x) for kv in ports.items() for x in kv]]
        if read_only:  # this node sees these folders read-only (its own mount namespace)
            mounts = " && ".join(f"mount --bind {p} {p} && mount -o remount,bind,ro {p}" for p in map(str, read_only))
            cmd = ["unshare", "--mount", "sh", "-c", f"{mounts} && exec \"$@\"", "sh", *cmd]
        node_env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
        node_env.update({**ENV, **(env or {})})
        node_env.update({MARK: f"{self.id}:{name}", "RAY_USAGE_STATS_ENABLED": "0"})
        log = (self.folder / f"{name}.log").open("w")
        self.processes[name] = subprocess.Popen(cmd, env=node_env, stdout=log, stderr=subprocess.STDOUT,
                                                start_new_session=True)
        self.wait_for(name)

    def start(self) -> None:
        self._start("head", ["--head", "--port", str(self.port), "--temp-dir", str(self.temp),
                             "--include-dashboard", "false", "--ray-client-server-port", str(free_port())],
                    self.head_cpus, None)

    def add_node(self, name: str, cpus: int = 1, env: dict | None = None, read_only=()) -> None:
        """A worker node of ``cpus`` CPUs; ``env``: its environment's changes (e.g. a PYTHONPATH
        whose ``zsrm`` does not import: a node without zsrm); ``read_only``: folders it cannot write."""
        self._start(name, ["--address", self.address], cpus, env, read_only)

    def nodes(self) -> list[dict]:
        """``{"name", "node_id", "alive"}`` of each node the head knows."""
        from ray._raylet import GcsClient

        out = []
        for node_id, info in GcsClient(address=self.address).get_all_node_info(timeout=10).items():
            names = [k[len(NODE_RESOURCE):] for k in info.resources_total if k.startswith(NODE_RESOURCE)]
            out.append({"name": names[0] if names else None, "node_id": node_id.hex(), "alive": info.state == 0})
        return out

    def node_names(self) -> dict[str, str]:
        """node id -> node name, for every node the head has known."""
        return {n["node_id"]: n["name"] for n in self.nodes()}

    def wait_for(self, name: str, timeout: float = 180) -> None:
        deadline, last = time.time() + timeout, None
        while time.time() < deadline:
            if self.processes[name].poll() is not None:
                raise RuntimeError(f"Ray node {name} exited ({self.folder / f'{name}.log'})")
            try:
                if any(n["name"] == name and n["alive"] for n in self.nodes()):
                    return
            except Exception as err:  # the head's GCS not up yet
                last = err
            time.sleep(1.0)
        raise TimeoutError(f"Ray node {name} did not join in {timeout:.0f} s ({self.folder / f'{name}.log'}; {last})")

    def kill_node(self, name: str) -> int:
        """SIGKILL every process of node ``name`` (its raylet, workers, trials): as a machine that
        dies. Returns how many were killed."""
        pids = marked_processes(f"{self.id}:{name}")
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        process = self.processes.pop(name, None)
        if process is not None:
            process.wait()
        return len(pids)

    def remove_node(self, name: str, timeout: float = 60) -> None:
        """Stop node ``name`` the way ``ray stop`` would stop that node alone (SIGTERM to its
        ``ray start --block``, which stops its processes and leaves the cluster), then wait until
        the head counts it dead; anything left is killed."""
        process = self.processes.pop(name, None)
        if process is not None:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                pass
        self.processes[name] = process  # kill_node waits for it
        self.kill_node(name)
        deadline = time.time() + timeout
        while time.time() < deadline and any(n["name"] == name and n["alive"] for n in self.nodes()):
            time.sleep(1.0)

    def shutdown(self) -> None:
        """Kill every process of this cluster's nodes (workers first, the head last)."""
        for name in [n for n in self.processes if n != "head"] + ["head"]:
            self.kill_node(name)
        for pid in marked_processes(f"{self.id}:"):  # any left (e.g. a node that failed to start)
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        shutil.rmtree(self.temp, ignore_errors=True)

"""The behaviour-cloning data of the multi-task policy: rollouts of the task policies.

Each of the 18 training tasks (red, green and yellow only: blue is held out for the test
tasks) has its own policy trained with the zsrm reward (``zsrm multitask-policies``). Each is
rolled out for ``episodes`` seeded 100-step episodes on the scenes it was trained in (seen
start-state spread; a task scene shows the task's two blocks only), and every decision is
kept: the frame the policy saw (its camera, at its render size), the action it took, the goal
sentence and the task's index. A task policy trained in choice scenes (``--choice``: a third
block beside the moved one, so the base is found by colour) is rolled out in them, and its
shard says so (``choice``). One shard per task in a :class:`~zsrm.data.shards.ShardFolder`,
so a killed collection resumes at the first unfinished task. With action repeat 2 an episode
is 50 decisions covering 100 control steps (the paper's 5,000 steps per task = 2,500 frames).

The manifest also keeps each task policy's oracle episode rewards over these episodes (their
mean is the ceiling of Table 2, ``oracle_task_policies``) and the objects its scenes held
(``objects``: the colours, a choice scene's third block included).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from stable_baselines3.common.vec_env import VecEnvWrapper

from zsrm.data.shards import ShardFolder, load_npz, read_manifest, save_npz
from zsrm.envs.rollout import run_vec_episodes
from zsrm.tasks.catalogue import TRAIN_TASKS
from zsrm.tasks.language import parse_goal

KIND = "multitask-rollouts"
COLLECT_SEED = 2_000_000  # collection envs: seeds apart from training (seed * 10,000) and evaluation envs'


def train_task_index(goal: str) -> int:
    """The index in ``TRAIN_TASKS`` (the primitive code of the full data) of a training goal; a
    ValueError for anything else (a test task: blue never enters the distillation data)."""
    task = parse_goal(goal)
    if task not in TRAIN_TASKS:
        raise ValueError(f"{task.text!r} is not one of the 18 training tasks (on top of, left of, right of over "
                         "red, green and yellow; blue is held out for the test tasks)")
    return TRAIN_TASKS.index(task)


def policy_folder(root: str | Path, goal: str, seed: int = 0) -> Path:
    """Where ``zsrm multitask-policies`` (a zsrm-reward sweep) leaves the policy of ``goal``."""
    from zsrm.rl.sweep import trial_name

    return Path(root) / trial_name(goal, "zsrm", seed) / "policy"


def keep_task_policies(root: str | Path, keep: str | Path, trials) -> list[Path]:
    """Copy the policy of each of a zsrm sweep's ``trials`` (name and config) that finished with
    the trial's settings from ``root`` to ``keep`` (same layout, under 1 MB a policy): the folder
    a results directory keeps under version control, so the rollouts need not retrain what a
    finished sweep skips. Returns the policies of ``trials`` kept there, copied now or before."""
    import shutil

    from zsrm.common.files import atomic_path
    from zsrm.rl.sweep import is_finished

    kept = []
    for trial in trials:
        src, dest = Path(root) / trial["name"] / "policy", Path(keep) / trial["name"] / "policy"
        if not is_finished(dest / "config.json", trial["config"]):
            if not is_finished(src.parent, trial["config"]):
                continue
            # config.json last: it marks a complete copy for the check above
            for f in sorted((p for p in src.iterdir() if p.is_file()), key=lambda p: p.name == "config.json"):
                with atomic_path(dest / f.name) as tmp:
                    shutil.copyfile(f, tmp)
        kept.append(dest)
    return kept


def teacher_folders(rollouts, teachers: str | Path | None = None) -> list[str]:
    """Each goal's task policy (in ``rollouts.goals`` order): the folder its rollouts were collected
    with, or ``teachers``' (a folder of kept task policies, as ``zsrm multitask-policies`` keeps them)."""
    if teachers is not None:
        folders = [str(policy_folder(teachers, goal)) for goal in rollouts.goals]
    else:
        config = rollouts.manifest["config"]
        by_goal = {parse_goal(t).text: p for t, p in zip(config["tasks"], config["policies"])}
        folders = [by_goal[goal] for goal in rollouts.goals]
    missing = [f for f in folders if not Path(f, "config.json").is_file()]
    if missing:
        raise FileNotFoundError(f"no task policy in {missing[0]} ({len(missing)} of {len(folders)} missing): "
                                "DAgger labels with the task policies and --mirror-teachers compares them; "
                                "pass --teachers (e.g. results/multitask/task_policies)")
    return folders


@dataclass
class RolloutConfig:
    """Which rollouts to collect (saved in the manifest: a folder resumes only with the same)."""

    tasks: tuple[str, ...]  # the training tasks' goal sentences, in TRAIN_TASKS order
    policies: tuple[str, ...]  # each task's policy folder
    episodes: int = 50  # seeded episodes per task
    envs: int = 10  # episodes stepped together

    def __post_init__(self):
        if len(self.tasks) != len(self.policies):
            raise ValueError(f"{len(self.tasks)} tasks but {len(self.policies)} policy folders")
        if self.episodes < 1 or self.envs < 1:
            raise ValueError(f"episodes and envs must be >= 1, got {self.episodes} and {self.envs}")


class DecisionRecorder(VecEnvWrapper):
    """Keeps every decision of a vectorised episode: the camera's frames at its own size (the
    policy may see them shrunk), its actions and the dones, so each env's episode can be cut
    where it ended. Wrap the camera's VecEnv, inside the policy's view."""

    def __init__(self, venv, camera: str):
        super().__init__(venv)
        self.camera = camera
        self.frames, self.actions, self.dones, self.last = [], [], [], None

    def reset(self):
        obs = self.venv.reset()
        self.last = obs[self.camera]
        return obs

    def step_async(self, actions):
        self.frames.append(np.array(self.last))
        self.actions.append(np.array(actions, dtype=np.float32))
        self.venv.step_async(actions)

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        self.dones.append(np.array(dones))
        self.last = obs[self.camera]
        return obs, rewards, dones, infos

    def episodes(self) -> list[dict]:
        """Per env: frames (T, H, W, 3) uint8 and actions (T, A) of its first episode."""
        dones = np.stack(self.dones)  # (T, N)
        out = []
        for e in range(dones.shape[1]):
            end = int(np.argmax(dones[:, e])) + 1 if dones[:, e].any() else len(dones)
            out.append({"frames": np.stack([f[e] for f in self.frames[:end]]),
                        "actions": np.stack([a[e] for a in self.actions[:end]])})
        return out


def collect_task(policy: str | Path, goal: str, episodes: int, envs: int) -> tuple[dict, dict]:
    """The decisions of ``episodes`` seeded episodes of one task policy, as shard arrays, and
    the shard's manifest entry (the oracle episode rewards, the camera, the action repeat)."""
    import torch

    from zsrm.rl.envs import make_vec
    from zsrm.rl.features import policy_view
    from zsrm.rl.goals import goal_camera
    from zsrm.rl.policy import PolicyBundle
    from zsrm.vlm import load_vlm

    index = train_task_index(goal)
    bundle = PolicyBundle.load(policy)
    if parse_goal(bundle.cfg.goal) != TRAIN_TASKS[index]:
        raise ValueError(f"{policy} was trained for {bundle.cfg.goal!r}, not {goal!r}")
    if bundle.cfg.reward != "zsrm":
        raise ValueError(f"{policy} was trained with the {bundle.cfg.reward} reward; the multi-task data "
                         "comes from zsrm-trained policies")
    vlm, rewards, parts, objects = load_vlm(bundle.cfg.vlm), [], [], set()
    for start in range(0, episodes, envs):
        n, seed = min(envs, episodes - start), COLLECT_SEED + 1000 * index + start
        torch.manual_seed(seed)  # the policy samples its actions: same seed, same data
        recorder = DecisionRecorder(make_vec(bundle.cfg, n, seed), goal_camera(goal))
        objects.update(*recorder.get_attr("objects"))  # every object in the scenes, distractors too
        venv = policy_view(recorder, vlm, bundle.cfg)
        try:
            result = run_vec_episodes(venv, lambda obs: bundle.act(obs, deterministic=bundle.cfg.eval_deterministic))
        finally:
            venv.close()
        rewards += result["episode_rewards"]
        parts += recorder.episodes()
    arrays = {"frames": np.concatenate([p["frames"] for p in parts]),
              "actions": np.concatenate([p["actions"] for p in parts]),
              "episode": np.concatenate([np.full(len(p["actions"]), i, np.int32) for i, p in enumerate(parts)]),
              "step": np.concatenate([np.arange(len(p["actions"]), dtype=np.int32) for p in parts])}
    arrays["task"] = np.full(len(arrays["actions"]), index, np.int16)
    arrays["goal"] = np.array([TRAIN_TASKS[index].text])
    info = {"goal": TRAIN_TASKS[index].text, "task": index, "decisions": len(arrays["task"]),
            "episode_rewards": rewards, "camera": goal_camera(goal), "action_repeat": bundle.cfg.action_repeat,
            "objects": sorted(objects), **({"choice": True} if bundle.cfg.choice else {})}
    return arrays, info


def collect_rollouts(cfg: RolloutConfig, folder: str | Path, progress: bool = True) -> "RolloutData":
    """Collect (or finish collecting) one shard per task into ``folder``."""
    from tqdm import tqdm

    for goal in cfg.tasks:
        train_task_index(goal)  # refuse a test task before any work
    shards = ShardFolder(folder, kind=KIND, config=asdict(cfg), n_shards=len(cfg.tasks))
    for i in tqdm(shards.pending(), desc="rollouts", unit="task", disable=not progress):
        arrays, info = collect_task(cfg.policies[i], cfg.tasks[i], cfg.episodes, cfg.envs)
        save_npz(shards.path(i, ".npz"), **arrays)
        shards.finish(i, info)
    return RolloutData(folder)


class RolloutData:
    """A folder written by :func:`collect_rollouts`."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self.manifest = read_manifest(self.folder)
        if self.manifest["kind"] != KIND:
            raise ValueError(f"{self.folder} holds a {self.manifest['kind']} folder, not multi-task rollouts "
                             "(zsrm multitask-rollouts)")
        if not self.manifest["complete"]:
            raise ValueError(f"{self.folder} is not complete: rerun zsrm multitask-rollouts to finish it")
        self.infos = [self.manifest["shards"][name] for name in sorted(self.manifest["shards"])]

    @property
    def goals(self) -> list[str]:
        """The tasks' goal sentences, in TRAIN_TASKS order (primitive code i is goals[i])."""
        return [info["goal"] for info in self.infos]

    def setting(self, key: str):
        """A setting every task's rollouts share (``camera``, ``action_repeat``)."""
        values = {info[key] for info in self.infos}
        if len(values) != 1:
            raise ValueError(f"{self.folder}: the task policies differ in {key} ({sorted(values)})")
        return values.pop()

    @property
    def choice_goals(self) -> list[str]:
        """The tasks rolled out in choice scenes (their policies trained with ``--choice``)."""
        return [info["goal"] for info in self.infos if info.get("choice")]

    @property
    def episode_rewards(self) -> list[float]:
        """The task policies' oracle episode rewards over the collected episodes, all tasks."""
        return [r for info in self.infos for r in info["episode_rewards"]]

    def load(self) -> dict[str, np.ndarray]:
        """All shards concatenated: frames (N, H, W, 3) uint8, actions (N, A), task (N,) index
        into TRAIN_TASKS, episode, step; goal (T,) the goal sentences, one per shard."""
        parts = [load_npz(self.folder / f"{name}.npz") for name in sorted(self.manifest["shards"])]
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

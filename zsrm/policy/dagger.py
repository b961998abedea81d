"""zsrm's distillation method, not the paper's: DAgger-style relabelling (Ross et al., 2011).

Behaviour cloning fits the frames the task policies visited; a distilled policy drifts into
frames they never showed and has learnt nothing there. After behaviour cloning, each round:

1. rolls the student (the distilled policy) out on every training task's scenes (seeded,
   ``episodes`` per task; the scenes its task policy was rolled out in);
2. labels each frame the student saw with its task policy's action on that frame (the
   teacher's deterministic action, the frame seen as the teacher sees it);
3. adds those frames to the rollouts and the earlier rounds' frames, and trains the student on
   the whole for ``epochs`` more epochs.

The teachers are the task policies the rollouts were collected with (the manifest names them),
so only training tasks, and no blue, enter the data. Each round is a folder
``OUT/dagger/<policy>/round_<r>/``: the policy after the round (safetensors + JSON, with the
round's record) and ``relabelled.npz`` (its frames, the teachers' actions, each frame's task); a
killed run resumes at its first unfinished round.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch

from zsrm.common.files import read_json
from zsrm.data.shards import load_npz, save_npz
from zsrm.envs.rollout import run_vec_episodes
from zsrm.policy.mirror import mirror_actions
from zsrm.policy.models import DistilledPolicy, embed_goals, load_policy, save_policy
from zsrm.policy.rollouts import DecisionRecorder, teacher_folders, train_task_index
from zsrm.policy.training import CloningData, DistillConfig, run_epoch
from zsrm.tasks.language import parse_goal

DAGGER_SEED = 4_000_000  # student rollouts: seeds apart from training, collection (2M) and evaluation (3M) envs'


@dataclass
class DaggerConfig:
    rounds: int = 1  # rounds of student rollouts, relabelling and training
    episodes: int = 10  # the student's seeded episodes per training task per round
    epochs: int = 2  # epochs over the aggregated data per round
    envs: int = 10  # episodes stepped together

    def __post_init__(self):
        if min(self.rounds, self.episodes, self.epochs, self.envs) < 1:
            raise ValueError("dagger rounds, episodes, epochs and envs must be >= 1")


class Dagger:
    """The DAgger rounds of every policy of a ``zsrm distill`` run, as
    :func:`zsrm.policy.training.distill` calls them after behaviour cloning; ``teachers``: the task
    policies' folder (default: those the rollouts were collected with)."""

    def __init__(self, config: DaggerConfig, teachers: str | Path | None = None):
        self.config, self.teachers = config, teachers

    def __call__(self, cfg: DistillConfig, data: CloningData, vlm, rollouts, out: Path, progress: bool,
                 fresh: bool) -> dict[str, list[dict]]:
        folders = teacher_folders(rollouts, self.teachers)
        teaching = data.teaching or range(len(data.goals))  # --mirror-teachers: a task may be taught by its mirror's
        tutors = [Teacher(folders[i], goal) if j == i else MirroredTeacher(folders[i], goal, folders[j])
                  for i, (goal, j) in enumerate(zip(data.goals, teaching))]
        return {name: dagger_policy(cfg, self.config, name, data, vlm, tutors, Path(out), progress, fresh)
                for name in cfg.policies}

    def settings(self) -> dict:
        """What distill.json records of the method (the envs stepped together change nothing)."""
        return {k: v for k, v in asdict(self.config).items() if k != "envs"}


class Teacher:
    """A task policy labelling camera frames with its action, the frames seen as it sees them."""

    def __init__(self, folder: str | Path, goal: str):
        from zsrm.rl.policy import PolicyBundle
        from zsrm.vlm import load_vlm

        self.bundle = PolicyBundle.load(folder)
        if parse_goal(self.bundle.cfg.goal).text != goal:
            raise ValueError(f"{folder} was trained for {self.bundle.cfg.goal!r}, not {goal!r}")
        self.vlm = load_vlm(self.bundle.cfg.vlm)

    def scenes(self, n: int, seed: int):
        """``n`` seeded scenes of its task, as it was trained and rolled out in (choice scenes too)."""
        from zsrm.rl.envs import make_vec

        return make_vec(self.bundle.cfg, n, seed)

    def actions(self, frames: np.ndarray, batch: int = 256) -> np.ndarray:
        """Its deterministic action on each camera frame (N, H, W, 3) uint8."""
        from zsrm.rl.features import policy_view

        venv = self.scenes(1, 0)
        try:  # the view converts frames as the teacher's env wrapper did in training
            view = policy_view(venv, self.vlm, self.bundle.cfg)
            return np.concatenate([self.bundle.act(view.convert(frames[i:i + batch]), deterministic=True)
                                   for i in range(0, len(frames), batch)]).astype(np.float32)
        finally:
            venv.close()


class MirroredTeacher(Teacher):
    """Labels the frames of a task's scenes with the mirror task's policy: its action on each frame
    flipped left to right, x negated (``zsrm distill --mirror-teachers``, :mod:`zsrm.policy.mirror`)."""

    def __init__(self, folder: str | Path, goal: str, mirror_folder: str | Path):
        super().__init__(folder, goal)  # the task's own scenes
        self.mirror = Teacher(mirror_folder, parse_goal(goal).mirrored().text)

    def actions(self, frames: np.ndarray, batch: int = 256) -> np.ndarray:
        return mirror_actions(self.mirror.actions(np.ascontiguousarray(frames[:, :, ::-1]), batch))


def relabel_task(student: DistilledPolicy, embedding: torch.Tensor, teacher: Teacher, episodes: int, envs: int,
                 seed: int) -> dict:
    """The student's ``episodes`` seeded episodes on the teacher's task: every frame it decided on,
    the teacher's action on it, the student's oracle episode rewards and the scenes' objects."""
    camera = student.cfg.camera
    frames, rewards, objects = [], [], set()
    for start in range(0, episodes, envs):
        n = min(envs, episodes - start)
        recorder = DecisionRecorder(teacher.scenes(n, seed + start), camera)
        objects.update(*recorder.get_attr("objects"))
        condition = embedding.expand(n, -1)
        try:
            result = run_vec_episodes(recorder, lambda obs: student.act(obs[camera], condition).numpy())
        finally:
            recorder.close()
        rewards += result["episode_rewards"]
        frames += [episode["frames"] for episode in recorder.episodes()]
    frames = np.concatenate(frames)
    return {"frames": frames, "actions": teacher.actions(frames), "rewards": rewards, "objects": sorted(objects)}


def aggregate(data: CloningData, parts: list[dict]) -> CloningData:
    """The rollouts with the relabelled frames of ``parts`` (frames, actions, codes) added."""
    if not parts:
        return data
    return replace(data, images=torch.cat([data.images, *(torch.from_numpy(p["frames"]).permute(0, 3, 1, 2)
                                                          for p in parts)]),
                   actions=torch.cat([data.actions, *(torch.from_numpy(p["actions"]).float() for p in parts)]),
                   codes=torch.cat([data.codes, *(torch.from_numpy(p["codes"]).long() for p in parts)]))


def dagger_policy(cfg: DistillConfig, dagger: DaggerConfig, name: str, data: CloningData, vlm,
                  teachers: list[Teacher], out: Path, progress: bool = True, fresh: bool = False) -> list[dict]:
    """``dagger.rounds`` rounds on the behaviour-cloned policy in ``out/<name>/``; each round's record."""
    from tqdm import tqdm

    policy = load_policy(out / name)
    base = read_json(out / name / "config.json")["training"]["config"]
    embeddings = embed_goals(vlm, data.goals, policy.cfg.text_embedding)
    parts, records = [], []
    bar = tqdm(total=dagger.rounds * len(teachers), unit="task", desc=f"dagger {name}", disable=not progress)
    for r in range(1, dagger.rounds + 1):
        folder = out / "dagger" / name / f"round_{r}"
        ident = json.loads(json.dumps({"behaviour_cloning": base, "round": r, **asdict(dagger)}))
        ident.pop("envs")
        ident.pop("rounds")  # more rounds go on from the finished ones
        done = (folder / "config.json").is_file() and (folder / "relabelled.npz").is_file() and not fresh
        if done and read_json(folder / "config.json").get("training", {}).get("config") == ident:
            policy, record = load_policy(folder), read_json(folder / "config.json")["training"]
            parts.append(load_npz(folder / "relabelled.npz"))
            records.append(record)
            bar.update(len(teachers))
            continue
        labelled = []
        for code, teacher in enumerate(teachers):
            seed = DAGGER_SEED + 1000 * train_task_index(data.goals[code]) + 100 * r
            task = relabel_task(policy, embeddings[code:code + 1], teacher, dagger.episodes, dagger.envs, seed)
            labelled.append({**task, "codes": np.full(len(task["actions"]), code, np.int64)})
            bar.update(1)
        part = {k: np.concatenate([t[k] for t in labelled]) for k in ("frames", "actions", "codes")}
        parts.append(part)
        # Each epoch's shuffle and crops by its own number, after behaviour cloning's.
        opt = torch.optim.Adam(policy.parameters(), lr=cfg.lr, amsgrad=True)
        whole = aggregate(data, parts)
        first = cfg.epochs + (r - 1) * dagger.epochs
        log = [{"epoch": first + k + 1, "loss": run_epoch(policy, opt, whole, cfg, first + k)}
               for k in range(dagger.epochs)]
        record = {"config": ident, "round": r, "frames": len(whole.actions), "relabelled": len(part["actions"]),
                  "student_reward": {t: float(np.mean(x["rewards"])) for t, x in zip(data.goals, labelled)},
                  "objects": sorted({o for x in labelled for o in x["objects"]}), "log": log,
                  "final_loss": log[-1]["loss"]}
        save_npz(folder / "relabelled.npz", **part)
        save_policy(policy, folder, record)  # config.json last: it marks the round finished
        records.append(record)
        bar.set_postfix(loss=f"{record['final_loss']:.4f}")
    bar.close()
    return records

"""``zsrm distill``: behaviour cloning of the three multi-task policies (paper 2.3, 3.3).

L2 loss on the task policies' continuous actions, Adam with AMSGrad at 1e-4, each frame
augmented by RandomResizedCrop (area 0.95-1.0, aspect 0.98-1.02) back to its own size. Two
schedules: ``paper`` (ResNet18, ImageNet weights when the user has them, 300 epochs) and
``cpu`` (the scene VLM's image trunk at the policies' render size, pretrained on renders of
all four colours in the role ImageNet plays in the paper, 10 epochs). Each policy is written
to ``OUT/<conditioning>/`` (safetensors + JSON) with its per-epoch losses; a checkpoint after
each epoch lets a killed run resume, a finished policy is skipped, and a larger ``--epochs``
goes on from where a finished run stopped.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch
import torch.nn.functional as F

from zsrm.common.checkpoints import load_optimizer, read_checkpoint_state, save_checkpoint
from zsrm.common.files import read_json, write_json
from zsrm.common.registry import load_weights
from zsrm.policy.models import (CONDITIONINGS, IMAGE_VIEWS, KEYPOINT_VIEWS, DistilledPolicy, PolicyConfig,
                                embed_goals, load_policy, save_policy)
from zsrm.policy.mirror import mirror_batch, taught_by, teaching_tasks
from zsrm.policy.rollouts import RolloutData, teacher_folders, train_task_index
from zsrm.tasks.language import parse_goal

# cpu reads grey frames: the scene VLM's trunk, pretrained on which colours are present, gives features
# so colour-bound that, read in colour, none of the paper's three follows a colour it never saw
# (results/side/multitask/table2_view_colour.json); the paper reads colour through ImageNet's ResNet18.
SCHEDULES = {"cpu": {"tower": "scene", "epochs": 10, "image_view": "grey", "centre_text": True},
             "paper": {"tower": "resnet18", "epochs": 300, "image_view": "colour", "centre_text": False}}


@dataclass
class DistillConfig:
    schedule: Literal["cpu", "paper"] = "cpu"
    """cpu: the scene VLM's image trunk on grey frames, 10 epochs; paper: ResNet18 on colour frames, 300 epochs"""
    tower: Literal["scene", "resnet18"] | None = None
    """image tower (default: the schedule's)"""
    epochs: int | None = None
    """epochs over the rollouts (default: the schedule's)"""
    policies: tuple[str, ...] = ("language", "primitive", "none")
    """which policies to train: the paper's three, and zsrm's grounded variant (zsrm.policy.models)"""
    pretrained: bool = True
    """start the tower from pretrained weights (scene: the VLM's trunk; resnet18: ImageNet)"""
    vlm: str = "scene"
    """the VLM whose text tower embeds the goals (and whose image trunk the scene tower starts from)"""
    text_embedding: Literal["language", "joint"] = "language"
    """goal embedding: the language encoder's own (as the paper feeds CLIP's) or the image-text space's"""
    keypoint_view: Literal["colour", "grey", "shape", "none"] = "none"
    """what the grounded policy's own keypoints look at: the frames, grey frames, grey frames with every
    coloured object one grey (through a trunk copy that trains), or nothing (results/side/multitask/table2_grounded*)"""
    centre_text: bool | None = None
    """language policy: centre and scale the goal embeddings by the training goals' (their sentence
    embeddings differ by a few hundredths per dimension, one-hot codes by 1); default: the schedule's
    (cpu centres them, results/multitask/table2_centred_seeds.json; paper feeds them raw, as the paper)"""
    image_view: Literal["colour", "grey", "shape"] | None = None
    """what the paper's three policies' image tower reads (default: the schedule's): the frames in colour
    (as the paper), in grey, or as shapes (grey, every coloured object one grey)"""
    mirror: bool = False
    """zsrm's, not the paper's: each frame, with probability 1/2, mirrored left to right (the frame flipped,
    the action's x negated, "left of" read as "right of"): the scenes and the front camera are
    mirror-symmetric, so each placing task teaches its mirror task too"""
    mirror_teachers: bool = False
    """zsrm's, not the paper's: each task taught by the better of its task policy and its mirror task's, as
    their training return under the zsrm reward says (the mirror's rollouts and DAgger labels mirrored)"""
    batch_size: int = 64
    """frames per step"""
    lr: float = 1e-4
    """Adam (AMSGrad) learning rate"""
    seed: int = 0
    """seed of the initialisation, the shuffling and the crops"""
    threads: int = 2
    """torch threads"""

    def __post_init__(self):
        if self.schedule not in SCHEDULES:
            raise ValueError(f"unknown schedule {self.schedule!r}; choose cpu or paper")
        self.tower = self.tower or SCHEDULES[self.schedule]["tower"]
        self.epochs = int(self.epochs or SCHEDULES[self.schedule]["epochs"])
        self.image_view = self.image_view or SCHEDULES[self.schedule]["image_view"]
        if self.centre_text is None:
            self.centre_text = SCHEDULES[self.schedule]["centre_text"]
        unknown = set(self.policies) - set(CONDITIONINGS)
        if unknown or not self.policies:
            raise ValueError(f"policies must be of {', '.join(CONDITIONINGS)}; got {', '.join(self.policies)}")
        if self.keypoint_view not in KEYPOINT_VIEWS:
            raise ValueError(f"unknown keypoint view {self.keypoint_view!r}; choose one of {', '.join(KEYPOINT_VIEWS)}")
        if self.image_view not in IMAGE_VIEWS:
            raise ValueError(f"unknown image view {self.image_view!r}; choose one of {', '.join(IMAGE_VIEWS)}")
        if self.text_embedding == "grounded":
            raise ValueError("--text-embedding is the language policy's: language or joint (the grounded "
                             "policy always reads grounded embeddings)")
        if "grounded" in self.policies and (self.tower != "scene" or not self.pretrained):
            raise ValueError("the grounded policy finds objects with the pretrained scene VLM: --tower scene, "
                             "--pretrained")
        if min(self.epochs, self.batch_size, self.threads) < 1:
            raise ValueError("epochs, batch_size and threads must be >= 1")


def random_crops(images: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
    """RandomResizedCrop (area 0.95-1.0, aspect 0.98-1.02) of each frame, back to its size."""
    from zsrm.vlm.compat import import_torchvision

    import_torchvision()
    from torchvision.transforms.v2 import functional as TF

    n, _, h, w = images.shape
    area = h * w * (0.95 + 0.05 * torch.rand(n, generator=generator))
    ratio = torch.exp(np.log(0.98) + (np.log(1.02) - np.log(0.98)) * torch.rand(n, generator=generator))
    ch = torch.sqrt(area / ratio).round().clamp(1, h).long()
    cw = torch.sqrt(area * ratio).round().clamp(1, w).long()
    out = []
    for i in range(n):
        top = int(torch.randint(0, h - int(ch[i]) + 1, (1,), generator=generator))
        left = int(torch.randint(0, w - int(cw[i]) + 1, (1,), generator=generator))
        out.append(TF.resized_crop(images[i], top, left, int(ch[i]), int(cw[i]), [h, w], antialias=True))
    return torch.stack(out)


@dataclass
class CloningData:
    """The rollouts as tensors: frames (N, 3, H, W) uint8, actions (N, A), each frame's primitive
    code (its task's position in ``goals``) and the goals' embeddings (T, D) of each kind the
    policies read (``embeddings[kind]``, see :func:`~zsrm.policy.models.embed_goals`)."""

    images: torch.Tensor
    actions: torch.Tensor
    codes: torch.Tensor
    goals: list[str]
    embeddings: dict[str, torch.Tensor]
    camera: str
    action_repeat: int
    teaching: tuple[int, ...] | None = None  # --mirror-teachers: each task's teaching task (zsrm.policy.mirror)

    def condition(self, cfg: PolicyConfig, codes: torch.Tensor) -> torch.Tensor | None:
        """What a policy of ``cfg`` reads of the goals of ``codes``."""
        if cfg.conditioning in ("language", "grounded"):
            return self.embeddings[cfg.text_embedding][codes]
        return codes if cfg.conditioning == "primitive" else None

    def mirror_codes(self) -> torch.Tensor:
        """Each goal's mirror goal's code (:meth:`~zsrm.tasks.language.Task.mirrored`); a ValueError when
        the data lacks one, or its camera's image is not the scene's left-right mirror."""
        if self.camera != "front":
            raise ValueError(f"mirroring flips front-camera frames; these rollouts are the {self.camera} camera's")
        texts = [parse_goal(goal).mirrored().text for goal in self.goals]
        missing = sorted(set(texts) - set(self.goals))
        if missing:
            raise ValueError(f"mirroring needs each goal's mirror goal in the rollouts; {missing[0]!r} is not")
        return torch.tensor([self.goals.index(t) for t in texts])


def embedding_kind(cfg: DistillConfig, conditioning: str) -> str:
    return "grounded" if conditioning == "grounded" else cfg.text_embedding


def cloning_data(data: RolloutData, vlm, kinds) -> CloningData:
    """The rollouts as :class:`CloningData`; a ValueError for a goal that is not a training task's
    (a test task's blue words and frames never enter the distillation data)."""
    for goal in data.goals:
        train_task_index(goal)
    arrays = data.load()
    lookup = np.full(int(arrays["task"].max()) + 1, -1, np.int64)
    lookup[[int(info["task"]) for info in data.infos]] = np.arange(len(data.infos))
    return CloningData(images=torch.from_numpy(arrays["frames"]).permute(0, 3, 1, 2).contiguous(),
                       actions=torch.from_numpy(arrays["actions"]).float(),
                       codes=torch.from_numpy(lookup[arrays["task"]]), goals=data.goals,
                       embeddings={kind: embed_goals(vlm, data.goals, kind) for kind in sorted(set(kinds))},
                       camera=data.setting("camera"), action_repeat=int(data.setting("action_repeat")))


def build_policy(cfg: DistillConfig, conditioning: str, data: CloningData, vlm) -> DistilledPolicy:
    """A fresh policy for the rollouts, its tower started as ``cfg`` says."""
    if cfg.tower == "scene" and not hasattr(vlm, "visual"):
        raise ValueError(f"--tower scene starts from a scene VLM's image trunk; {cfg.vlm!r} is not one")
    kind = embedding_kind(cfg, conditioning)
    pcfg = PolicyConfig(conditioning=conditioning, tower=cfg.tower, image_size=int(data.images.shape[-1]),
                        action_dim=int(data.actions.shape[1]), text_dim=int(data.embeddings[kind].shape[1]),
                        goals=tuple(data.goals), scene=vlm.config if cfg.tower == "scene" else None, vlm=cfg.vlm,
                        text_embedding=kind, camera=data.camera, action_repeat=data.action_repeat,
                        keypoint_view=cfg.keypoint_view if conditioning == "grounded" else cfg.image_view,
                        centre_text=centres_text(cfg, conditioning, data.goals))
    torch.manual_seed(cfg.seed)
    policy = DistilledPolicy(pcfg, pretrained=cfg.pretrained and cfg.tower == "resnet18")
    if cfg.tower == "scene" and cfg.pretrained:
        policy.load_scene_vlm(vlm)
    policy.goal_embeddings.copy_(data.embeddings[kind])
    return policy


def run_epoch(policy: DistilledPolicy, opt, data: CloningData, cfg: DistillConfig, epoch: int) -> float:
    """One pass over the shuffled frames; the mean L2 (MSE) loss."""
    generator = torch.Generator().manual_seed(cfg.seed * 100_003 + epoch)
    n = len(data.actions)
    order, total = torch.randperm(n, generator=generator), 0.0
    mirrors = data.mirror_codes() if cfg.mirror else None
    policy.train()
    for start in range(0, n, cfg.batch_size):
        index = order[start:start + cfg.batch_size]
        images, actions, codes = data.images[index], data.actions[index], data.codes[index]
        if mirrors is not None:
            images, actions, codes = mirror_batch(images, actions, codes, mirrors, generator)
        pred = policy(random_crops(images, generator), data.condition(policy.cfg, codes))
        loss = F.mse_loss(pred, actions)
        opt.zero_grad()
        loss.backward()
        opt.step()
        total += loss.item() * len(index)
    policy.eval()
    return total / n


def centres_text(cfg: DistillConfig, conditioning: str, goals) -> bool:
    """Whether this policy centres its goal embeddings: only the language policy does, and only
    over two goals or more (one goal has no spread to scale by)."""
    return bool(cfg.centre_text) and conditioning == "language" and len(goals) > 1


def identity(cfg: DistillConfig, conditioning: str, data: CloningData) -> dict:
    """The settings that define one policy's training (a checkpoint resumes only under them)."""
    d = {**asdict(cfg), "conditioning": conditioning, "frames": len(data.actions), "goals": data.goals}
    for k in ("policies", "threads"):
        d.pop(k)
    if conditioning != "grounded":  # only the grounded policy reads it
        d.pop("keypoint_view")
    if conditioning == "grounded" or cfg.image_view == "colour":  # as before image_view existed
        d.pop("image_view")
    if not centres_text(cfg, conditioning, data.goals):  # as before centre_text existed
        d.pop("centre_text")
    for key in ("mirror", "mirror_teachers"):
        if not d[key]:  # as before they existed
            d.pop(key)
    return json.loads(json.dumps(d))


def extendable(ckpt: Path, ident: dict) -> dict:
    """``ident`` with the checkpoint's epoch count when that is all that differs: a run goes on to
    more epochs, as if it had asked for them at the start (epoch k's shuffle and crops depend on k
    alone and the learning rate is constant)."""
    saved = read_json(ckpt / "state.json", "a checkpoint's state").get("config")
    if isinstance(saved, dict) and "epochs" in saved and {**saved, "epochs": ident["epochs"]} == ident:
        return {**ident, "epochs": saved["epochs"]}
    return ident


def train_policy(cfg: DistillConfig, conditioning: str, data: CloningData, vlm, folder: Path,
                 progress: bool = True, fresh: bool = False) -> dict:
    """Train (or resume, or skip when finished) one policy into ``folder``; its training record."""
    from tqdm import tqdm

    ident = identity(cfg, conditioning, data)
    if not fresh and (folder / "config.json").is_file():
        training = read_json(folder / "config.json").get("training", {})
        if training.get("config") == ident:
            return training
    policy = build_policy(cfg, conditioning, data, vlm)
    opt = torch.optim.Adam(policy.parameters(), lr=cfg.lr, amsgrad=True)
    ckpt, start, log = folder / "checkpoint", 0, []
    if not fresh and (ckpt / "state.json").is_file():
        state = read_checkpoint_state(ckpt, extendable(ckpt, ident), {"epoch": int, "log": list})
        if state["epoch"] > cfg.epochs:
            raise ValueError(f"the checkpoint in {ckpt} has {state['epoch']} epochs, more than --epochs "
                             f"{cfg.epochs}; pass --fresh to start over or use another --out")
        load_weights(policy, ckpt)
        load_optimizer(ckpt, opt)
        start, log = state["epoch"], state["log"]
    with tqdm(total=cfg.epochs, initial=start, unit="epoch", desc=f"distill {conditioning}",
              disable=not progress) as bar:
        for epoch in range(start, cfg.epochs):
            log.append({"epoch": epoch + 1, "loss": run_epoch(policy, opt, data, cfg, epoch)})
            save_checkpoint(ckpt, lambda tmp: save_policy(policy, tmp), opt,
                            {"config": ident, "epoch": epoch + 1, "log": log})
            bar.update(1)
            bar.set_postfix(loss=f"{log[-1]['loss']:.4f}")
    training = {"config": ident, "log": log, "final_loss": log[-1]["loss"] if log else None}
    save_policy(policy, folder, training)
    return training


def distill(cfg: DistillConfig, data_folder: str | Path, out: str | Path, progress: bool = True,
            fresh: bool = False, dagger=None) -> dict:
    """Behaviour cloning of ``cfg.policies`` on the rollouts in ``data_folder``, each into
    ``out/<conditioning>/``; writes and returns ``out/distill.json``. ``dagger`` (a
    :class:`~zsrm.policy.dagger.Dagger`, passed in: it imports this module): zsrm's method, rounds
    of DAgger-style relabelling after that by the task policies, and distill.json names each
    policy's last round."""
    from zsrm.vlm import load_vlm

    torch.set_num_threads(cfg.threads)
    vlm = load_vlm(cfg.vlm)
    rollouts = RolloutData(data_folder)
    data = cloning_data(rollouts, vlm, [embedding_kind(cfg, name) for name in cfg.policies])
    if cfg.mirror or cfg.mirror_teachers:
        mirrors = data.mirror_codes()  # refuse rollouts it cannot mirror before any work
    if cfg.mirror_teachers:
        data = taught_by(data, teaching_tasks(mirrors.tolist(), teacher_folders(rollouts)))
    policies = {name: train_policy(cfg, name, data, vlm, Path(out) / name, progress, fresh)
                for name in cfg.policies}
    rounds = dagger(cfg, data, vlm, rollouts, Path(out), progress, fresh) if dagger is not None else {}
    summary = {"schedule": cfg.schedule, "tower": cfg.tower, "pretrained": cfg.pretrained, "epochs": cfg.epochs,
               "vlm": cfg.vlm, "text_embedding": cfg.text_embedding, "seed": cfg.seed,
               **({"centre_text": True} if "language" in cfg.policies and centres_text(cfg, "language", data.goals) else {}),
               **({"keypoint_view": cfg.keypoint_view} if "grounded" in cfg.policies else {}),
               **({"mirror": True} if cfg.mirror else {}),
               **({"mirror_teachers": {g: data.goals[j] for g, j in zip(data.goals, data.teaching) if g != data.goals[j]}}
                  if cfg.mirror_teachers else {}),
               **({"image_view": cfg.image_view} if set(cfg.policies) - {"grounded"} else {}), "data": str(data_folder),
               "frames": len(data.actions), "goals": data.goals,
               "policies": {name: {"folder": name, "final_loss": t["final_loss"]}
                            for name, t in policies.items()}}
    if dagger is not None:
        summary["distillation"] = "dagger"
        summary["dagger"] = dagger.settings()
        for name, records in rounds.items():
            summary["policies"][name] = {
                "folder": f"dagger/{name}/round_{len(records)}", "final_loss": records[-1]["final_loss"],
                "behaviour_cloning": summary["policies"][name],
                "rounds": [{k: r[k] for k in ("round", "frames", "relabelled", "final_loss")}
                           | {"student_reward": float(np.mean(list(r["student_reward"].values())))}
                           for r in records]}
    write_json(Path(out) / "distill.json", summary)
    return summary


DAGGER_SUFFIX = "_dagger"  # a DAgger run's policy in a table, beside its behaviour cloning
MIRROR_SUFFIX = "_mirror"  # a policy distilled with --mirror, beside one without
MIRROR_TEACHERS_SUFFIX = "_mirror_teachers"  # one distilled with --mirror-teachers


def load_distilled(out: str | Path) -> tuple[dict, dict[str, DistilledPolicy]]:
    """``out/distill.json`` and the policies it lists. A DAgger run's policy is two: ``<name>`` (its
    behaviour cloning, the paper's method) and ``<name>_dagger`` (its last round, zsrm's). A run with
    ``--mirror`` names its policies ``<name>_mirror`` (and ``<name>_mirror_dagger``), one with
    ``--mirror-teachers`` ``<name>_mirror_teachers``; a run with both, ``<name>_mirror_mirror_teachers``."""
    summary = read_json(Path(out) / "distill.json", "the summary of zsrm distill")
    if not isinstance(summary.get("policies"), dict) or not summary["policies"]:
        raise ValueError(f"{Path(out) / 'distill.json'} lists no policies; rerun zsrm distill")
    policies = {}
    suffix = (MIRROR_SUFFIX if summary.get("mirror") else "") + \
        (MIRROR_TEACHERS_SUFFIX if "mirror_teachers" in summary else "")
    for name, entry in summary["policies"].items():
        entry = entry if isinstance(entry, dict) else {}
        if "rounds" in entry:  # zsrm.policy.dagger
            policies[name + suffix] = load_policy(Path(out) / entry["behaviour_cloning"].get("folder", name))
            policies[name + suffix + DAGGER_SUFFIX] = load_policy(Path(out) / entry["folder"])
        else:
            policies[name + suffix] = load_policy(Path(out) / entry.get("folder", name))
    return summary, policies


def runs_vlm(runs) -> str:
    """The VLM every one of several ``zsrm distill`` runs (:func:`load_distilled_runs`) read."""
    vlms = {summary["vlm"] for summary, _ in runs}
    if len(vlms) > 1:
        raise ValueError(f"the --policies folders read different VLMs ({sorted(vlms)})")
    return vlms.pop()


def load_distilled_runs(outs) -> list[tuple[dict, dict[str, DistilledPolicy]]]:
    """Several ``zsrm distill`` runs as one table's (:func:`load_distilled` of each), no policy name twice."""
    runs, names = [load_distilled(out) for out in outs], set()
    for out, (_, policies) in zip(outs, runs):
        if names & set(policies):
            raise ValueError(f"{out} has a policy named as one of an earlier folder's ({sorted(names & set(policies))}"
                             "); give a table one run per policy")
        names |= set(policies)
    return runs

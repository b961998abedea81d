"""``--zsrm-correct-every N``: the zsrm reward corrected by the labeler during training
(:class:`zsrm.rewards.corrected.CorrectedZSRMReward`).

The labeler is calibrated once per run on a few exploration renders kept in the run folder
(``goal_labeler/``); the reward model's latest state is kept beside it (``zsrm_online/``), where
a resumed run picks it up (the labelled frames start afresh, as VICE's do).
"""
from __future__ import annotations

from pathlib import Path

from zsrm.common.files import read_json, write_json
from zsrm.data.shards import load_npz, save_npz
from zsrm.fullmodel import load_reward_backbone
from zsrm.grounding.annotate import BOX_VLM, DEFAULT_VLM
from zsrm.grounding.goal_check import GoalLabeler
from zsrm.rewards.corrected import CorrectedZSRMReward
from zsrm.rl.config import TrainConfig
from zsrm.rl.goals import task_entry
from zsrm.tasks.catalogue import SCENE_IDS
from zsrm.tasks.lexicon import BOX
from zsrm.vlm import load_vlm


def labeler_scene(cfg: TrainConfig) -> str:
    """The zsrm scene (tabletop or pushing) of ``cfg.goal``'s task."""
    env_id = task_entry(cfg.goal).env_id
    return next(name for name, scene_id in SCENE_IDS.items() if scene_id == env_id)


def goal_labeler(cfg: TrainConfig, folder: str | Path) -> GoalLabeler:
    """The labeler of ``cfg.goal`` in its task scene, read through ``cfg.vlm`` (and the box-aware
    scene VLM for a goal with the box, as ``zsrm label`` reads the box), calibrated into ``folder``."""
    entry = task_entry(cfg.goal)
    scene = labeler_scene(cfg)
    box_vlm = load_vlm(BOX_VLM) if cfg.vlm == DEFAULT_VLM and BOX in entry.task.objects else None
    return GoalLabeler.calibrated(entry.task, scene, cfg.image_size, folder, load_vlm(cfg.vlm), vlm_spec=cfg.vlm,
                                  box_vlm=box_vlm, box_min_area=cfg.zsrm_correct_box_area,
                                  front_check=cfg.zsrm_correct_front, height_check=cfg.zsrm_correct_height,
                                  lift_max=cfg.zsrm_correct_lift_max)


def explored_labels(cfg: TrainConfig, labeler: GoalLabeler, folder: str | Path):
    """``cfg.zsrm_correct_explore`` exploration renders of the goal's scene (collected into ``folder``
    once), those holding the goal's objects, and the labeler's verdicts on them (kept beside them);
    None when the setting is 0. Which objects a render holds is what ``zsrm label`` reads too."""
    if not cfg.zsrm_correct_explore:
        return None
    folder = Path(folder)
    kept = folder / "labelled.npz"
    if kept.is_file():
        done = load_npz(kept)
        return done["frames"], done["holds"]
    from zsrm.data.collect import CollectConfig, collect
    from zsrm.tasks.language import COLOURS

    task, camera = labeler.task, labeler.camera
    data = collect(CollectConfig(images=cfg.zsrm_correct_explore, shard_size=min(cfg.zsrm_correct_explore, 256),
                                 scenes=(labeler_scene(cfg),), cameras=labeler.grounder.data.cameras,
                                 image_size=cfg.image_size,
                                 p_box=0.5 if task.has_container else 0.0), folder, progress=False).load()
    hold = data["present"][:, [COLOURS.index(c) for c in task.objects if c in COLOURS]].all(axis=1)
    if task.has_container:
        hold &= data["box_present"]
    frames = data[f"images_{camera}"][hold]
    holds = labeler(frames, **({"front": data["images_front"][hold]} if labeler.needs_front else {}))
    save_npz(kept, frames=frames, holds=holds)  # atomically: a killed run labels again, never reads half
    return frames, holds


def corrected_reward(cfg: TrainConfig, out: str | Path) -> CorrectedZSRMReward:
    """The zsrm reward of ``cfg`` whose model learns, every ``cfg.zsrm_correct_every`` env steps,
    from ``cfg.zsrm_correct_frames`` of the policy's frames labelled by ``cfg.vlm``'s Grad-CAM."""
    out = Path(out)
    labeler = goal_labeler(cfg, out / "goal_labeler")
    latest = out / "zsrm_online"
    model = load_reward_backbone(latest if (latest / "config.json").is_file() else cfg.reward_model)
    reward = CorrectedZSRMReward(model, labeler, update_every=max(1, cfg.zsrm_correct_every // cfg.action_repeat),
                                 label_frames=cfg.zsrm_correct_frames, seed=cfg.seed, output=cfg.zsrm_output,
                                 label_cameras=("front",) if labeler.needs_front else (),
                                 labelled=explored_labels(cfg, labeler, out / "goal_labeler_explore"))
    if (latest / "corrections.json").is_file():  # a resumed run counts on from what it had done
        done = read_json(latest / "corrections.json", "the corrected reward's counts")
        reward.updates, reward.labelled, reward.labelled_goal = done["updates"], done["labelled"], done["labelled_goal"]

    def keep(model) -> None:  # the latest model, and what the labeler said so far
        model.save(latest)
        write_json(latest / "corrections.json", {"updates": reward.updates, "labelled": reward.labelled,
                                                 "labelled_goal": reward.labelled_goal})

    reward.on_update = keep
    return reward

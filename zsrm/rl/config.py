"""Settings of one PPO run (``zsrm train``), written once as a dataclass (CleanRL's ``Args``).

Two presets: ``cpu`` fits the 300k-step budget of a 2-core machine; ``paper`` is the paper's
200k steps per task with more envs and bigger batches for a machine with more cores.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from typing import Literal

REWARDS = ("oracle", "zsrm", "base", "vice", "curiosity", "random")


@dataclass
class TrainConfig:
    goal: str = "stack"
    """goal sentence or catalogue task name (stack, place_right, push_close, ..., pendulum: the double
    inverted pendulum of Figure 4, with the base, oracle, curiosity or random reward)"""
    scene: str | None = None
    """your own scene (docs/own-scene.md): a SceneAdapter as module:Class or a registered id; the goal then
    names its objects by their phrases, and trains with the oracle, base, curiosity or random reward, or
    zsrm with --reward-model (a student trained on the scene's data: zsrm own-scene); default: zsrm's own
    scenes, chosen by the goal"""
    reward: Literal["oracle", "zsrm", "base", "vice", "curiosity", "random"] = "oracle"
    """reward the policy learns from: oracle (privileged), zsrm (the full reward model), base (the VLM's
    image-goal cosine; for the pendulum 1 when the goal beats the other poses' sentences), vice (privileged
    goal classifier), curiosity (ICM, no goal), random (no learning)"""
    seed: int = 0
    """seed of the policy, the training envs and the evaluation envs"""
    steps: int = 300_000
    """environment (control) steps to train for; an agent step covers `action_repeat` of them"""
    reward_model: str = "student"
    """for --reward zsrm: the model folder (zsrm finetune) or 'student', the shipped student
    (recorded as student@<version of its weights>)"""
    zsrm_output: Literal["binary", "margin"] = "binary"
    """for --reward zsrm: binary (the paper's), or margin (dense: goal score minus best negative)"""
    vlm: str = "scene"
    """VLM whose frozen image trunk (its Grad-CAM layer) the policy sees through, and that scores the
    base reward (for the pendulum, scene means scene-pendulum: the scene VLM taught the pole's pose)"""
    n_envs: int = 16
    """parallel training envs (one process, one batched reward call per step)"""
    action_repeat: int = 4
    """control steps per agent decision; only the last frame is rendered"""
    image_size: int = 64
    """camera image side in pixels (the reward model reads this frame)"""
    trunk_size: int = 32
    """side the frame is shrunk to before the policy's frozen VLM trunk (0: image_size); 32 px costs a
    quarter of 64 px and gives an 8x8 map"""
    pixel_size: int = 32
    """side of the frame the policy's pixel CNN reads (0: image_size)"""
    keypoints: int = 32
    """spatial-softmax keypoints the policy reads from the VLM feature map"""
    pixels: bool = True
    """also a small CNN on the raw frame, trained by RL (sees the gripper, which the VLM hardly does)"""
    pixel_stride: int = 4
    """the pixel CNN's stride: its keypoints' heat maps are the pixel view's side over this (2 or 4; at
    a 32 px view 4 gives 8x8 maps, a cell about 8 cm of the table)"""
    pair_scale: float = 0.0
    """also give the policy every pair of keypoints' difference (x_j - x_i, y_j - y_i) times this (the
    frame spans 2: 3 makes a unit about 10 cm of the table): on true state, PPO learnt push_close from
    such relative places; on pixels, 3 did not move it (docs/training.md); 0: off"""
    aux_inverse: bool = True
    """train the keypoints with a self-supervised inverse-dynamics loss too (they learn where the agent is)"""
    augment_shift: int = 0
    """after each rollout, pull the policy and value on the pixel view shifted by up to this many
    pixels towards theirs on the view itself (DrAC's regulariser, zsrm.rl.augment); 0: off"""
    learner: Literal["ppo", "sac"] = "ppo"
    """ppo: PPO on the policy view, its keypoints trained with it (zsrm.rl.ppo); sac: stable-baselines3's
    SAC on the frozen keypoints of a keypoint autoencoder pretrained on random actions' frames, whose
    env steps count in the run's (zsrm.rl.sac, zsrm.rl.pretrain; --config sac)"""
    pretrain_episodes: int = 320
    """--learner sac: episodes of random actions whose frames the keypoints are pretrained on"""
    pretrain_steps: int = 4000
    """--learner sac: Adam steps of the keypoint autoencoder"""
    n_steps: int = 32
    """PPO rollout length per env"""
    batch_size: int = 32
    """PPO minibatch size"""
    n_epochs: int = 4
    """PPO epochs per rollout"""
    learning_rate: float = 3e-4
    """Adam learning rate"""
    gamma: float = 0.96
    """discount per agent decision (0.96 at action repeat 4 is v1's 0.98 at action repeat 2: the
    same horizon in seconds)"""
    gae_lambda: float = 0.9
    """GAE lambda (per decision, like gamma: 0.9 at action repeat 4 is about 0.95 at 2)"""
    ent_coef: float = 0.0
    """entropy bonus"""
    clip_range: float = 0.2
    """PPO clip range"""
    log_std_init: float = -1.0
    """initial log standard deviation of the policy's Gaussian actions (stable-baselines3's
    log_std_init; -1: 0.37 over actions in [-1, 1], so early grasps and placements are not shaken
    loose by the noise; 0, a standard deviation of 1, until 2026-12-06: --config v2)"""
    target_kl: float = 0.0
    """stop an update's epochs at a minibatch whose KL from the rollout's policy passes 1.5x this
    (0: never; stable-baselines3's target_kl)"""
    anneal_lr: bool = True
    """decay the learning rate linearly to 0 over the run (CleanRL's anneal_lr): late updates take
    small steps, so a policy that has learned does not collapse in its last rollouts (--no-anneal-lr:
    a constant rate, as every run before 2026-12-04 had)"""
    eval_every: int = 20_000
    """environment steps between evaluations"""
    eval_episodes: int = 10
    """episodes per evaluation, on separate envs with their own seeds"""
    eval_deterministic: bool = True
    """evaluate the policy's mean action, as a deployed policy acts, instead of sampling it (sampled
    until 2026-12-06: --config v2; the grip's hysteresis makes an early mean action that never crosses
    a threshold score 0 while the sampled policy succeeds); a run's summary has both (final_by_actions)"""
    checkpoint_every: int = 20_000
    """environment steps between checkpoints a killed run resumes from"""
    threads: int = 1
    """torch threads"""
    start: Literal["auto", "above", "around"] = "auto"
    """tabletop tasks: the gripper starts open above the block the goal moves (above), or with its
    open fingers around it, so that closing them grasps it (around); auto: around for stacking
    goals (on top of, below), whose oracle reward stayed 0 for 300k steps from above, and for inside
    of (a block lifted into the box; from above 0 in 300k steps with zsrm), else above"""
    lift_ceiling: float = 0.0
    """tabletop tasks: the gripper's origin stays at most this many metres above the table (the held
    block's centre 0.056 below it; the workspace's top is 0.33); 0: no ceiling below the workspace's"""
    near_start: float = 0.0
    """push tasks: training episodes' pucks start between this many puck widths from the centre
    line and the scene's 1.7, drawn per episode (a curriculum of nearer starts); evaluation keeps
    1.7; 0: off"""
    zsrm_correct_every: int = 0
    """--reward zsrm: every this many env steps the labeler (the VLM's Grad-CAM + Table 1, as zsrm label)
    labels zsrm_correct_frames of the policy's latest frames and the reward model takes 50 Adam steps on
    them (zsrm.rewards.corrected): frames the policy reaches that only look like the goal stop paying;
    0: the reward model stays as loaded"""
    zsrm_correct_frames: int = 128
    """--reward zsrm with zsrm_correct_every: frames labelled per update"""
    zsrm_correct_box_area: float = 0.0
    """--reward zsrm with zsrm_correct_every, goals with the box: the labeler's box point whose
    silhouette covers less of the table than this (square metres; the box alone 0.013-0.016 on the
    tilted camera, a block 0.007-0.010) sat on a block and is dropped, so inside of does not hold
    there; 0: no check (the labeler as zsrm label's)"""
    zsrm_correct_front: bool = False
    """--reward zsrm with zsrm_correct_every, inside of the box: the training scenes render the front
    camera too, for the labeler alone, and inside of holds only where the block's Grad-CAM point there
    sits a little above the box's (zsrm.grounding.goal_check.FRONT_RISE); on the tilted camera a block
    held in the air in front of the box reads as one in it (the policy and the reward read the tilted
    camera alone)"""
    zsrm_correct_explore: int = 0
    """--reward zsrm with zsrm_correct_every: before training the labeler labels this many exploration
    renders of the goal's scene (zsrm collect's, cached in the run folder), and those that hold the
    goal's objects stay in its banks for good: the first update then need not wait for the policy to
    reach the goal, and a fooled reward is corrected from the first update on; 0: none"""
    zsrm_correct_height: bool = False
    """--reward zsrm with zsrm_correct_every, inside of the box: the training scenes render the front
    camera too, for the labeler alone, and inside of holds only where the block's centre, triangulated
    from its Grad-CAM points on the tilted and front cameras, is at most half a block width above a
    resting block's (zsrm.grounding.goal_check.LIFT_MAX): a block held in the air does not count"""
    zsrm_correct_lift_max: float = 0.5
    """--reward zsrm with zsrm_correct_height: the highest the block's centre may be, in block widths
    above a resting block's (0.67: a block held low in the box, its bottom under the walls' top, counts)"""
    vice_update_every: int = 4000
    """--reward vice: every this many env steps the goal classifier takes 50 Adam steps on the
    policy's latest frames beside the frames it was fitted on, as Fu et al. (2018) train VICE
    (zsrm.rewards.vice.OnlineVICEReward); 0: fitted once before training (the default until 2026-12-06)"""
    vice_oracle_labels: bool = True
    """--reward vice: the policy's frames are labelled by the oracle, as the frames the classifier was
    fitted on are (VICE-RAQ with every frame queried): those in the goal relation join the positives,
    the others the negatives; --no-vice-oracle-labels: all of them negatives, as VICE's (Fu et al.)"""
    choice: bool = False
    """stacking goals: the scene also holds a third block (the first training colour the goal does not
    name) in line with the goal's, on the far side of the moved block from its base, so the policy
    must find its base by colour (the multi-task policy's choice scenes); off: the goal's blocks only"""
    init: str = ""
    """a trained policy folder (zsrm train's policy/) to start from instead of random weights, with
    the same architecture (keypoints, pixels, action space); e.g. the goal's policy from the scenes
    without a choice. A run that resumes from its checkpoint ignores it"""
    layout_version: int = field(default=0, metadata={"cli": False})
    """how the goal's scene starts its episodes (0: the scene's current version); recorded, not chosen"""

    # Settings added after runs were committed: written only when changed, so that a finished
    # run made before they existed still matches its configuration.
    ADDED = {"start": "above", "layout_version": 1, "choice": False, "init": "", "trunk_size": 0, "pixel_size": 0,
             "target_kl": 0.0, "anneal_lr": False, "scene": None, "log_std_init": 0.0, "vice_update_every": 0,
             "vice_oracle_labels": False, "augment_shift": 0, "lift_ceiling": 0.0,
             "near_start": 0.0, "zsrm_correct_every": 0, "zsrm_correct_frames": 128,
             "zsrm_correct_box_area": 0.0, "zsrm_correct_front": False, "zsrm_correct_height": False, "zsrm_correct_explore": 0, "zsrm_correct_lift_max": 0.5, "pair_scale": 0.0, "pixel_stride": 4, "learner": "ppo",
             "pretrain_episodes": 320, "pretrain_steps": 4000}
    # What a file without the setting means, where that is not the default: a run made before the
    # setting existed (read by from_dict and by zsrm.common.registry.parse_fields, e.g. a saved policy)
    LEGACY_DEFAULTS = {"trunk_size": 0, "pixel_size": 0, "anneal_lr": False, "log_std_init": 0.0,
                       "eval_deterministic": False, "vice_update_every": 0, "vice_oracle_labels": False}

    def __post_init__(self):
        if self.reward not in REWARDS:
            raise ValueError(f"unknown reward {self.reward!r}; choose one of {', '.join(REWARDS)}")
        if self.zsrm_output not in ("binary", "margin"):
            raise ValueError(f"unknown zsrm output {self.zsrm_output!r}; choose binary or margin")
        for name in ("steps", "n_envs", "action_repeat", "n_steps", "batch_size", "n_epochs", "eval_every",
                     "eval_episodes", "checkpoint_every", "threads", "keypoints", "pretrain_episodes", "pretrain_steps"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.augment_shift < 0 or (self.augment_shift and not self.pixels):
            raise ValueError(f"augment_shift shifts the pixel view: >= 0, and 0 without pixels; got "
                             f"{self.augment_shift} with pixels={self.pixels}")
        if self.near_start:  # 0: off
            from zsrm.envs.pushing import check_near_start

            check_near_start(self.near_start)
        self.check_policy_settings()
        if self.lift_ceiling < 0:
            raise ValueError(f"lift_ceiling must be >= 0 (0: the workspace's top), got {self.lift_ceiling}")
        if min(self.zsrm_correct_every, self.zsrm_correct_box_area, self.zsrm_correct_explore) < 0 \
                or self.zsrm_correct_frames < 1:
            raise ValueError(f"zsrm_correct_every, zsrm_correct_box_area and zsrm_correct_explore must be >= 0 "
                             f"(0: off) and zsrm_correct_frames >= 1, got {self.zsrm_correct_every}, "
                             f"{self.zsrm_correct_box_area}, {self.zsrm_correct_explore} and {self.zsrm_correct_frames}")
        if self.vice_update_every < 0:
            raise ValueError(f"vice_update_every must be >= 0 (0: a fixed classifier), got {self.vice_update_every}")
        if self.target_kl < 0:
            raise ValueError(f"target_kl must be >= 0 (0: no early stop), got {self.target_kl}")
        if self.start not in ("auto", "above", "around"):
            raise ValueError(f"unknown start {self.start!r}; choose auto, above or around")
        if self.scene is not None:
            check_scene_run(self)
        relation = goal_relation(self.goal, self.scene)
        if self.choice and relation not in STACKING:
            raise ValueError(f"--choice is for stacking goals (on top of, below): it puts a second possible "
                             f"base beside the moved block; {self.goal!r} is not one")
        if self.start == "auto":
            self.start = "around" if relation in GRASPED else "above"
        if not self.scene and not takes_reward(self.goal, self.reward):
            raise ValueError(f"the {self.reward} reward reads a spatial relation; the pendulum trains with "
                             "base, oracle, curiosity or random")
        if relation is None and self.vlm == "scene":  # the scene VLM never saw the pole: its pose words are here
            self.vlm = PENDULUM_VLM
        if self.layout_version == 0 and not self.scene:  # a run of an older layout is another run
            from zsrm.envs import layout_version
            from zsrm.tasks.catalogue import resolve

            self.layout_version = layout_version(resolve(self.goal).env_id)
        if self.reward == "zsrm":  # record which shipped student: a retrained one is another run
            import zsrm.fullmodel  # noqa: F401  (registers the shipped student)
            from zsrm.vlm.factory import pinned

            self.reward_model = pinned(self.reward_model)
        else:  # only the zsrm reward reads it: any other run is the same run whatever it says
            self.reward_model = "student"
        self.drop_unread_settings()
        if 100 % self.action_repeat:
            raise ValueError(f"action_repeat must divide the 100-step episode, got {self.action_repeat}")

    def check_policy_settings(self) -> None:
        """The learner and the policy view's settings, one line each."""
        if self.learner not in ("ppo", "sac"):
            raise ValueError(f"unknown learner {self.learner!r}; choose ppo or sac")
        if self.learner == "sac" and not self.pixels:
            raise ValueError("--learner sac reads the keypoints of a pretrained pixel CNN: it needs --pixels")
        if self.learner == "sac" and (self.reward in ("curiosity", "vice") or self.zsrm_correct_every):
            raise ValueError(f"--learner sac trains with the oracle, zsrm, base or random reward; the {self.reward} "
                             f"reward{' corrected online' if self.zsrm_correct_every else ''} updates between PPO's "
                             "rollouts and has not been run with SAC")
        if self.pixel_stride not in (2, 4):
            raise ValueError(f"pixel_stride is 2 or 4, got {self.pixel_stride}")
        if self.pair_scale < 0:
            raise ValueError(f"pair_scale must be >= 0 (0: no keypoint pairs), got {self.pair_scale}")

    def drop_unread_settings(self) -> None:
        """Settings only one reward reads, back to their unwritten values for the others: a sweep
        shares them across rewards, and any other reward's run is the same run whatever they say."""
        if self.reward != "zsrm" or not self.zsrm_correct_every:  # only the zsrm reward is corrected
            self.zsrm_correct_every = self.ADDED["zsrm_correct_every"]
            self.zsrm_correct_frames = self.ADDED["zsrm_correct_frames"]
            self.zsrm_correct_box_area = self.ADDED["zsrm_correct_box_area"]
            self.zsrm_correct_front = self.ADDED["zsrm_correct_front"]
            self.zsrm_correct_height = self.ADDED["zsrm_correct_height"]
            self.zsrm_correct_explore = self.ADDED["zsrm_correct_explore"]
        if not goal_has_box(self.goal, self.scene):  # only the box is checked
            self.zsrm_correct_box_area = self.ADDED["zsrm_correct_box_area"]
            self.zsrm_correct_front = self.ADDED["zsrm_correct_front"]
            self.zsrm_correct_height = self.ADDED["zsrm_correct_height"]
        if not self.zsrm_correct_height:
            self.zsrm_correct_lift_max = self.ADDED["zsrm_correct_lift_max"]
        if self.reward == "random":  # uniform random actions: no policy network reads its inputs
            self.pair_scale = self.ADDED["pair_scale"]
            self.pixel_stride = self.ADDED["pixel_stride"]
            self.learner = self.ADDED["learner"]
        if self.learner != "sac":  # only SAC's keypoints are pretrained
            self.pretrain_episodes = self.ADDED["pretrain_episodes"]
            self.pretrain_steps = self.ADDED["pretrain_steps"]
        if self.reward != "vice":  # the same for VICE's classifier updates
            self.vice_update_every = self.ADDED["vice_update_every"]
            self.vice_oracle_labels = self.ADDED["vice_oracle_labels"]
        if not self.vice_update_every:  # a classifier fitted once learns nothing from the policy's frames
            self.vice_oracle_labels = self.ADDED["vice_oracle_labels"]

    @property
    def episode_decisions(self) -> int:
        """Agent steps per 100-step episode."""
        return 100 // self.action_repeat

    def identity(self) -> dict:
        """The settings that define the run (a checkpoint resumes only under the same ones)."""
        d = self.to_dict()
        for k in ("steps", "eval_every", "eval_deterministic", "checkpoint_every", "threads"):
            d.pop(k)
        return d

    def to_dict(self) -> dict:
        return {k: v for k, v in asdict(self).items() if not (k in self.ADDED and v == self.ADDED[k])}

    @classmethod
    def from_dict(cls, d: dict) -> "TrainConfig":
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown training settings: {', '.join(sorted(unknown))}")
        return cls(**{**cls.LEGACY_DEFAULTS, **d})


# The pendulum's VLM by default: the scene VLM taught the pole's pose in words (Figure 4).
PENDULUM_VLM = "scene-pendulum"


def takes_reward(goal: str, reward: str) -> bool:
    """Can a run of ``goal`` train with ``reward``? The zsrm and vice rewards read a spatial
    relation, which the pendulum has not."""
    return not (goal_relation(goal) is None and reward in ("zsrm", "vice"))


# Stacking relations (the choice scenes' goals).
STACKING = ("on_top_of", "below")
# Relations whose tasks start with the moved block in the open fingers (start "auto"): the block
# must be lifted (onto another, into the box), which from above a policy rarely finds.
GRASPED = (*STACKING, "inside_of")


def check_scene_run(cfg: TrainConfig) -> None:
    """A run on a user's own scene: a scene named as the config records it, a reward that needs
    nothing zsrm builds only for its own scenes, none of the tabletop's starts; one line each."""
    if not isinstance(cfg.scene, str) or not cfg.scene:
        raise ValueError(f"scene must be module:Class or a registered id, got {cfg.scene!r}")
    if cfg.reward == "zsrm" and cfg.reward_model.split("@")[0] == "student":
        raise ValueError(f"the zsrm reward on your own scene ({cfg.scene}) reads a reward model trained on that "
                         "scene's labelled data: give its folder with --reward-model (zsrm reward-data --scene, then "
                         "zsrm finetune --student; docs/own-scene.md); the shipped student knows zsrm's blocks and "
                         "pucks only")
    if cfg.reward == "vice":
        raise ValueError(f"the vice reward fits its goal classifier on zsrm's scripted episodes, which your own "
                         f"scene ({cfg.scene}) has not; train with the oracle, zsrm (--reward-model), base, curiosity or "
                         "random reward")
    if cfg.zsrm_correct_every:
        raise ValueError(f"--zsrm-correct-every labels frames of zsrm's own scenes; your own scene ({cfg.scene}) has "
                         "no calibrated goal labeler in a run yet")
    if cfg.choice:
        raise ValueError("--choice adds a block to zsrm's tabletop; your own scene holds the objects its env holds")
    if cfg.start not in ("auto", "above"):
        raise ValueError(f"start {cfg.start!r} is for the tabletop's blocks; your own scene starts as its env does")
    cfg.start = "above"  # the default: nothing to record


def goal_has_box(goal: str, scene: str | None = None) -> bool:
    """Does a catalogue task or goal sentence of zsrm's scenes name the box? (Own scenes: no.)"""
    from zsrm.tasks.catalogue import resolve

    task = None if scene else resolve(goal).task
    return task is not None and task.has_container


def goal_relation(goal: str, scene: str | None = None) -> str | None:
    """The relation of a goal sentence or catalogue task (None for the pendulum); with ``scene``,
    of a goal over that own scene's objects."""
    from zsrm.tasks.catalogue import resolve

    if scene:
        from zsrm.rl.goals import scene_goal

        return scene_goal(goal, scene).relation
    task = resolve(goal).task
    return task.relation if task is not None else None


# The presets' names, as the commands take them (--config).
PresetName = Literal["cpu", "paper", "v3", "v2", "v1", "sac", "per-task"]
# The old defaults stay by name: a committed result's command names the preset it was made with.
SAMPLED_V2 = {"log_std_init": 0.0, "eval_deterministic": False}
FIXED_VICE = {"vice_update_every": 0, "vice_oracle_labels": False}  # VICE's classifier fitted once
PRESETS: dict[str, dict] = {
    "cpu": {},  # the default (v3 since 2026-12-06)
    "paper": {"steps": 200_000, "n_envs": 16, "n_steps": 256, "batch_size": 512},
    # issue 52's learner (docs/training.md), the default since 2026-12-06: the policy's actions start
    # with a standard deviation of 0.37 instead of 1, and it is evaluated by its mean action
    "v3": {"log_std_init": -1.0, "eval_deterministic": True},  # and VICE updated on oracle-labelled frames
    # the default from 2026-12-04 to 2026-12-06 (action noise 1, sampled evaluation)
    "v2": {**SAMPLED_V2, **FIXED_VICE},
    # issue 52's off-policy learner (docs/training.md, push_close): SAC on keypoints pretrained on
    # random actions' frames of a 64 px view, 4 envs, 500k env steps with the pretraining's
    "sac": {"learner": "sac", "pixel_size": 64, "n_envs": 4, "steps": 500_000},
    # the default until 2026-12-04, behind the results committed before then (64 px policy views,
    # action repeat 2, 10 epochs): about a fifth of the default's speed (results/ppo_speed.json)
    "v1": {"trunk_size": 0, "pixel_size": 0, "action_repeat": 2, "n_epochs": 10, "batch_size": 128, "n_envs": 8,
           "n_steps": 128, "gamma": 0.98, "gae_lambda": 0.95, "anneal_lr": False, **SAMPLED_V2, **FIXED_VICE},
}


# Presets whose settings depend on the goal's relation (in zsrm's scenes); a relation left out takes
# the default's (v3, 300k env steps).
TASK_PRESETS: dict[str, dict[str, dict]] = {
    # issue 52's learner per task (docs/training.md), at most 500k env steps: SAC for the push, the
    # online correction where the student is fooled, a longer budget where PPO was still learning
    "per-task": {
        "close_to": PRESETS["sac"],
        "in_between": {"steps": 500_000, "zsrm_correct_every": 10_000},
        "in_front_of": {"steps": 500_000, "zsrm_correct_every": 10_000},
        "behind": {"steps": 500_000},
        # a longer horizon, and the correction whose labeler reads the block's height (a block held
        # in the air fooled the tilted camera) and starts from labelled exploration renders
        "inside_of": {"steps": 500_000, "gamma": 0.99, "zsrm_correct_every": 10_000, "zsrm_correct_box_area": 0.0115,
                      "zsrm_correct_height": True, "zsrm_correct_lift_max": 0.67, "zsrm_correct_explore": 1024},
    },
}
PRESETS["per-task"] = {}


def preset_settings(name: str, goal: str | None = None, scene: str | None = None) -> dict:
    """The settings of preset ``name`` for ``goal`` (a catalogue task or a goal sentence; the
    per-task presets read its relation; an own ``scene``'s goals take the default's).

    >>> preset_settings("per-task", "push_close")["learner"], preset_settings("per-task", "stack")
    ('sac', {})
    >>> preset_settings("per-task", "a green block behind a blue block")
    {'steps': 500000}
    """
    if name not in PRESETS:
        raise ValueError(f"unknown config {name!r}; choose one of {', '.join(PRESETS)}")
    relation = None
    if name in TASK_PRESETS and goal and not scene:
        try:
            relation = goal_relation(goal)
        except ValueError:  # not a goal: TrainConfig says why
            relation = None
    return {**PRESETS[name], **TASK_PRESETS.get(name, {}).get(relation, {})}


def preset(name: str, **overrides) -> TrainConfig:
    # built anew, not replaced from a default: the default's resolved settings (start) follow its goal
    return TrainConfig(**{**preset_settings(name, overrides.get("goal", TrainConfig.goal), overrides.get("scene")),
                          **overrides})

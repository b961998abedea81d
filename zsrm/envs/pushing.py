"""Sawyer-like pushing: a planar pusher and two pucks on a table (default blue and yellow)."""
from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np

from zsrm.envs.base import TABLE_TOP, MujocoPixelEnv

PUCK_HALF = 0.035
PUCK_HALF_HEIGHT = 0.02
MAX_MOVE = 0.025  # metres of pusher motion per step at |action| = 1
# Pusher workspace: its edge (2 cm radius) plus a puck's width (7 cm) stays on the table
# (half extents 0.32 x 0.24 m), so the pusher cannot shove a puck over the edge.
X_RANGE = (-0.22, 0.22)
Y_RANGE = (-0.14, 0.14)
PUSHER_Z = TABLE_TOP + 0.03
# close to / inside of / on top of / below / in between: each puck starts this many puck widths
# from the table's centre line. At 1.3 a uniform random policy brought the pucks close in 15% of
# the steps (the oracle's 23-48 was under 3x that); at 1.7, in 7% (3 seeds x 30 episodes).
GAP_START = 1.7
# A puck's centre stays this far inside X_RANGE, so the pusher fits behind it (2-3 half-widths).
PUCK_X_MAX = X_RANGE[1] - 2 * PUCK_HALF
NEAR_START_MIN = 0.6  # the nearest a curriculum may start the pucks (puck widths from the centre line)


def check_near_start(near_start: float) -> float:
    """A curriculum's nearest start gap, in [NEAR_START_MIN, GAP_START] puck widths; ValueError otherwise."""
    if not NEAR_START_MIN <= near_start <= GAP_START:
        raise ValueError(f"near_start {near_start}: puck widths from the centre line, in [{NEAR_START_MIN}, "
                         f"{GAP_START}]")
    return float(near_start)


class PushingEnv(MujocoPixelEnv):
    """Two pucks and a pusher driven in the table plane by a mocap body.

    Actions in [-1, 1]: ``(dx, dy)``. Observations: images only. ``near_start`` (training
    curricula): the pucks of close to and the like start a gap drawn per episode between it and
    ``GAP_START`` puck widths from the centre line, instead of ``GAP_START``.

    >>> import gymnasium as gym, zsrm.envs
    >>> env = gym.make("zsrm/Pushing-v0")  # "a blue puck close to a yellow puck"
    >>> obs, info = env.reset(seed=0)
    >>> env.action_space.shape
    (2,)
    """

    asset = "pushing.xml"
    shape = "puck"
    object_half_size = PUCK_HALF

    rest_height = PUCK_HALF_HEIGHT
    layout_version = 2  # 2: pucks start GAP_START = 1.7 widths out (1: 1.3)

    def __init__(self, task="push_close", cameras=("front",), image_size=64, spread="seen", render_mode=None,
                 objects=None, action_repeat: int = 1, near_start: float | None = None):
        # Training curricula: each episode's pucks start a gap drawn between near_start and GAP_START.
        self.near_start = None if near_start is None else check_near_start(near_start)
        super().__init__(task, cameras, image_size, spread, render_mode, objects, action_repeat)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
        m = self.model
        self._mocap = m.body_mocapid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "mocap")]
        self._pusher = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "pusher")
        self._pusher_qadr = m.jnt_qposadr[m.body_jntadr[self._pusher]]

    def _initial_layout(self):
        rng, w = self.np_random, 2 * PUCK_HALF
        rel = self.task.relation
        side = rng.choice([-1.0, 1.0])
        if rel in ("close_to", "inside_of", "on_top_of", "below", "in_between"):
            gap = GAP_START if self.near_start is None else rng.uniform(self.near_start, GAP_START)
            xs, ys = [side * gap * w, -side * gap * w, 0.0], [0.5 * w, 0.5 * w, 0.5 * w]
        elif rel == "left_of":
            xs, ys = [1.2 * w, -1.2 * w], [0.5 * w, 0.5 * w]
        elif rel == "right_of":
            xs, ys = [-1.2 * w, 1.2 * w], [0.5 * w, 0.5 * w]
        elif rel == "in_front_of":
            xs, ys = [-w, w], [1.6 * w, -0.2 * w]
        else:  # behind
            xs, ys = [-w, w], [-0.2 * w, 1.6 * w]
        layout = {}
        for colour, x, y in zip(self.task.objects, xs, ys):
            dx, dy = rng.uniform(-self.spread_width, self.spread_width, 2)
            layout[colour] = np.array([np.clip(x + dx, -PUCK_X_MAX, PUCK_X_MAX), y + dy, TABLE_TOP + PUCK_HALF_HEIGHT])
        return layout

    def _reset_agent(self):
        """Task scenes: the pusher starts on the far side of the puck the goal moves (2-3 puck
        half-widths from its centre, away from the other puck), so exploration pushes it;
        exploration scenes: anywhere along the front edge."""
        rng = self.np_random
        pos = np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.14, -0.11), PUSHER_Z])
        if self.task is not None:
            mover, anchor = (self.data.qpos[self._qpos_adr(c):self._qpos_adr(c) + 3] for c in self.task.objects[:2])
            side = np.sign(mover[0] - anchor[0]) or 1.0
            pos[0] = mover[0] + side * rng.uniform(2.0, 3.0) * PUCK_HALF
            pos[1] = mover[1] + rng.uniform(-PUCK_HALF, PUCK_HALF)
            pos = np.clip(pos, [X_RANGE[0], Y_RANGE[0], PUSHER_Z], [X_RANGE[1], Y_RANGE[1], PUSHER_Z])
        self.data.mocap_pos[self._mocap] = pos
        self.data.qpos[self._pusher_qadr:self._pusher_qadr + 3] = pos
        self.data.qpos[self._pusher_qadr + 3:self._pusher_qadr + 7] = (1, 0, 0, 0)

    @property
    def pusher_position(self) -> np.ndarray:
        return self.data.xpos[self._pusher].copy()

    def _apply_action(self, action):
        target = self.data.mocap_pos[self._mocap] + MAX_MOVE * np.array([action[0], action[1], 0.0])
        target = np.clip(target, [X_RANGE[0], Y_RANGE[0], PUSHER_Z], [X_RANGE[1], Y_RANGE[1], PUSHER_Z])
        self.data.mocap_pos[self._mocap] = target
        self._simulate()

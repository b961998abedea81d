"""Scripted controllers that read the TRUE state. Used only in tests and to show every task is
achievable; never by an agent or a reward model.

>>> import gymnasium as gym, zsrm.envs
>>> from zsrm.envs.scripted import scripted_controller
>>> env = gym.make("zsrm/Tabletop-v0", task="stack")
>>> obs, info = env.reset(seed=0)
>>> controller = scripted_controller(env)
>>> obs, reward, terminated, truncated, info = env.step(controller())
"""
from __future__ import annotations

import numpy as np

from zsrm.envs import pushing, tabletop
from zsrm.envs.base import TABLE_TOP

W = 2 * tabletop.BLOCK_HALF  # block width
HOVER_Z = TABLE_TOP + 0.2
GRASP_DZ = tabletop.GRASP_HEIGHT  # the fingers hold the block, tips clear of the table


def scripted_controller(env):
    """The scripted controller for an environment's task (call it for each action)."""
    base = env.unwrapped
    if isinstance(base, tabletop.TabletopEnv):
        return PickPlaceController(base)
    if isinstance(base, pushing.PushingEnv):
        return PushController(base)
    raise TypeError(f"no scripted controller for {type(base).__name__}")


def _toward(current, target, max_move):
    return np.clip((np.asarray(target) - current) / max_move, -1.0, 1.0)


class PickPlaceController:
    """Pick the block the relation moves, carry it to where the relation holds, release it."""

    def __init__(self, env: tabletop.TabletopEnv):
        self.env = env
        rel, objs = env.task.relation, env.task.objects
        if rel == "inside_of" and objs[1] not in tabletop.CONTAINERS:
            raise NotImplementedError("only the box is a container: no script for 'inside of' another block")
        # below(a, b) is done by putting b on a; everything else moves the first object.
        self.mover = env.task_mover(env.task)
        self.phase, self.wait = "approach", 0

    def _goal(self) -> np.ndarray:
        """Where the moved block's centre should end up, from the other objects' true positions."""
        env, (rel, objs) = self.env, (self.env.task.relation, self.env.task.objects)
        pos = env.object_positions()
        on_table = TABLE_TOP + tabletop.BLOCK_HALF
        if rel == "on_top_of":
            return pos[objs[1]] + (0, 0, W)
        if rel == "below":
            return pos[objs[0]] + (0, 0, W)
        if rel == "inside_of":  # over the box, the block's bottom 1 cm above the walls: dropped in
            return np.array([*pos[objs[1]][:2], TABLE_TOP + 2 * tabletop.BOX_HALF_HEIGHT + 0.01 + W / 2])
        # Two block widths aside, but within the gripper's reach (else the script would hover
        # at the workspace edge with the block in the air for the rest of the episode).
        reach, reach_y = tabletop.X_RANGE[1] - 0.01, tabletop.Y_RANGE[1] - 0.01
        if rel == "left_of":
            return np.array([max(pos[objs[1]][0] - 2 * W, -reach), pos[objs[1]][1], on_table])
        if rel == "right_of":
            return np.array([min(pos[objs[1]][0] + 2 * W, reach), pos[objs[1]][1], on_table])
        if rel == "in_between":
            mid = (pos[objs[1]] + pos[objs[2]]) / 2
            return np.array([mid[0], mid[1], on_table])
        if rel == "in_front_of":
            return np.array([pos[objs[1]][0], max(pos[objs[1]][1] - 2 * W, -reach_y), on_table])
        if rel == "behind":
            return np.array([pos[objs[1]][0], min(pos[objs[1]][1] + 2 * W, reach_y), on_table])
        # close_to: in front of or behind the other block (the fingers open along x, so
        # beside it in x an opening finger would shove it away).
        side = np.sign(pos[objs[0]][1] - pos[objs[1]][1]) or 1.0
        return pos[objs[1]] + (0, side * 1.3 * W, 0)

    def _move(self, target, grip: float):
        g = self.env.gripper_position
        d = _toward(g, target, tabletop.MAX_MOVE)
        if self.env.action_mode == "planar":
            return np.array([d[0], d[2], grip], dtype=np.float32), np.linalg.norm((target - g)[[0, 2]]) < 0.004
        return np.array([*d, grip], dtype=np.float32), np.linalg.norm(target - g) < 0.004

    def _held_target(self, goal) -> np.ndarray:
        """Where the gripper goes to put the held block at ``goal``. Into the box: with the block's
        true offset from the gripper (a block grasped off-centre would land on a wall)."""
        if self.env.task.relation == "inside_of":
            return goal + self.env.gripper_position - self.env.object_positions()[self.mover]
        return goal + (0, 0, GRASP_DZ + 0.004)

    def __call__(self) -> np.ndarray:
        env = self.env
        block = env.object_positions()[self.mover]
        goal = self._goal() if self.phase in ("approach", "descend", "grip") else self._goal_fixed
        if self.phase == "approach":
            action, done = self._move(np.array([block[0], block[1], HOVER_Z]), -1.0)
            if done:
                self.phase = "descend"
        elif self.phase == "descend":
            action, done = self._move(block + (0, 0, GRASP_DZ), -1.0)
            if done:
                self.phase, self.wait = "grip", 3
        elif self.phase == "grip":
            action, _ = self._move(block + (0, 0, GRASP_DZ), 1.0)
            self.wait -= 1
            if self.wait <= 0:
                self.phase, self._goal_fixed = "lift", goal
        elif self.phase == "lift":
            action, done = self._move(np.array([block[0], block[1], HOVER_Z]), 1.0)
            if done:
                self.phase = "carry"
        elif self.phase == "carry":
            target = self._held_target(goal)
            action, done = self._move(np.array([target[0], target[1], HOVER_Z]), 1.0)
            if done:
                self.phase = "lower"
        elif self.phase == "lower":
            action, done = self._move(self._held_target(goal), 1.0)
            if done:
                self.phase, self.wait = "release", 3
        elif self.phase == "release":
            action, _ = self._move(self._held_target(goal), -1.0)
            self.wait -= 1
            if self.wait <= 0:
                self.phase = "retreat"
        else:  # retreat and stay
            g = env.gripper_position
            action, _ = self._move(np.array([g[0], g[1], HOVER_Z]), -1.0)
        return action


class PushController:
    """Push the first puck toward the second: go behind it, then push along the line."""

    def __init__(self, env: pushing.PushingEnv):
        self.env = env
        if env.task.relation != "close_to":
            raise NotImplementedError("the pushing script does 'close to' only")
        self.mover, self.anchor = env.task.objects
        self.phase = "behind"

    def __call__(self) -> np.ndarray:
        env = self.env
        pos = env.object_positions()
        a, b, p = pos[self.mover][:2], pos[self.anchor][:2], env.pusher_position[:2]
        d = (b - a) / (np.linalg.norm(b - a) + 1e-9)
        standoff = pushing.PUCK_HALF + 0.02 + 0.015
        behind = a - d * standoff
        if np.linalg.norm(b - a) < 0.075:
            return np.zeros(2, dtype=np.float32)
        if self.phase == "behind":
            # Go round the puck, not through it: first to a point beside and behind it.
            to_puck = a - p
            side = np.array([-d[1], d[0]])
            in_the_way = np.dot(behind - p, to_puck) > 0 and np.linalg.norm(to_puck) < np.linalg.norm(behind - p) + 0.01
            if in_the_way and abs(np.dot(p - a, side)) < standoff + 0.01:
                sgn = np.sign(np.dot(p - a, side)) or 1.0
                target = a + side * sgn * (standoff + 0.03) - d * standoff
            else:
                target = behind
            if np.linalg.norm(behind - p) < 0.006:
                self.phase = "push"
            return _toward(p, target, pushing.MAX_MOVE).astype(np.float32)
        # push: along the line, correcting sideways drift; re-approach if we lost the puck.
        off_line = np.linalg.norm((p - a) - np.dot(p - a, d) * d)
        if off_line > 0.015 or np.dot(a - p, d) < 0:
            self.phase = "behind"
        return (0.6 * d + _toward(p, a - d * (standoff - 0.01), pushing.MAX_MOVE) * 0.3).astype(np.float32)

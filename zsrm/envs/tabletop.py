"""Fetch-like tabletop: pick, carry, stack and place coloured blocks with a two-finger gripper, and
drop them into an open box (the object "box", present where a goal or ``objects`` names it)."""
from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np

from zsrm.envs.base import TABLE_TOP, MujocoPixelEnv
from zsrm.tasks.lexicon import CONTAINERS
from zsrm.tasks.relations import RELATIONS

BLOCK_HALF = 0.03
# The open box (MJCF "box"): outer half-width, inner half-width, half-height (its origin is the
# centre of its height); blocks drop in over walls BOX_HALF_HEIGHT * 2 high.
BOX_HALF, BOX_INNER_HALF, BOX_HALF_HEIGHT = 0.05, 0.042, 0.02
MAX_MOVE = 0.03  # metres of gripper motion per step at |action| = 1
# Gripper workspace (gripper body origin; fingertips reach 0.08 below it).
X_RANGE = (-0.2, 0.2)  # fingers (6.1 cm out) cannot push a block past the edge (0.32)
Y_RANGE = (-0.16, 0.16)
Z_RANGE = (TABLE_TOP + 0.084, TABLE_TOP + 0.33)
FINGER_OPEN, FINGER_CLOSED = 0.0, 0.045
FINGER_HOLD = 0.053 - 0.008 - BLOCK_HALF  # finger command that rests on a held block's faces
GRASP_HEIGHT = 0.056  # gripper origin above a block's centre when the fingers hold it
FINGERTIP_DROP = 0.08  # fingertips below the gripper origin
# The grip command has hysteresis: the fingers close when it rises above GRIP_CLOSE and open
# again only when it falls below GRIP_OPEN. With a plain sign test, random (and early PPO)
# actions released a grasped block after about one step; now a grasp survives a noisy command.
GRIP_CLOSE, GRIP_OPEN = 0.3, -0.7
# Where a task scene's distractor starts: at the back of the table, out of the way (the base
# class's), or in line with the goal's blocks on the far side of the moved block from its
# base ("line", stacking goals), so a policy must tell its base from the distractor by colour.
DISTRACTOR_PLACES = ("back", "line")


class TabletopEnv(MujocoPixelEnv):
    """Blocks on a table, a gripper driven by a mocap body. Observations: images only.

    Actions in [-1, 1]: ``(dx, dz, grip)`` in the front camera's plane ("planar", the default
    for relations the front camera reads) or ``(dx, dy, dz, grip)`` ("full", the default for
    in front of / behind / close to / inside of). ``grip`` above 0.3 closes the fingers and only
    ``grip`` below -0.7 opens them again (hysteresis, so a noisy command keeps its grasp); a block
    held between closing fingers is welded to the gripper until they open (a grasp that does not
    slip). ``lift_ceiling`` (metres above the table) lowers the top of the gripper's workspace in
    task scenes, for goals read on the table where a high lift only leaves the frames a reward
    model was trained on.

    >>> import gymnasium as gym, zsrm.envs
    >>> env = gym.make("zsrm/Tabletop-v0", task="a yellow block on top of a red block")
    >>> obs, info = env.reset(seed=0)
    >>> obs["front"].shape, sorted(info["object_positions"])
    ((64, 64, 3), ['red', 'yellow'])
    """

    asset = "tabletop.xml"
    shape = "block"
    object_half_size = BLOCK_HALF
    containers = CONTAINERS

    rest_height = BLOCK_HALF

    def __init__(self, task="stack", cameras=("front",), image_size=64, spread="seen",
                 action_mode: str | None = None, render_mode=None, objects=None, action_repeat: int = 1,
                 start: str = "above", distractor_place: str = "back", lift_ceiling: float | None = None):
        if start not in ("above", "around"):
            raise ValueError(f"unknown start {start!r}; choose 'above' or 'around'")
        if distractor_place not in DISTRACTOR_PLACES:
            raise ValueError(f"unknown distractor_place {distractor_place!r}; choose one of {', '.join(DISTRACTOR_PLACES)}")
        if lift_ceiling is not None and not Z_RANGE[0] - TABLE_TOP <= lift_ceiling <= Z_RANGE[1] - TABLE_TOP:
            raise ValueError(f"lift_ceiling {lift_ceiling} m: the gripper's highest point above the table must lie "
                             f"in [{Z_RANGE[0] - TABLE_TOP:.3f}, {Z_RANGE[1] - TABLE_TOP:.3f}]")
        self.start, self.distractor_place = start, distractor_place
        # The workspace's top, or lower: a task whose relation lies on the table needs no high lift.
        self.z_max = Z_RANGE[1] if lift_ceiling is None else TABLE_TOP + float(lift_ceiling)
        super().__init__(task, cameras, image_size, spread, render_mode, objects, action_repeat)
        if distractor_place == "line":
            if self.task is None or self.task.relation not in ("on_top_of", "below") or len(self.distractors) != 1:
                raise ValueError("distractor_place 'line' is for a stacking goal (on top of, below) with one "
                                 "distractor colour in objects")
        if action_mode is None:
            planar = self.task is not None and RELATIONS[self.task.relation].camera == "front"
            action_mode = "planar" if planar else "full"
        if action_mode not in ("planar", "full"):
            raise ValueError(f"unknown action_mode {action_mode!r}; choose 'planar' or 'full'")
        self.action_mode = action_mode
        self.action_space = gym.spaces.Box(-1.0, 1.0, (3 if action_mode == "planar" else 4,), np.float32)
        m = self.model
        self._mocap = m.body_mocapid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "mocap")]
        self._gripper = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "gripper")
        self._gripper_qadr = m.jnt_qposadr[m.body_jntadr[self._gripper]]
        self._grasp_eq = {c: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, f"grasp_{c}")
                          for c in self.objects if c not in CONTAINERS}  # the box is not grasped
        self.held: str | None = None
        self.closed = False  # the grip state the hysteresis keeps
        self._hold_at_reset: str | None = None  # exploration: the block the gripper starts holding

    # --- layout ------------------------------------------------------------------------
    def _initial_layout(self):
        """Nominal start positions per relation, plus uniform noise of ``spread_width``."""
        rng, w = self.np_random, 2 * BLOCK_HALF
        rel, n = self.task.relation, len(self.task.objects)
        side = rng.choice([-1.0, 1.0])
        if rel == "left_of":
            xs, ys = [1.5 * w, -1.5 * w], [0, 0]
        elif rel == "right_of":
            xs, ys = [-1.5 * w, 1.5 * w], [0, 0]
        elif rel in ("on_top_of", "below") and self.distractor_place == "line":
            # the moved block in the middle: its base on one side, the distractor on the other
            xs, ys = [0.0, side * 2.5 * w], [0, 0]
            if rel == "below":
                xs = xs[::-1]
        elif rel in ("on_top_of", "below"):
            xs, ys = [side * 1.5 * w, -side * 1.5 * w], [0, 0]
        elif rel == "in_between":
            xs, ys = [side * 2.5 * w, -side * 2.5 * w, 0.0], [0, 0, 0]
        # In front of / behind: the other block starts near the centre line, so that there is room
        # to put the moved one down on its far side within the gripper's reach (Y_RANGE).
        elif rel == "in_front_of":
            xs, ys = [-w, w], [1.3 * w, -0.3 * w]
        elif rel == "behind":
            xs, ys = [-w, w], [-1.3 * w, 0.3 * w]
        else:  # close_to, inside_of (the box starts two block widths from the block)
            xs, ys = [side * 2 * w, -side * 2 * w], [0, 0]
        planar = self.action_mode == "planar"
        layout = {}
        for colour, x, y in zip(self.task.objects, xs, ys):
            dx, dy = rng.uniform(-self.spread_width, self.spread_width, 2)
            layout[colour] = np.array([x + dx, y + (0.0 if planar else dy), TABLE_TOP + BLOCK_HALF])
        assert len(layout) == n
        if self.distractor_place == "line":
            dx, dy = rng.uniform(-self.spread_width, self.spread_width, 2)
            layout[self.distractors[0]] = np.array([-side * 2.5 * w + dx, 0.0 if planar else dy, TABLE_TOP + BLOCK_HALF])
        return layout

    def _layout_ok(self, layout) -> bool:
        """Every block starts clear of the box's walls (a 1 cm gap), or (exploration scenes that
        stack a block on the box) above its opening, to fall in."""
        if "box" not in layout:
            return True
        box = layout["box"]

        def ok(p):
            d = np.max(np.abs(p[:2] - box[:2]))
            above = p[2] > TABLE_TOP + 2 * BOX_HALF_HEIGHT + BLOCK_HALF and d < BOX_INNER_HALF - BLOCK_HALF
            return d > BOX_HALF + BLOCK_HALF + 0.01 or above
        return all(ok(p) for c, p in layout.items() if c != "box")

    def _random_layout(self, p_stack: float = 0.25, p_side: float = 0.0, p_hold: float = 0.0,
                       p_inside: float = 0.0, p_hold_free: float = 0.0):
        """Exploration: :meth:`MujocoPixelEnv._random_layout`; in a scene with the box, with
        probability ``p_inside`` a block starts just above the box's opening and falls in (random
        actions almost never drop one in, and "inside of" needs frames that show it); and with
        probability ``p_hold`` the gripper starts holding a block in the air above another (up to
        15 cm above stacked height, mostly in line with it). Random actions almost never lift a
        block over another, so without these frames a reward model never sees a block that hovers
        just too high to be "on top of" one, and a policy learns to hover instead of stacking.
        With probability ``p_hold_free`` a held block is instead anywhere in the gripper's reach,
        high above the others (a policy trained on a student that never saw one lifted the block
        to the top of the frame beside the others, where the student read "in between")."""
        layout = super()._random_layout(p_stack, p_side)
        self._hold_at_reset = None
        rng = self.np_random
        # Drawn only in box scenes with p_inside set: other scenes keep their random stream.
        if "box" in layout and p_inside and rng.random() < p_inside:
            self._drop_into_box(layout)
        if not rng.random() < p_hold:
            return layout
        free = self._free_blocks(layout)
        if len(free) < 2:
            return layout
        mover, base = rng.choice(free, 2, replace=False).tolist()
        # Drawn only with p_hold_free set: datasets without it keep their random stream.
        if p_hold_free and rng.random() < p_hold_free:
            layout[mover] = np.array([rng.uniform(*X_RANGE), rng.uniform(-0.3, 0.3) * BLOCK_HALF,
                                      rng.uniform(TABLE_TOP + 5 * BLOCK_HALF, Z_RANGE[1] - GRASP_HEIGHT)])
            self._hold_at_reset = mover
            return layout
        b = layout[base]
        spread = 0.3 * BLOCK_HALF if rng.random() < 0.7 else 2.5 * BLOCK_HALF
        gap = rng.uniform(0.005, 0.15)  # above stacked height: "on top of" holds below 3 cm
        p = np.array([b[0] + rng.uniform(-spread, spread), b[1] + rng.uniform(-0.3, 0.3) * BLOCK_HALF,
                      b[2] + 2 * BLOCK_HALF + gap])
        p[:2] = np.clip(p[:2], [X_RANGE[0], Y_RANGE[0]], [X_RANGE[1], Y_RANGE[1]])
        p[2] = min(p[2], Z_RANGE[1] - GRASP_HEIGHT)
        layout[mover] = p
        self._hold_at_reset = mover
        return layout

    def _free_blocks(self, layout) -> list[str]:
        """Blocks on the table with nothing stacked on them (they can move without hitting one)."""
        return [c for c, p in layout.items() if c not in self.containers and p[2] < TABLE_TOP + 1.5 * BLOCK_HALF
                and not any(np.allclose(q[:2], p[:2], atol=BLOCK_HALF) and q[2] > p[2] for q in layout.values())]

    def _drop_into_box(self, layout) -> None:
        """Move a free block to just above the box's opening (it falls in while the reset
        settles); nothing moves when a block is over the opening already (stacked on the box)."""
        box, slack = layout["box"], BOX_INNER_HALF - BLOCK_HALF - 0.002  # _layout_ok's "above the opening"
        free = self._free_blocks(layout)
        over = [c for c, p in layout.items()
                if c != "box" and np.max(np.abs(p[:2] - box[:2])) < BOX_INNER_HALF - BLOCK_HALF]
        if not free or over:
            return
        colour = free[self.np_random.integers(len(free))]
        dx, dy = self.np_random.uniform(-slack, slack, 2)
        layout[colour] = np.array([box[0] + dx, box[1] + dy, TABLE_TOP + 2 * BOX_HALF_HEIGHT + BLOCK_HALF + 0.005])

    def _set_object(self, colour: str, xyz):
        if colour in CONTAINERS:  # fixed to the world: move the body, standing on the table
            self.model.body_pos[self._body(colour)] = (xyz[0], xyz[1], TABLE_TOP + BOX_HALF_HEIGHT)
        else:
            super()._set_object(colour, xyz)

    def _reset_agent(self):
        """Task scenes: the gripper starts open above the block the goal moves (within one block
        width, its fingertips 1-6 cm above the block), so exploration touches it, or with
        ``start="around"`` its open fingers around that block; exploration scenes: anywhere above
        the table."""
        rng = self.np_random
        y = 0.0 if self.action_mode == "planar" else rng.uniform(-0.08, 0.08)
        pos = np.array([rng.uniform(-0.15, 0.15), y, rng.uniform(TABLE_TOP + 0.15, TABLE_TOP + 0.25)])
        if self.task is not None:
            mover = self.task_mover(self.task)
            block = self.data.qpos[self._qpos_adr(mover):self._qpos_adr(mover) + 3]
            pos[0] = block[0] + rng.uniform(-2 * BLOCK_HALF, 2 * BLOCK_HALF)
            if self.action_mode == "full":
                pos[1] = block[1] + rng.uniform(-BLOCK_HALF, BLOCK_HALF)
            pos[2] = block[2] + BLOCK_HALF + FINGERTIP_DROP + rng.uniform(0.01, 0.06)
            if self.start == "around":  # open fingers around the block: closing them grasps it
                pos[0] = block[0] + rng.uniform(-0.01, 0.01)
                pos[1] = block[1] if self.action_mode == "full" else pos[1]
                pos[2] = block[2] + GRASP_HEIGHT
            pos = np.clip(pos, [X_RANGE[0], Y_RANGE[0], Z_RANGE[0]], [X_RANGE[1], Y_RANGE[1], self.z_max])
        self.data.mocap_pos[self._mocap] = pos
        self.data.qpos[self._gripper_qadr:self._gripper_qadr + 3] = pos
        self.data.qpos[self._gripper_qadr + 3:self._gripper_qadr + 7] = (1, 0, 0, 0)
        self.data.ctrl[:] = FINGER_OPEN
        self.data.eq_active[list(self._grasp_eq.values())] = 0
        self.held = None
        self.closed = False
        if self.task is None and self._hold_at_reset is not None:  # exploration: start holding it
            block = self.data.qpos[self._qpos_adr(self._hold_at_reset):self._qpos_adr(self._hold_at_reset) + 3]
            self.data.mocap_pos[self._mocap] = block + (0.0, 0.0, GRASP_HEIGHT)
            self.data.qpos[self._gripper_qadr:self._gripper_qadr + 3] = block + (0.0, 0.0, GRASP_HEIGHT)
            mujoco.mj_forward(self.model, self.data)
            self.held, self.closed = self._hold_at_reset, True
            self._weld(self.held)
            self.data.ctrl[:] = FINGER_HOLD
            self._hold_at_reset = None

    @staticmethod
    def task_mover(task) -> str:
        """The block a task moves: below(a, b) puts b on a; the box never moves."""
        objs = task.objects
        order = (objs[1], objs[0]) if task.relation == "below" else objs
        return next(c for c in order if c not in CONTAINERS)

    # --- control -----------------------------------------------------------------------
    @property
    def gripper_position(self) -> np.ndarray:
        return self.data.xpos[self._gripper].copy()

    def _apply_action(self, action):
        if self.action_mode == "planar":
            delta = np.array([action[0], 0.0, action[1]])
        else:
            delta = action[:3].copy()
        target = self.data.mocap_pos[self._mocap] + MAX_MOVE * delta
        target = np.clip(target, [X_RANGE[0], Y_RANGE[0], Z_RANGE[0]], [X_RANGE[1], Y_RANGE[1], self.z_max])
        if self.action_mode == "planar":
            target[1] = 0.0
        self.data.mocap_pos[self._mocap] = target
        if action[-1] > GRIP_CLOSE:
            self.closed = True
        elif action[-1] < GRIP_OPEN:
            self.closed = False
        closing = self.closed
        if closing and self.held is None:
            self.held = self._block_between_fingers()
            if self.held is not None:
                self._weld(self.held)
        elif not closing and self.held is not None:
            self.data.eq_active[self._grasp_eq[self.held]] = 0
            self.held = None
        # Fingers close onto a held block's faces, or fully when empty.
        self.data.ctrl[:] = FINGER_HOLD if self.held else (FINGER_CLOSED if closing else FINGER_OPEN)
        self._simulate()

    def _block_between_fingers(self) -> str | None:
        g = self.gripper_position
        for colour, p in self.object_positions().items():
            if colour not in self._grasp_eq:
                continue
            d = p - g
            if abs(d[0]) < 0.035 and abs(d[1]) < 0.03 and -0.075 < d[2] < -0.02:
                return colour
        return None

    def _weld(self, colour: str):
        """Weld the block to the gripper at their present relative pose."""
        eq = self._grasp_eq[colour]
        b = self._body(colour)
        g_pos, g_quat = self.data.xpos[self._gripper], self.data.xquat[self._gripper]
        b_pos, b_quat = self.data.xpos[b], self.data.xquat[b]
        inv = np.zeros(4)
        mujoco.mju_negQuat(inv, g_quat)
        rel_pos = np.zeros(3)
        mujoco.mju_rotVecQuat(rel_pos, b_pos - g_pos, inv)
        rel_quat = np.zeros(4)
        mujoco.mju_mulQuat(rel_quat, inv, b_quat)
        # eq_data of a weld: anchor (3), relative position (3), relative quaternion (4), torquescale.
        self.model.eq_data[eq, 0:3] = 0.0
        self.model.eq_data[eq, 3:6] = rel_pos
        self.model.eq_data[eq, 6:10] = rel_quat
        self.model.eq_data[eq, 10] = 1.0
        self.data.eq_active[eq] = 1

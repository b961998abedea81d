"""zsrm: zero-shot rewards for reinforcement learning from a goal sentence and camera images."""
import os

# Offscreen rendering on a machine without a display: MuJoCo reads this when it is first imported,
# so it is set here, before any zsrm module imports mujoco (a user's own value wins).
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"

"""zsrm: zero-shot rewards for reinforcement learning from a goal sentence and camera images."""
__version__ = "0.1.0"

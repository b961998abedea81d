"""Test doubles shared by the doctests and the tests: small models whose answers are known and
synthetic captioned frames. No library package imports this one.

>>> from zsrm.testing import ColourVLM, TaskTextVLM, synthetic_pairs
"""
from zsrm.testing.colour_vlm import ColourVLM
from zsrm.testing.synthetic import TaskTextVLM, render_squares, synthetic_pairs

__all__ = ["ColourVLM", "TaskTextVLM", "render_squares", "synthetic_pairs"]

"""The examples in the docstrings of the other layers run and give what they show."""
import doctest
import importlib

import pytest

MODULES = ["zsrm.tasks.catalogue", "zsrm.tasks.language", "zsrm.envs.rollout", "zsrm.fullmodel",
           "zsrm.fullmodel.ensemble", "zsrm.evaluation.metrics", "zsrm.evaluation.curves", "zsrm.evaluation.goal_parsing", "zsrm.cli.options", "zsrm.testing.colour_vlm",
           "zsrm.testing.hostile", "zsrm.testing.synthetic", "zsrm.rewards.vice", "zsrm.rl.sweep",
           "zsrm.rl.auxiliary", "zsrm.rl.augment", "zsrm.envs.state", "zsrm.evaluation.learning_curves", "zsrm.evaluation.pendulum_pose",
           "zsrm.pipeline.learn"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0

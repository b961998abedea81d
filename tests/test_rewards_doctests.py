"""The examples in the rewards package's docstrings run and give what they show."""
import doctest
import importlib

import pytest

MODULES = ["zsrm.rewards.reward_model", "zsrm.rewards.oracle", "zsrm.rewards.wrappers", "zsrm.rewards.curve"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0


def test_projection_reward_example():
    from zsrm.rewards import base

    finder = doctest.DocTestFinder()
    runner = doctest.DocTestRunner()
    for test in finder.find(base.projection_reward, "projection_reward", globs=vars(base)):
        runner.run(test)
    assert runner.summarize(verbose=False).failed == 0

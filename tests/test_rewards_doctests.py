"""The examples in the rewards package's docstrings run and give what they show."""
import doctest
import importlib

import pytest

# base.py's example loads the shipped scene VLM (zsrm/vlm/weights/scene).
MODULES = ["zsrm.rewards.binarised", "zsrm.rewards.base", "zsrm.rewards.oracle", "zsrm.rewards.wrappers",
           "zsrm.rewards.corrected"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0


"""The examples in the vlm package's docstrings run and give what they show."""
import doctest
import importlib

import pytest

MODULES = ["zsrm.vlm.base", "zsrm.vlm.losses", "zsrm.vlm.presence", "zsrm.vlm.scene", "zsrm.vlm.text_cache"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0

"""The examples in the common package's docstrings (files, saved-model registry) run and give what they show."""
import doctest
import importlib

import pytest

MODULES = ["zsrm.common.files", "zsrm.common.registry"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0

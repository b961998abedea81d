"""The examples in the common package's docstrings (files, saved-model registry, machine) run and give what they show."""
import doctest
import importlib

import pytest

MODULES = ["zsrm.common.files", "zsrm.common.registry", "zsrm.common.machine"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0


def test_cpu_model_reads_cpuinfo(tmp_path):
    # Results record the CPU's model: float results move across CPU models (docs/own-scene.md).
    from zsrm.common.machine import cpu_model

    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\ncpu family\t: 26\nmodel\t\t: 2\nmodel name\t: AMD EPYC\n"
                    "flags\t\t: fpu sse2 avx2 avx512f\n\nprocessor\t: 1\nmodel name\t: AMD EPYC\n")
    assert cpu_model(info) == "AMD EPYC (family 26, model 2), AVX-512"
    info.write_text("processor\t: 0\nmodel name\t: Intel(R) Xeon(R) Gold\nflags\t\t: avx2\n")
    assert cpu_model(info) == "Intel(R) Xeon(R) Gold"

"""What machine a result came from. Float results move across CPUs (docs/own-scene.md: the same
command and seed differ between two x86_64 models), so a result records the CPU's model, not only
its architecture.

>>> import platform
>>> describe().startswith(platform.machine() + ", ")
True
"""
from __future__ import annotations

import os
import platform
from pathlib import Path


def cpu_model(cpuinfo: str | Path = "/proc/cpuinfo") -> str:
    """The CPU's model name (Linux: /proc/cpuinfo, with family/model numbers where the name is
    generic, and AVX-512 where present); else what ``platform`` knows."""
    info = Path(cpuinfo)
    fields: dict[str, str] = {}
    if info.is_file():
        for line in info.read_text(errors="replace").splitlines():
            key, _, value = line.partition(":")
            fields.setdefault(key.strip(), value.strip())
    name = fields.get("model name") or platform.processor() or platform.machine()
    if "cpu family" in fields and "model" in fields:
        name += f" (family {fields['cpu family']}, model {fields['model']})"
    if "avx512f" in fields.get("flags", "").split():
        name += ", AVX-512"
    return name


def describe() -> str:
    """``x86_64, AMD EPYC (family 26, model 2), AVX-512, 2 cores``."""
    return f"{platform.machine()}, {cpu_model()}, {os.cpu_count()} cores"

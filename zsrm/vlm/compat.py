"""Imports that need care on CPU-only machines.

PyPI's torchvision wheel is built for CUDA. Next to a CPU-only torch its compiled ops do not
load, and ``import torchvision`` (so also ``open_clip`` and ``transformers``' image code,
which sentence-transformers pulls in) fails with ``operator torchvision::nms does not exist``.
Declaring the two missing operator schemas lets everything but ``torchvision.ops.nms`` work.
We only declare them after a real import has failed, so a working torchvision is untouched.
"""
from __future__ import annotations

import os
import sys

import torch

_SCHEMAS = (
    "nms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor",
    "qnms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor",
)
_LIBRARIES: list = []  # keeps the fragment alive for the life of the process


def import_torchvision():
    """``import torchvision``, declaring the missing nms/qnms schemas first if it needs them."""
    try:
        import torchvision
        return torchvision
    except RuntimeError as err:
        if "torchvision::nms" not in str(err) or _LIBRARIES:
            raise
    # Drop the half-imported package so that the second import starts clean.
    for name in [m for m in sys.modules if m == "torchvision" or m.startswith("torchvision.")]:
        del sys.modules[name]
    lib = torch.library.Library("torchvision", "FRAGMENT")
    for schema in _SCHEMAS:
        lib.define(schema)
    _LIBRARIES.append(lib)
    import torchvision
    return torchvision


def import_open_clip():
    """``import open_clip`` after :func:`import_torchvision`."""
    import_torchvision()
    import open_clip
    return open_clip


def import_sentence_transformers():
    """``import sentence_transformers`` after :func:`import_torchvision`, hub offline by default
    (zsrm loads sentence encoders from installed folders only)."""
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    import_torchvision()
    import sentence_transformers
    return sentence_transformers

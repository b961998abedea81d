"""The full zero-shot reward model (paper 2.2): contrastive fine-tuning of a VLM on the generated
pairs (an adapted VLM) and a small student network for the RL loop, and an ensemble of several
(the mean of their image-text scores). Importing this package registers the three model kinds
and the shipped student (spec ``"student"``) with the VLM registry.

>>> from zsrm.fullmodel import FinetuneConfig, finetune, load_reward_backbone
>>> load_reward_backbone("student").backend
'zsrm-student'
"""
from __future__ import annotations

from pathlib import Path

from zsrm.fullmodel.adapted import AdaptedVLM
from zsrm.fullmodel.ensemble import StudentEnsemble, write_ensemble
from zsrm.fullmodel.pairs import CaptionedImages
from zsrm.fullmodel.student import SHIPPED_STUDENT_DIR, StudentConfig, StudentRewardNet
from zsrm.fullmodel.training import FinetuneConfig, finetune
from zsrm.vlm.factory import load_vlm


def load_reward_backbone(spec: str | Path, device="cpu"):
    """The model a zsrm reward scores with: a folder written by ``zsrm finetune`` (fine-tuned VLM
    or student) or an ensemble of such (:func:`write_ensemble`), ``"student"`` (the shipped
    student), or any other ``load_vlm`` spec (e.g. ``scene``, the base VLM). The same as
    :func:`zsrm.vlm.load_vlm` once this package has registered its model kinds."""
    return load_vlm(str(spec), device=device)


__all__ = ["AdaptedVLM", "CaptionedImages", "FinetuneConfig", "SHIPPED_STUDENT_DIR", "StudentConfig",
           "StudentEnsemble", "StudentRewardNet", "finetune", "load_reward_backbone", "write_ensemble"]

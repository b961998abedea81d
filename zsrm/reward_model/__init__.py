"""The full zero-shot reward model (paper 2.2): contrastive fine-tuning on the generated pairs,
a small student network for the RL loop, and the binarised reward's negatives.

>>> from zsrm.reward_model import FinetuneConfig, finetune, negative_texts
>>> negative_texts("a yellow block on top of a red block")[-1]
'a red block on top of a yellow block'
"""
from zsrm.reward_model.training import FinetuneConfig, finetune
from zsrm.reward_model.negatives import candidate_texts, negative_tasks, negative_texts
from zsrm.reward_model.pairs import CaptionedImages
from zsrm.reward_model.student import StudentConfig, StudentRewardNet, load_reward_backbone

__all__ = ["FinetuneConfig", "finetune", "candidate_texts", "negative_tasks", "negative_texts", "CaptionedImages",
           "StudentConfig", "StudentRewardNet", "load_reward_backbone"]

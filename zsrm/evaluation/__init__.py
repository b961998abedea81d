"""Evaluation: how well each stage does, against the oracle (true state), as tables and plots.

* :mod:`~zsrm.evaluation.scripted_success`: every task is achievable (``zsrm scripted-eval``);
* :mod:`~zsrm.evaluation.vlm_presence`: the scene VLM's zero-shot presence AUROC (``zsrm eval-vlm``);
* :mod:`~zsrm.evaluation.grounding_quality`: Grad-CAM localisation and caption F1 (``zsrm eval-grounding``);
* :mod:`~zsrm.evaluation.reward_quality`: rewards against the oracle on held-out frames (``zsrm eval-reward``);
* :mod:`~zsrm.evaluation.curves`: rewards along scripted trajectories (Figure 5, ``zsrm reward-curve``);
* :mod:`~zsrm.evaluation.goal_parsing`: goal sentences read against the paraphrase set (``zsrm eval-goals``);
* :mod:`~zsrm.evaluation.metrics`: AUROC, precision/recall/F1, computed one way everywhere.
"""

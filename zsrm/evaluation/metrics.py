"""The scores every evaluation reports, computed one way everywhere.

>>> auroc([0.1, 0.9, 0.4], [False, True, False])
1.0
>>> auroc([0.1, 0.9], [True, True])  # one class only: undefined
nan
"""
from __future__ import annotations

import numpy as np


def auroc(scores, truth) -> float:
    """Area under the ROC curve of ``scores`` against boolean ``truth`` (ties count half);
    NaN when it is undefined: only one class present."""
    from sklearn.metrics import roc_auc_score

    t = np.asarray(truth, bool)
    if t.all() or not t.any():
        return float("nan")
    return float(roc_auc_score(t, np.asarray(scores, np.float64)))


def binary_metrics(predicted, truth) -> dict:
    """Precision, recall and F1 of binary predictions (0 where undefined), and the counts
    (accuracy NaN over no frames)."""
    p, t = np.asarray(predicted, bool), np.asarray(truth, bool)
    tp, fp, fn = int((p & t).sum()), int((p & ~t).sum()), int((~p & t).sum())
    precision = tp / (tp + fp) if tp + fp else 0.0
    recall = tp / (tp + fn) if tp + fn else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {"precision": precision, "recall": recall, "f1": f1, "accuracy": float((p == t).mean()) if p.size else float("nan"),
            "predicted_positive": int(p.sum())}


def best_threshold_f1(scores, truth) -> float:
    """The highest F1 of ``scores > threshold`` over all thresholds (privileged: uses the labels)."""
    from sklearn.metrics import precision_recall_curve

    t = np.asarray(truth, bool)
    if not t.any():
        return float("nan")
    precision, recall, _ = precision_recall_curve(t, np.asarray(scores, np.float64))
    f1 = np.where(precision + recall > 0, 2 * precision * recall / np.maximum(precision + recall, 1e-12), 0.0)
    return float(f1.max())

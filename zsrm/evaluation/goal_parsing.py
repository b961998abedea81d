"""How well goal sentences are read: the paraphrase set kept in the repo, scored (``zsrm eval-goals``).

The set (``zsrm/tasks/paraphrases.json``) holds goals as people write them, each with the
relation, ordered objects and shape zsrm must read, and sentences that must be refused, each
with the reason. ``accuracy`` is the fraction of the first read exactly right (relation and
objects in order; a refusal counts as wrong), ``refusal_accuracy`` the fraction of the second
refused. Reading a sentence as the *wrong* task is the failure that matters most: it is
counted on its own (``wrong_task``).

>>> result = score_goals()
>>> result["accuracy"] >= 0.95, result["refusal_accuracy"] >= 0.95, result["wrong_task"]
(True, True, 0)
"""
from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import zsrm.tasks
from zsrm.tasks.language import GoalError, parse_goal

PARAPHRASES = Path(zsrm.tasks.__file__).with_name("paraphrases.json")


def load_paraphrases(path: str | Path = PARAPHRASES) -> dict:
    """The paraphrase set: ``understood`` (text, relation, objects, shape) and ``refused`` (text, reason)."""
    data = json.loads(Path(path).read_text())
    for key, fields in (("understood", ("text", "relation", "objects")), ("refused", ("text", "reason"))):
        for entry in data.get(key, []):
            missing = [f for f in fields if f not in entry]
            if missing:
                raise ValueError(f"{path}: {key} entry {entry!r} lacks {', '.join(missing)}")
    return data


def _read(text: str) -> tuple[dict | None, GoalError | None]:
    try:
        task = parse_goal(text)
    except GoalError as err:
        return None, err
    return {"relation": task.relation, "objects": list(task.objects), "shape": task.shape}, None


def _score_understood(entries: list[dict]) -> tuple[dict, list[dict]]:
    right, shape_right, wrong_task = 0, 0, 0
    by_relation, by_batch = defaultdict(list), defaultdict(list)
    failures = []
    for e in entries:
        got, err = _read(e["text"])
        ok = got is not None and (got["relation"], got["objects"]) == (e["relation"], list(e["objects"]))
        right += ok
        shape_right += ok and got["shape"] == e.get("shape", "block")
        wrong_task += got is not None and not ok
        by_relation[e["relation"]].append(ok)
        by_batch[str(e.get("batch", 1))].append(ok)
        if not ok:
            expected = {k: e[k] for k in ("relation", "objects")}
            failures.append({"text": e["text"], "expected": expected, "got": got or f"refused: {err}"})
    n = max(len(entries), 1)
    figures = {
        "accuracy": right / n, "shape_accuracy": shape_right / n, "wrong_task": wrong_task,
        "accuracy_by_relation": {r: sum(v) / len(v) for r, v in sorted(by_relation.items())},
        "accuracy_by_batch": {b: sum(v) / len(v) for b, v in sorted(by_batch.items())},
    }
    return figures, failures


def _score_refused(entries: list[dict]) -> tuple[dict, list[dict]]:
    refused, reason_right, failures = 0, 0, []
    for e in entries:
        got, err = _read(e["text"])
        refused += err is not None
        reason_right += err is not None and err.reason == e["reason"]
        if err is None:
            failures.append({"text": e["text"], "expected": f"refused: {e['reason']}", "got": got})
        elif err.reason != e["reason"]:
            failures.append({"text": e["text"], "expected": f"refused: {e['reason']}", "got": f"refused: {err}",
                             "only_the_reason_differs": True})
    n = max(len(entries), 1)
    return {"refusal_accuracy": refused / n, "refusal_reason_accuracy": reason_right / n}, failures


def score_goals(path: str | Path = PARAPHRASES) -> dict:
    """Every sentence of the set read by :func:`zsrm.tasks.parse_goal`: the figures and each failure."""
    data = load_paraphrases(path)
    understood, failures = _score_understood(data["understood"])
    refused, refusal_failures = _score_refused(data["refused"])
    return {
        "accuracy": understood.pop("accuracy"), "refusal_accuracy": refused.pop("refusal_accuracy"),
        "understood": len(data["understood"]), "refused": len(data["refused"]), **understood, **refused,
        "failures": failures + refusal_failures,
    }

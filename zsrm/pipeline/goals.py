"""Stages about goal sentences: ``zsrm parse-goal`` (how zsrm reads one) and ``zsrm eval-goals``
(how well it reads the paraphrase set kept in the repo)."""
from __future__ import annotations

import json
import platform
import shlex
import sys
from dataclasses import dataclass, field
from pathlib import Path

from zsrm.evaluation.goal_parsing import PARAPHRASES
from zsrm.tasks.language import parse_goal
from zsrm.tasks.relations import RELATIONS


@dataclass
class ParseGoal:
    """Print a goal sentence as zsrm reads it: relation, objects in order, canonical sentence.

    What it cannot read it refuses: exit status 2 and one line saying what is wrong (unknown
    colour or object, one object only, the same object twice, no relation, ...) and, where
    there is one, the nearest goal it does read. Quoting the sentence is optional.
    """

    text: tuple[str, ...] = field(metadata={"positional": True, "split": False, "metavar": "TEXT"})  # the goal sentence
    json: bool = False  # print the reading as one JSON object
    scene: str | None = None  # your own scene (module:Class or a registered id): read the goal over its objects

    def run(self) -> int:
        sentence = " ".join(self.text)
        reading = self.scene_reading(sentence) if self.scene else self.zsrm_reading(sentence)
        if self.json:
            print(json.dumps(reading))
        else:
            kind = f"{reading['shape']}s, in order" if "shape" in reading else "in order"
            print(f"relation:  {reading['relation']}\nobjects:   {', '.join(reading['objects'])} ({kind})\n"
                  f"canonical: {reading['canonical']}")
        return 0

    @staticmethod
    def zsrm_reading(sentence: str) -> dict:
        task = parse_goal(sentence)
        return {"text": sentence, "relation": task.relation, "objects": list(task.objects), "shape": task.shape,
                "canonical": task.text, "scene": task.scene, "camera": RELATIONS[task.relation].camera}

    def scene_reading(self, sentence: str) -> dict:
        from zsrm.rl.goals import scene_goal

        goal = scene_goal(sentence, self.scene)
        return {"text": sentence, "relation": goal.relation, "objects": list(goal.objects), "canonical": goal.text,
                "scene": self.scene, "camera": RELATIONS[goal.relation].camera}


@dataclass
class EvalGoals:
    """Score goal reading on the paraphrase set kept in the repo (zsrm/tasks/paraphrases.json).

    accuracy: relation and ordered objects exactly right over the sentences that must be read;
    refusal_accuracy: fraction of the sentences that must be refused that are. Every failure is
    listed. Exit status 1 if either falls below --min-accuracy.
    """

    paraphrases: str = str(PARAPHRASES)  # the paraphrase set (JSON: understood, refused)
    out: str | None = None  # JSON path, e.g. results/goals.json
    min_accuracy: float = 0.95  # exit 1 if accuracy or refusal_accuracy falls below this

    @property
    def shipped_set(self) -> bool:
        return Path(self.paraphrases).resolve() == PARAPHRASES.resolve()

    def command(self) -> str:
        words = ["zsrm", "eval-goals"] + ([] if self.shipped_set else ["--paraphrases", self.paraphrases])
        return shlex.join(words + (["--out", str(self.out)] if self.out else []))

    def run(self) -> int:
        from zsrm.common.files import check_writable
        from zsrm.evaluation.goal_parsing import score_goals
        from zsrm.pipeline.measure import write_json

        if self.out:
            check_writable(self.out)
        result = score_goals(self.paraphrases)
        result["meta"] = {
            "command": self.command(),
            "paraphrases": "zsrm/tasks/paraphrases.json" if self.shipped_set else self.paraphrases,
            "metric": "accuracy: relation and ordered objects exactly right (a refusal counts as wrong); "
                      "refusal_accuracy: fraction of must-refuse sentences refused; wrong_task: sentences read as "
                      "another task",
            "machine": platform.platform(),
        }
        keys = ("accuracy", "refusal_accuracy", "understood", "refused", "wrong_task", "refusal_reason_accuracy")
        print(json.dumps({k: result[k] for k in keys}, indent=2))
        for failure in result["failures"]:
            print(f"  failure: {failure['text']!r} -> {failure['got']}", file=sys.stderr)
        if self.out:
            print(f"wrote {write_json(result, self.out)}")
        low = [k for k in ("accuracy", "refusal_accuracy") if not result[k] >= self.min_accuracy]
        if low:
            print(f"below {self.min_accuracy}: {', '.join(low)}", file=sys.stderr)
            return 1
        return 0

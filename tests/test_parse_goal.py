"""Goals as people write them (zsrm.tasks.language.parse_goal), the commands that read them
(zsrm parse-goal, zsrm eval-goals) and the entry points that take a goal."""
import json
import re

import pytest

from zsrm.cli import main
from zsrm.evaluation.goal_parsing import load_paraphrases, score_goals
from zsrm.rewards.binarised import ZSRMReward
from zsrm.tasks import RELATIONS, GoalError, Task, candidate_texts, parse_goal, resolve
from zsrm.tasks.language import REFUSAL_REASONS
from zsrm.tasks.lexicon import RELATION_WORDS

SET = load_paraphrases()
UNDERSTOOD = [e for e in SET["understood"] if e.get("batch", 1) == 1]


def test_the_paraphrase_set_covers_every_relation_and_every_refusal_kind():
    relations = {e["relation"] for e in SET["understood"]}
    assert relations == set(RELATIONS) and len(SET["understood"]) >= 150 and len(SET["refused"]) >= 30
    assert all(sum(e["relation"] == r for e in SET["understood"]) >= 15 for r in RELATIONS)
    for e in SET["understood"]:
        Task(e["relation"], tuple(e["objects"]), e.get("shape", "block"))  # a valid task
    assert {e["reason"] for e in SET["refused"]} <= set(REFUSAL_REASONS)
    assert {"unknown colour", "unknown object", "one object", "same object", "no relation"} <= {
        e["reason"] for e in SET["refused"]}


@pytest.mark.parametrize("entry", UNDERSTOOD, ids=lambda e: e["text"].strip()[:60])
def test_paraphrases_parse_both_ways(entry):
    task = parse_goal(entry["text"])
    assert (task.relation, list(task.objects), task.shape) == (entry["relation"], entry["objects"], entry["shape"])
    assert parse_goal(task.text) == task  # parse -> canonical text -> parse: the same task


@pytest.mark.parametrize("relation", sorted(RELATIONS))
@pytest.mark.parametrize("shape", ["block", "puck"])
def test_every_wording_of_every_relation_reads_as_that_relation(relation, shape):
    colours = ("green", "yellow", "red")[: RELATIONS[relation].arity]
    for words in RELATION_WORDS[relation]:
        rest = f"the {colours[1]} {shape}" + (f" and the {colours[2]} {shape}" if len(colours) == 3 else "")
        for text in (f"the {colours[0]} {shape} {words} {rest}", f"put the {colours[0]} one {words} {rest}"):
            assert parse_goal(text) == Task(relation, colours, shape), text


@pytest.mark.parametrize("text, relation, objects", [
    ("put the red block onto the yellow block", "on_top_of", ("red", "yellow")),
    ("stack the red block on the green one", "on_top_of", ("red", "green")),
    ("place the red block left of the green block", "left_of", ("red", "green")),
    ("move the blue block to the red block's right", "right_of", ("blue", "red")),
    ("put the green block on the yellow block's left side", "left_of", ("green", "yellow")),
    ("the blue puck should be near the yellow one", "close_to", ("blue", "yellow")),
    ("the red block under the blue block", "below", ("red", "blue")),
    ("put the red block into the blue block", "inside_of", ("red", "blue")),
    ("put the yellow block right next to the red block", "close_to", ("yellow", "red")),
    ("pick up the red block and put it on the blue block", "on_top_of", ("red", "blue")),
    ("the blue puck and the yellow puck next to each other", "close_to", ("blue", "yellow")),
    ("PUT  the Green cube,   in between the RED and blue cubes!!", "in_between", ("green", "red", "blue")),
])
def test_semantics_of_what_people_write(text, relation, objects):
    task = parse_goal(text)
    assert (task.relation, task.objects) == (relation, objects)


@pytest.mark.parametrize("text, reason, message, suggestion", [
    ("   ", "empty", "empty goal", None),
    ("don't put the red block on the blue block", "negation", "the goal says 'not'", None),
    ("put the purple block on the red block", "unknown colour",
     "unknown colour 'purple'; known colours: red, green, yellow, blue", None),
    ("put the gren block on the red block", "unknown colour", "unknown colour 'gren'",
     "a green block on top of a red block"),
    ("stack the red blok on the green block", "unknown object", "unknown object 'blok'; known objects: block, puck",
     "a red block on top of a green block"),
    ("put the red block on the table", "unknown object", "unknown object 'table'", None),
    ("put the block on the red block", "no colour", "'the block' names no colour", None),
    ("two blocks on the red block", "no colour", "'blocks' names no colour", None),
    ("push the blue puck next to the yellow block", "mixed objects", "objects of one kind, got block and puck",
     "a blue puck close to a yellow puck"),
    ("put the red block on the red one", "same object", "different objects, got the red one twice", None),
    ("stack the green block on top of itself", "same object", "the green block and itself", None),
    ("pick up the red block", "one object", "only one object (red block)", None),
    ("an inverted pendulum standing upright", "unknown object", "unknown object 'inverted pendulum'", None),
    ("move it to the left", "no object", "no coloured block or puck", None),
    ("move the red block to the blue block", "no relation",
     "no relation between the red block and the blue block ('to' is not one); known relations: on the left of", None),
    ("put the red block nxt to the blue block", "no relation", "no relation", "a red block close to a blue block"),
    ("swap the red and green blocks", "no relation", "no relation between the red and green blocks", None),
    ("put the red block between the blue block", "object count", "'in between' relates 3 objects, the goal names 2",
     None),
    ("put the red block on the blue block and then knock it over", "extra words",
     "words zsrm cannot read: 'and knock it over'", "a red block on top of a blue block"),
])
def test_refusals_say_what_is_wrong_in_one_line(text, reason, message, suggestion):
    with pytest.raises(GoalError, match=re.escape(message)) as info:
        parse_goal(text)
    err = info.value
    assert (err.reason, err.suggestion) == (reason, suggestion)
    assert "\n" not in str(err) and (suggestion is None or f"did you mean {suggestion!r}?" in str(err))


def test_refused_sentences_of_the_set_are_refused_for_their_reason():
    for e in SET["refused"]:
        with pytest.raises(GoalError) as info:
            parse_goal(e["text"])
        assert info.value.reason == e["reason"], e["text"]


@pytest.mark.parametrize("text", [
    "put the purple block\non the red block", "the red block " + "is " * 5000 + "the blue one",
    "x" * 100_000 + " block on the red block", "put the red block on it " + "qq " * 3000,
])
def test_a_long_or_broken_goal_is_still_one_short_line_of_error(text):
    with pytest.raises(GoalError) as info:
        parse_goal(text)
    assert "\n" not in str(info.value) and len(str(info.value)) < 600


def test_entry_points_take_what_parse_goal_reads(toy_vlm):
    entry = resolve("put the yellow block on the red one")
    assert (entry.env_id, entry.goal) == ("zsrm/Tabletop-v0", "a yellow block on top of a red block")
    assert resolve("push the blue puck next to the yellow one").env_id == "zsrm/Pushing-v0"
    reward = ZSRMReward(toy_vlm)
    assert reward.candidates("Stack the yellow cube onto the red cube.") == candidate_texts(
        "a yellow block on top of a red block")
    assert reward.goal_camera("the blue puck should be near the yellow one") == "tilted"
    with pytest.raises(GoalError, match="unknown colour 'pink'"):
        resolve("put the pink block on the red one")


def test_parse_goal_command_prints_the_reading(capsys):
    assert main(["parse-goal", "put", "the", "red", "block", "onto", "the", "yellow", "one"]) == 0
    out = capsys.readouterr().out
    assert "relation:  on_top_of" in out and "red, yellow" in out and "a red block on top of a yellow block" in out
    assert main(["parse-goal", "the blue puck should be near the yellow one", "--json"]) == 0
    reading = json.loads(capsys.readouterr().out)
    assert reading == {"text": "the blue puck should be near the yellow one", "relation": "close_to",
                       "objects": ["blue", "yellow"], "shape": "puck",
                       "canonical": "a blue puck close to a yellow puck", "scene": "pushing", "camera": "tilted"}


@pytest.mark.parametrize("text, message", [
    ("put the purple block on the red block", "unknown colour 'purple'"),
    ("pick up the red block", "only one object"),
    ("put the red block on the red block", "different objects"),
    ("the red block and the blue block", "no relation"),
])
def test_parse_goal_command_refuses_with_status_2_and_one_line(capsys, text, message):
    assert main(["parse-goal", text, "--json"]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert captured.out == "" and len(err) == 1 and "Traceback" not in err[0]
    assert err[0].startswith("zsrm parse-goal: error: cannot read") and message in err[0]


def test_eval_goals_writes_the_figures(tmp_path, capsys):
    out = tmp_path / "goals.json"
    assert main(["eval-goals", "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["accuracy"] >= 0.95 and result["refusal_accuracy"] >= 0.95 and result["wrong_task"] == 0
    assert result["understood"] == len(SET["understood"]) and result["refused"] == len(SET["refused"])
    assert result["meta"]["command"] == f"zsrm eval-goals --out {out}"
    assert len(result["failures"]) == round((1 - result["accuracy"]) * result["understood"]) + sum(
        f.get("only_the_reason_differs", False) for f in result["failures"]) + round(
        (1 - result["refusal_accuracy"]) * result["refused"])
    assert score_goals()["accuracy"] == result["accuracy"]


def test_eval_goals_fails_below_the_bar(tmp_path):
    bad = tmp_path / "set.json"
    bad.write_text(json.dumps({"understood": [{"text": "the red block and the blue block", "relation": "left_of",
                                               "objects": ["red", "blue"]}],
                               "refused": [{"text": "a red block on top of a blue block", "reason": "no relation"}]}))
    assert main(["eval-goals", "--paraphrases", str(bad)]) == 1
    assert score_goals(bad)["failures"][1]["got"] == {"relation": "on_top_of", "objects": ["red", "blue"],
                                                      "shape": "block"}

"""Goal sentences to tasks and back, and the errors users see."""
import pytest

from zsrm.tasks import RELATIONS, SINGLE_TASKS, TEST_TASKS, TRAIN_TASKS, GoalError, Task, parse_goal, resolve


@pytest.mark.parametrize("task", TRAIN_TASKS + TEST_TASKS, ids=lambda t: t.text)
def test_catalogue_tasks_round_trip(task):
    assert parse_goal(task.text) == task


@pytest.mark.parametrize("relation", sorted(RELATIONS))
def test_every_relation_round_trips(relation):
    colours = ("yellow", "red", "green")[: RELATIONS[relation].arity]
    for shape in ("block", "puck"):
        task = Task(relation, colours, shape)
        assert parse_goal(task.text) == task


@pytest.mark.parametrize("text, relation, objects", [
    ("a yellow block on the right of a red block", "right_of", ("yellow", "red")),
    ("A yellow block to the right of a red block.", "right_of", ("yellow", "red")),
    ("an image of a yellow object close to a blue object", "close_to", ("yellow", "blue")),
    ("a yellow block on top of a red block", "on_top_of", ("yellow", "red")),
    ("the green cube on the blue cube", "on_top_of", ("green", "blue")),
    ("a red block under a blue block", "below", ("red", "blue")),
    ("a red block between a blue block and a green block", "in_between", ("red", "blue", "green")),
    ("a red block in front of a blue block", "in_front_of", ("red", "blue")),
    ("a red block inside of a blue block", "inside_of", ("red", "blue")),
    ("a blue puck near a yellow puck", "close_to", ("blue", "yellow")),
])
def test_parse_wordings(text, relation, objects):
    task = parse_goal(text)
    assert (task.relation, task.objects) == (relation, objects)


def test_task_text_and_phrases():
    task = Task("right_of", ("yellow", "red"))
    assert task.text == "a yellow block on the right of a red block"
    assert task.phrases == ("yellow block", "red block")
    assert not task.has_container and Task("inside_of", ("yellow", "box")).has_container
    assert Task("close_to", ("blue", "yellow"), "puck").scene == "pushing"
    assert Task.from_text(task.text) == task


@pytest.mark.parametrize("text, message", [
    ("", "empty goal"),
    ("   ", "empty goal"),
    ("a purple block on top of a red block", "unknown colour 'purple'; known colours: red, green, yellow, blue"),
    ("a red sphere on top of a blue block", "unknown object 'sphere'; known objects"),
    ("a red block hovering over a blue block", "no relation .*known relations: on the left of"),
    ("a red block on top of a red block", "different objects"),
    ("a red puck on top of a blue block", "one kind"),
])
def test_bad_goals_get_clear_errors(text, message):
    with pytest.raises(GoalError, match=message):
        parse_goal(text)


def test_bad_tasks_get_clear_errors():
    with pytest.raises(GoalError, match="known relations"):
        Task("over", ("red", "blue"))
    with pytest.raises(GoalError, match="known colours"):
        Task("left_of", ("red", "pink"))
    with pytest.raises(GoalError, match="relates 3 objects"):
        Task("in_between", ("red", "blue"))
    with pytest.raises(GoalError):
        parse_goal(None)


def test_catalogue_matches_section_3_3():
    assert len(TRAIN_TASKS) == len(TEST_TASKS) == 18
    assert len(set(TRAIN_TASKS)) == len(set(TEST_TASKS)) == 18
    assert all("blue" not in t.objects for t in TRAIN_TASKS)
    assert all("blue" in t.objects for t in TEST_TASKS)
    assert {t.relation for t in TRAIN_TASKS} == {"on_top_of", "left_of", "right_of"}
    assert set(SINGLE_TASKS) == {"push_close", "stack", "place_right", "place_left", "place_below", "place_between",
                                 "place_front", "place_behind", "place_inside", "pendulum"}
    relations = {e.task.relation for e in SINGLE_TASKS.values() if e.task is not None}
    assert relations == set(RELATIONS)  # one task per relation of Table 1
    assert SINGLE_TASKS["stack"].task == Task("on_top_of", ("yellow", "red"))
    assert SINGLE_TASKS["pendulum"].task is None


def test_resolve_names_and_sentences():
    assert resolve("stack").env_id == "zsrm/Tabletop-v0"
    assert resolve("a blue puck close to a yellow puck").env_id == "zsrm/Pushing-v0"
    with pytest.raises(GoalError, match="catalogue task"):
        resolve("stakc")

"""Negative texts of the binarised reward (zsrm/tasks/negatives.py)."""
import numpy as np
import pytest

from zsrm.tasks.negatives import (IMPLIED_BY, SYMMETRIC, candidate_texts, negative_tasks, negative_texts,
                                         swapped_tasks)
from zsrm.tasks.language import GoalError, Task, parse_goal
from zsrm.tasks.relations import RELATIONS, WORLD_THRESHOLDS, holds_in_world

OBJECTS = ("yellow", "red", "green")


def task_of(relation, shape="block"):
    return Task(relation, OBJECTS[:RELATIONS[relation].arity], shape)


@pytest.mark.parametrize("relation", list(RELATIONS))
def test_every_relation_gets_negatives_over_the_same_objects(relation):
    task = task_of(relation)
    negatives = negative_tasks(task)
    texts = [t.text for t in negatives]
    assert len(negatives) >= 6
    assert len(set(texts)) == len(texts), "no duplicate negatives"
    assert task.text not in texts
    for neg in negatives:
        assert parse_goal(neg.text) == neg  # canonical sentences that read back
        assert set(neg.objects) <= set(task.objects) and neg.objects[0] in task.objects
        assert neg.relation != task.relation or neg.objects != task.objects
    # Every other relation of a formable arity appears over the goal's objects.
    other = {n.relation for n in negatives} - {task.relation}
    expected = {r for r, rel in RELATIONS.items() if r != task.relation and rel.arity <= len(task.objects)}
    assert other == expected - IMPLIED_BY.get(relation, set())


@pytest.mark.parametrize("relation", [r for r in RELATIONS if r not in SYMMETRIC])
def test_swapped_order_is_a_negative_for_asymmetric_relations(relation):
    task = task_of(relation)
    swapped = swapped_tasks(task)
    assert swapped and all(s.relation == relation and s.objects != task.objects for s in swapped)
    assert all(s in negative_tasks(task) for s in swapped)


def test_the_papers_example_swap():
    assert "a red block on top of a yellow block" in negative_texts("a yellow block on top of a red block")


def test_two_object_tasks_leave_out_in_between_and_three_object_tasks_use_pairs():
    assert not any(t.relation == "in_between" for t in negative_tasks(Task("left_of", ("red", "blue"))))
    three = negative_tasks(Task("in_between", ("yellow", "red", "green")))
    assert Task("on_top_of", ("yellow", "red")) in three and Task("on_top_of", ("yellow", "green")) in three
    # The equivalent outer-object order is not a negative; the other middles are.
    assert Task("in_between", ("yellow", "green", "red")) not in three
    assert Task("in_between", ("red", "yellow", "green")) in three


def test_candidates_start_with_the_canonical_goal():
    cands = candidate_texts("a yellow cube stacked on the red block")
    assert cands[0] == "a yellow block on top of a red block"
    assert cands[1:] == negative_texts(Task("on_top_of", ("yellow", "red")))


def test_puck_goals_keep_their_shape():
    assert all("puck" in t and "block" not in t for t in negative_texts("a blue puck close to a yellow puck"))


def test_non_spatial_goal_is_a_goal_error():
    with pytest.raises(GoalError):
        negative_texts("an inverted pendulum standing upright")


def _random_positions(rng, n):
    # Block centres over the table, some stacked, in metres.
    xyz = rng.uniform([-0.2, -0.15, 0.43], [0.2, 0.15, 0.55], (n, 3, 3))
    stacked = rng.random(n) < 0.3
    xyz[stacked, 0] = xyz[stacked, 1] + rng.normal(0, 0.01, (stacked.sum(), 3)) + (0, 0, 0.06)
    return xyz


def test_symmetric_set_matches_the_predicates():
    rng = np.random.default_rng(0)
    xyz = _random_positions(rng, 4000)
    for name, rel in RELATIONS.items():
        if rel.arity != 2:
            continue
        ab = holds_in_world(name, [xyz[:, 0], xyz[:, 1]])
        ba = holds_in_world(name, [xyz[:, 1], xyz[:, 0]])
        assert (ab == ba).all() == (name in SYMMETRIC), name


@pytest.mark.parametrize("relation", list(RELATIONS))
def test_no_negative_read_on_the_goals_camera_holds_whenever_the_goal_does(relation):
    """A negative equivalent to (or implied by) the goal on the camera the reward reads would tie
    with it: none is. (Relations of other cameras may co-hold, e.g. a stacked block is also
    "inside of" the lower one seen from the tilted camera; the reward scores every text on the
    goal camera's frame, where those captions never appear in training.)"""
    rng = np.random.default_rng(1)
    xyz = _random_positions(rng, 20000)
    task = task_of(relation)
    index = {c: i for i, c in enumerate(OBJECTS)}
    goal = holds_in_world(relation, [xyz[:, index[c]] for c in task.objects], WORLD_THRESHOLDS)
    assert goal.sum() > 20, "the sample must hold the goal often enough to test"
    camera = RELATIONS[relation].camera
    for neg in [n for n in negative_tasks(task) if RELATIONS[n.relation].camera == camera]:
        holds = holds_in_world(neg.relation, [xyz[:, index[c]] for c in neg.objects], WORLD_THRESHOLDS)
        assert holds[goal].mean() < 0.9, f"{neg.text} holds with {task.text}"


def test_close_to_ranks_against_its_complement_and_the_complement_against_it():
    close = "a blue puck close to a yellow puck"
    far = "a blue puck far from a yellow puck"
    assert negative_texts(close)[-1] == far
    assert candidate_texts(far) == [far, close]
    assert not any("far from" in t for r in RELATIONS if r != "close_to" for t in negative_texts(task_of(r)))

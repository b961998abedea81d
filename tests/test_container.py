"""The tabletop's open box: "inside of" as a task (scene, start states, oracle, script, goals)."""
import mujoco
import numpy as np
import pytest

from zsrm.envs.base import TABLE_TOP
from zsrm.envs.cameras import project
from zsrm.envs.rollout import make_env, run_episode
from zsrm.envs.scripted import scripted_controller
from zsrm.envs.tabletop import BLOCK_HALF, BOX_HALF, BOX_HALF_HEIGHT, TabletopEnv
from zsrm.tasks import SINGLE_TASKS, GoalError, Task, parse_goal
from zsrm.tasks.relations import WORLD_THRESHOLDS, holds_in_world


def _settle(env, n=15):
    for _ in range(n):
        env.step(np.array([0, 0, 0, -1.0]))


def test_the_box_is_in_the_scene_and_in_the_images():
    env = TabletopEnv("place_inside", cameras=("front", "left", "tilted"), image_size=64)
    obs, info = env.reset(seed=0)
    box = info["object_positions"]["box"]
    assert np.isclose(box[2], TABLE_TOP + BOX_HALF_HEIGHT) and env.over_table(box)
    x, row = np.round(project(env, "tilted", box + (0, 0, -BOX_HALF_HEIGHT), 64)).astype(int)
    assert obs["tilted"][row, x].min() > 180  # the box's light floor, seen from above
    assert env.action_space.shape == (4,)  # inside of is read on the tilted camera: full motion
    stack = TabletopEnv("stack", cameras=("tilted",), image_size=64)
    assert "box" not in stack.reset(seed=0)[1]["object_positions"]  # only where a goal names it
    env.close(), stack.close()


@pytest.mark.parametrize("spread", ["seen", "unseen"])
def test_the_block_never_starts_in_or_against_the_box(spread):
    env = TabletopEnv("place_inside", spread=spread, image_size=16)
    for seed in range(15):
        _, info = env.reset(seed=seed)
        pos = info["object_positions"]
        assert not info["is_success"] and not holds_in_world("inside_of", [pos["yellow"], pos["box"]])
        assert np.max(np.abs(pos["yellow"][:2] - pos["box"][:2])) > BOX_HALF + BLOCK_HALF
        assert abs(pos["yellow"][2] - (TABLE_TOP + BLOCK_HALF)) < 0.005  # resting on the table


def test_a_block_dropped_in_is_inside_and_one_beside_it_is_not():
    env = TabletopEnv("place_inside", image_size=16)
    env.reset(seed=1)
    box = env.object_positions()["box"]
    env._set_object("yellow", box + (0.01, -0.01, 0.08))  # above the box, off-centre: falls in
    _settle(env)
    yellow = env.object_positions()["yellow"]
    assert yellow[2] < TABLE_TOP + 2 * BOX_HALF_HEIGHT  # its bottom half below the walls' top
    assert env.oracle_success()
    beside = box + (BOX_HALF + BLOCK_HALF + 0.005, 0, BLOCK_HALF - BOX_HALF_HEIGHT)
    env._set_object("yellow", beside)
    _settle(env)
    assert not env.oracle_success()
    assert holds_in_world("close_to", [env.object_positions()["yellow"], box])  # close, but not inside
    assert WORLD_THRESHOLDS.inside < WORLD_THRESHOLDS.close / 4


def test_a_block_off_the_table_is_not_inside():
    env = TabletopEnv("place_inside", image_size=16)
    env.reset(seed=0)
    box = env.object_positions()["box"]
    env._set_object("yellow", (box[0], box[1], TABLE_TOP - 0.05))  # below the box, under the table top
    mujoco.mj_forward(env.model, env.data)
    assert holds_in_world("inside_of", [env.object_positions()["yellow"], box])  # Table 1 alone would say yes
    assert not env.oracle_success() and env.fell_off()


def test_the_scripted_controller_drops_the_block_into_the_box():
    env = make_env("place_inside", image_size=16)
    for seed in range(3):
        result = run_episode(env, scripted_controller, seed=seed)
        assert result["success"] and result["steps_in_goal"] > 30, seed
        pos = env.unwrapped.object_positions()
        assert pos["yellow"][2] < TABLE_TOP + 2 * BOX_HALF_HEIGHT  # in the box, not held above it


def test_exploration_scenes_can_hold_the_box_clear_of_the_blocks_or_with_one_in_it():
    env = TabletopEnv(task=None, objects=("red", "green", "box"), image_size=16)
    for seed in range(5):
        _, info = env.reset(seed=seed, options={"p_stack": 0.0, "p_side": 1.0})
        pos = info["object_positions"]
        assert all(np.max(np.abs(pos[c][:2] - pos["box"][:2])) > BOX_HALF + BLOCK_HALF for c in ("red", "green"))
    env = TabletopEnv(task=None, objects=("box", "red"), image_size=16)
    env.reset(seed=0, options={"p_stack": 1.0})  # red starts over the box's opening
    _settle(env)
    assert holds_in_world("inside_of", [env.object_positions()["red"], env.object_positions()["box"]])
    with pytest.raises(GoalError, match="known colours"):
        make_env("push_close", objects=("box",))


@pytest.mark.parametrize("text", [
    "put the red block into the box", "the red cube should be inside the box", "drop the red block in the box",
    "Place the red one in the container.", "a red block inside of a box",
])
def test_goals_with_the_box_read_as_inside_of_and_back(text):
    task = parse_goal(text)
    assert task == Task("inside_of", ("red", "box"))
    assert task.text == "a red block inside of a box" and task.phrases == ("red block", "box")
    assert parse_goal(task.text) == task
    assert SINGLE_TASKS["place_inside"].task == Task("inside_of", ("yellow", "box"))


@pytest.mark.parametrize("text, reason, message", [
    ("put the red block into the red box", "unknown object", "the box has no colour"),
    ("push the blue puck into the box", "mixed objects", "the box is on the tabletop"),
    ("put the box in the box", "same object", "got the box twice"),
    ("put the yellow block in the bowl", "unknown object", "unknown object 'bowl'"),
])
def test_goals_with_the_box_that_are_refused(text, reason, message):
    with pytest.raises(GoalError, match=message) as info:
        parse_goal(text)
    assert info.value.reason == reason
    with pytest.raises(GoalError, match="with blocks"):
        Task("inside_of", ("blue", "box"), "puck")

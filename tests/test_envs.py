"""The scenes: gymnasium/SB3 API checks, image-only observations, seeding, layouts, errors."""
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import zsrm.envs  # noqa: F401
from zsrm.envs import EPISODE_STEPS, PushingEnv, TabletopEnv
from zsrm.envs.base import TABLE_TOP
from zsrm.tasks import RELATIONS, GoalError, Task, holds_in_world

SCENES = [
    ("zsrm/Tabletop-v0", dict(task="stack", cameras=("front", "left", "tilted"))),
    ("zsrm/Tabletop-v0", dict(task="a red block behind a blue block", cameras=("left",))),
    ("zsrm/Pushing-v0", dict(cameras=("front", "tilted"))),
    ("zsrm/DoublePendulum-v0", dict()),
]


@pytest.mark.parametrize("env_id, kwargs", SCENES, ids=lambda x: str(x))
def test_gymnasium_and_sb3_checkers_pass(env_id, kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gym_check_env(gym.make(env_id, image_size=32, **kwargs).unwrapped)
        sb3_check_env(gym.make(env_id, image_size=32, **kwargs).unwrapped, warn=False)


def test_observations_are_images_only_and_info_has_the_oracle():
    env = gym.make("zsrm/Tabletop-v0", task="stack", cameras=("front", "tilted"), image_size=64)
    obs, info = env.reset(seed=3)
    assert set(obs) == {"front", "tilted"}
    assert all(o.shape == (64, 64, 3) and o.dtype == np.uint8 for o in obs.values())
    assert set(info) == {"object_positions", "oracle_reward", "is_success", "oracle_steps"}
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert reward == 0.0  # no environment reward ever reaches the agent
    assert info["oracle_reward"] in (0.0, 1.0)


@pytest.mark.parametrize("size", [64, 128])
def test_image_size_is_configurable(size):
    env = gym.make("zsrm/Pushing-v0", cameras=("left",), image_size=size)
    obs, _ = env.reset(seed=0)
    assert obs["left"].shape == (size, size, 3)


def _rollout(seed, n=5):
    env = gym.make("zsrm/Tabletop-v0", task="place_right", cameras=("front", "left", "tilted"), image_size=48)
    obs, _ = env.reset(seed=seed)
    frames = [obs]
    rng = np.random.default_rng(seed)
    for _ in range(n):
        obs, *_ = env.step(rng.uniform(-1, 1, env.action_space.shape))
        frames.append(obs)
    return frames


def test_same_seed_gives_the_same_images():
    a, b, c = _rollout(7), _rollout(7), _rollout(8)
    for fa, fb in zip(a, b):
        for cam in fa:
            np.testing.assert_array_equal(fa[cam], fb[cam])
    assert any(not np.array_equal(a[0][cam], c[0][cam]) for cam in a[0])


@pytest.mark.parametrize("relation", [r for r in RELATIONS if r != "inside_of"])
@pytest.mark.parametrize("spread", ["seen", "unseen"])
def test_objects_never_start_in_the_goal_relation(relation, spread):
    colours = ("yellow", "red", "green")[: RELATIONS[relation].arity]
    env = TabletopEnv(Task(relation, colours), spread=spread, image_size=16)
    for seed in range(15):
        _, info = env.reset(seed=seed)
        assert not info["is_success"]
        pos = info["object_positions"]
        assert not holds_in_world(relation, [pos[c] for c in colours])
        assert all(abs(p[2] - (TABLE_TOP + 0.03)) < 0.005 for p in pos.values())  # resting on the table


def test_unseen_spread_is_twice_the_seen_one():
    def starts(spread):
        env = TabletopEnv("stack", spread=spread, image_size=16)
        return np.array([env.reset(seed=s)[1]["object_positions"]["yellow"][0] for s in range(60)])

    seen, unseen = starts("seen"), starts("unseen")
    # Each side's nominal position +- one block width (seen) or two (unseen).
    assert np.abs(np.abs(seen) - 0.09).max() <= 0.03 + 1e-3
    assert np.abs(np.abs(unseen) - 0.09).max() > 0.03


def test_planar_tasks_use_the_front_plane_and_depth_tasks_use_3d():
    assert TabletopEnv("stack", image_size=16).action_space.shape == (3,)
    assert TabletopEnv("a red block in front of a blue block", image_size=16).action_space.shape == (4,)
    assert TabletopEnv("stack", action_mode="full", image_size=16).action_space.shape == (4,)
    assert PushingEnv(image_size=16).action_space.shape == (2,)


def test_gripper_grasps_lifts_and_releases_a_block():
    env = TabletopEnv("stack", image_size=16)
    env.reset(seed=0)
    yellow = env.object_positions()["yellow"]
    for _ in range(40):  # above the block, then down to grasp height
        target = yellow + (0, 0, 0.056)
        d = np.clip((target - env.gripper_position) / 0.03, -1, 1)
        env.step(np.array([d[0], d[2], -1.0]))
    env.step(np.array([0, 0, 1.0]))
    assert env.held == "yellow"
    for _ in range(5):
        env.step(np.array([0, 1.0, 1.0]))
    assert env.object_positions()["yellow"][2] > TABLE_TOP + 0.15  # lifted with the gripper
    for _ in range(20):
        env.step(np.array([0, 0, -1.0]))
    assert env.held is None
    assert env.object_positions()["yellow"][2] < TABLE_TOP + 0.04  # dropped back onto the table


def test_episode_ends_early_when_a_block_falls_off_the_table():
    env = gym.make("zsrm/Tabletop-v0", task="stack", image_size=16)
    env.reset(seed=0)
    base = env.unwrapped
    base._set_object("red", (0.6, 0.0, 0.5))  # beyond the table's edge
    terminated = False
    for _ in range(20):
        *_, terminated, truncated, _ = env.step(np.zeros(3))
        if terminated:
            break
    assert terminated


def test_episodes_last_100_steps():
    env = gym.make("zsrm/Pushing-v0", image_size=16)
    env.reset(seed=0)
    steps, done = 0, False
    while not done:
        *_, terminated, truncated, _ = env.step(np.zeros(2))
        steps += 1
        done = terminated or truncated
    assert steps == EPISODE_STEPS == 100 and truncated


def test_exploration_scene_has_the_requested_objects():
    env = TabletopEnv(task=None, objects=("red", "green", "blue"), cameras=("front", "left", "tilted"), image_size=16)
    _, info = env.reset(seed=1)
    assert sorted(info["object_positions"]) == ["blue", "green", "red"]
    assert not info["is_success"]


def test_exploration_objects_start_side_by_side_when_asked():
    """p_side=1 puts every object after the first beside one already placed (2-3 half-widths)."""
    env = PushingEnv(task=None, objects=("red", "blue"), image_size=16)
    h = env.object_half_size
    gaps = []
    for seed in range(10):
        _, info = env.reset(seed=seed, options={"p_side": 1.0})
        p = info["object_positions"]
        gaps.append(np.linalg.norm(p["red"][:2] - p["blue"][:2]))
    assert all(2.0 * h < g < 3.1 * h for g in gaps), gaps
    env.close()


def test_exploration_can_start_with_a_block_held_above_another():
    """p_hold=1: the gripper holds a block in the air over another, a hover that is sometimes
    "on top of" and mostly too high; the block stays held while the grip stays closed."""
    env = TabletopEnv(task=None, objects=("red", "green", "yellow"), image_size=16)
    rises, on_top = [], []
    for seed in range(12):
        _, info = env.reset(seed=seed, options={"p_hold": 1.0})
        if env.held is None:  # needs two blocks on the table with nothing stacked on them
            continue
        pos = info["object_positions"]
        held = pos[env.held]
        base = min((p for c, p in pos.items() if c != env.held), key=lambda p: np.linalg.norm(p[:2] - held[:2]))
        rises.append(held[2] - base[2])
        on_top.append(bool(holds_in_world("on_top_of", [held, base])))
        offset = held - env.gripper_position
        for _ in range(5):
            _, _, _, _, info = env.step(np.array([0.3, 0.0, 0.3, 1.0]))  # move with the grip closed
        assert np.allclose(info["object_positions"][env.held] - env.gripper_position, offset, atol=0.01)
    assert len(rises) >= 6 and min(rises) > 2 * 0.03 - 0.005 and max(rises) < 0.22
    assert not all(on_top)  # most hover too high to count
    _, _ = env.reset(seed=0)  # the default never holds
    assert env.held is None
    env.close()


def test_exploration_can_hold_a_block_high_anywhere_in_reach():
    """p_hold_free=1: every held block is high above the others (5 half-widths up or more) and
    within the gripper's reach, and stays held; p_hold alone keeps its random stream."""
    from zsrm.envs.tabletop import X_RANGE

    env = TabletopEnv(task=None, objects=("red", "green", "yellow"), image_size=16)
    held = 0
    for seed in range(8):
        _, info = env.reset(seed=seed, options={"p_hold": 1.0, "p_hold_free": 1.0})
        if env.held is None:
            continue
        held += 1
        pos = info["object_positions"]
        others = [p[2] for c, p in pos.items() if c != env.held]
        assert pos[env.held][2] > max(others) + 0.06 and X_RANGE[0] <= pos[env.held][0] <= X_RANGE[1]
        offset = pos[env.held] - env.gripper_position
        for _ in range(3):
            _, _, _, _, info = env.step(np.array([-0.3, 0.0, 0.0, 1.0]))
        assert np.allclose(info["object_positions"][env.held] - env.gripper_position, offset, atol=0.01)
    assert held >= 4
    a, _ = env.reset(seed=3, options={"p_hold": 1.0})
    b, _ = env.reset(seed=3, options={"p_hold": 1.0, "p_hold_free": 0.0})
    assert np.array_equal(a["front"], b["front"])
    env.close()


def test_bad_input_gets_clear_errors():
    with pytest.raises(ValueError, match="known cameras: front, left, tilted"):
        TabletopEnv("stack", cameras=("top",))
    with pytest.raises(ValueError, match="image_size"):
        TabletopEnv("stack", image_size=3)
    with pytest.raises(ValueError, match="spread"):
        TabletopEnv("stack", spread="wide")
    with pytest.raises(GoalError, match="this scene has blocks"):
        TabletopEnv("a blue puck close to a yellow puck")
    with pytest.raises(GoalError, match="known colours"):
        TabletopEnv("a pink block on top of a red block")
    with pytest.raises(GoalError, match="known colours"):
        TabletopEnv(task=None, objects=("red", "pink"))
    env = TabletopEnv("stack", image_size=16)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action must have shape"):
        env.step(np.zeros(5))


@pytest.mark.parametrize("env_id,task", [("zsrm/Tabletop-v0", "stack"), ("zsrm/Pushing-v0", "push_close")])
def test_table_homography_inverts_the_tilted_projection(env_id, task):
    from zsrm.envs.cameras import apply_homography, project, table_homography

    env = gym.make(env_id, task=task)
    _, info = env.reset(seed=3)
    h = table_homography(env, "tilted", 64)
    for xyz in info["object_positions"].values():
        xy = apply_homography(h, project(env.unwrapped, "tilted", xyz, 64))
        np.testing.assert_allclose(xy, xyz[:2], atol=1e-4)  # 0.1 mm: objects settle slightly
    env.close()

"""Scene faults that matter for learning: the grip a noisy agent can hold, blocks that are not
thrown, a fallen object that satisfies nothing, a pusher that cannot shove pucks off, and
action repeat that keeps the 100-step oracle metric."""
import gymnasium as gym
import numpy as np
import pytest

import zsrm.envs  # noqa: F401
from zsrm.envs import pushing
from zsrm.envs.base import MAX_OBJECT_SPEED, TABLE_HALF_X, TABLE_HALF_Y, TABLE_TOP
from zsrm.envs.pushing import PushingEnv
from zsrm.envs.tabletop import GRIP_CLOSE, GRIP_OPEN, TabletopEnv


def _grasp_yellow(env: TabletopEnv):
    yellow = env.object_positions()["yellow"]
    for _ in range(40):
        d = np.clip((yellow + (0, 0, 0.056) - env.gripper_position) / 0.03, -1, 1)
        env.step(np.array([d[0], d[2], -1.0]))
    env.step(np.array([0, 0, 1.0]))
    assert env.held == "yellow"


def test_grip_keeps_its_state_between_the_thresholds():
    env = TabletopEnv("stack", image_size=16)
    env.reset(seed=0)
    _grasp_yellow(env)
    for grip in (0.0, GRIP_CLOSE - 0.01, GRIP_OPEN + 0.01, -0.5):
        env.step(np.array([0, 0.5, grip]))
        assert env.held == "yellow", f"a grip command of {grip} dropped the block"
    env.step(np.array([0, 0, GRIP_OPEN - 0.01]))
    assert env.held is None


def test_random_grip_commands_hold_a_block_for_several_steps():
    env = TabletopEnv("stack", image_size=16)
    env.reset(seed=0)
    _grasp_yellow(env)
    rng = np.random.default_rng(0)
    held = 0
    while env.held and held < 50:
        env.step(np.array([0, 0, rng.uniform(-1, 1)]))
        held += 1
    assert held >= 3  # a plain sign test released it after about one step


@pytest.mark.parametrize("seed", range(5))
def test_start_around_puts_open_fingers_around_the_block_one_close_grasps(seed):
    env = TabletopEnv("stack", image_size=16, start="around")
    env.reset(seed=seed)
    assert env.held is None and not env.closed  # the fingers start open
    env.step(np.array([0, 0, 1.0]))
    assert env.held == "yellow"
    with pytest.raises(ValueError, match="start"):
        TabletopEnv("stack", image_size=16, start="inside")


def test_lift_ceiling_keeps_the_gripper_and_its_block_low():
    env = TabletopEnv("place_between", image_size=16, lift_ceiling=0.18)
    env.reset(seed=0)
    assert env.gripper_position[2] <= TABLE_TOP + 0.18 + 1e-3  # the start is under it too
    _grasp_yellow(env)
    for _ in range(20):
        env.step(np.array([0, 1.0, 1.0]))
    assert env.held == "yellow"
    assert env.gripper_position[2] == pytest.approx(TABLE_TOP + 0.18, abs=2e-3)
    free = TabletopEnv("place_between", image_size=16)
    free.reset(seed=0)
    for _ in range(20):
        free.step(np.array([0, 1.0, -1.0]))
    assert free.gripper_position[2] > TABLE_TOP + 0.3  # without it, the workspace's top
    with pytest.raises(ValueError, match="lift_ceiling"):
        TabletopEnv("place_between", image_size=16, lift_ceiling=0.5)


def test_lift_ceiling_reaches_the_tabletop_envs_and_is_written_only_when_set():
    from zsrm.rl.config import TrainConfig
    from zsrm.rl.envs import make_vec

    assert "lift_ceiling" not in TrainConfig(goal="place_between").to_dict()
    cfg = TrainConfig(goal="place_between", lift_ceiling=0.18)
    assert cfg.to_dict()["lift_ceiling"] == 0.18
    venv = make_vec(cfg, 1, seed=0)
    assert venv.envs[0].unwrapped.z_max == pytest.approx(TABLE_TOP + 0.18)
    venv.close()
    with pytest.raises(ValueError, match="tabletop"):
        make_vec(TrainConfig(goal="push_close", lift_ceiling=0.18), 1, seed=0)
    with pytest.raises(ValueError, match="lift_ceiling"):
        TrainConfig(goal="place_between", lift_ceiling=-0.1)


def test_start_is_written_only_when_changed():
    """Runs committed before the start setting existed keep matching their configuration."""
    from zsrm.rl.config import TrainConfig

    place = TrainConfig(goal="place_right")
    assert place.start == "above" and "start" not in place.to_dict() and "start" not in place.identity()
    assert TrainConfig(goal="place_right", start="around").to_dict()["start"] == "around"
    # stacking goals start around the block unless told otherwise, and say so in their config
    assert TrainConfig(goal="a red block on top of a green block").to_dict()["start"] == "around"
    assert TrainConfig.from_dict({**TrainConfig(goal="stack").to_dict(), "start": "above"}).start == "above"
    with pytest.raises(ValueError, match="not a tabletop task"):
        from zsrm.rl.envs import make_vec

        make_vec(TrainConfig(goal="push_close", start="around"), 1, 0)


@pytest.mark.parametrize("task", ["stack", "push_close"])
def test_random_actions_never_throw_objects(task):
    env = gym.make("zsrm/Tabletop-v0" if task == "stack" else "zsrm/Pushing-v0", task=task, image_size=16)
    base = env.unwrapped
    rng = np.random.default_rng(1)
    fastest = 0.0
    for ep in range(5):
        env.reset(seed=ep)
        for _ in range(100):
            *_, terminated, truncated, _ = env.step(rng.uniform(-1, 1, env.action_space.shape))
            for colour in base.objects:
                adr = base.model.jnt_dofadr[base.model.body_jntadr[base._body(colour)]]
                fastest = max(fastest, float(np.linalg.norm(base.data.qvel[adr:adr + 3])))
            if terminated or truncated:
                break
    assert fastest <= MAX_OBJECT_SPEED + 1e-6


def test_an_object_off_the_table_satisfies_no_relation():
    env = TabletopEnv("place_right", image_size=16)
    env.reset(seed=0)
    red = env.object_positions()["red"]
    env._set_object("yellow", (TABLE_HALF_X + 0.05, 0.0, TABLE_TOP + 0.03))  # right of red, but off the table
    import mujoco
    mujoco.mj_forward(env.model, env.data)
    assert env.object_positions()["yellow"][0] > red[0]
    assert not env.oracle_success()
    assert env.fell_off()
    env._set_object("yellow", (red[0] + 0.1, 0.0, TABLE_TOP + 0.03))  # on the table, right of red
    mujoco.mj_forward(env.model, env.data)
    assert env.oracle_success() and not env.fell_off()


def test_pusher_cannot_reach_past_the_table_edge_with_a_puck():
    reach_x = pushing.X_RANGE[1] + 0.02 + 2 * pushing.PUCK_HALF
    reach_y = pushing.Y_RANGE[1] + 0.02 + 2 * pushing.PUCK_HALF
    assert reach_x < TABLE_HALF_X and reach_y < TABLE_HALF_Y
    env = PushingEnv(image_size=16)
    env.reset(seed=0)
    for _ in range(40):
        env.step(np.array([1.0, 1.0]))
    p = env.pusher_position
    assert p[0] <= pushing.X_RANGE[1] + 0.005 and p[1] <= pushing.Y_RANGE[1] + 0.005


def test_action_repeat_counts_every_control_step_of_the_episode():
    env = gym.make("zsrm/Pushing-v0", image_size=16, action_repeat=4, max_episode_steps=25)
    env.reset(seed=0)
    steps, counted, done = 0, 0, False
    while not done:
        _, _, terminated, truncated, info = env.step(np.zeros(2, np.float32))
        assert 0 <= info["oracle_steps"] <= 4
        counted += info["oracle_steps"]
        steps += 1
        done = terminated or truncated
    assert steps == 25
    with pytest.raises(ValueError, match="action_repeat"):
        PushingEnv(image_size=16, action_repeat=0)


def test_objects_with_a_task_are_distractors_that_leave_the_goal_alone():
    from zsrm.envs.rollout import make_env, run_episode
    from zsrm.envs.scripted import scripted_controller

    env = make_env("stack", image_size=32, objects=("yellow", "red", "green", "blue"))
    base = env.unwrapped
    assert base.objects == ("yellow", "red", "green", "blue") and base.distractors == ("green", "blue")
    _, info = env.reset(seed=0)
    pos = info["object_positions"]
    assert set(pos) == {"yellow", "red", "green", "blue"}
    for colour in ("green", "blue"):  # behind the strip the goal's blocks start and move in
        assert pos[colour][1] > 0.12 and pos[colour][2] < TABLE_TOP + 0.05
    assert run_episode(env, scripted_controller, seed=0)["success"]  # the goal is still reachable
    with pytest.raises(Exception, match="unknown colour"):
        make_env("stack", image_size=32, objects=("yellow", "purple"))


def test_the_zsrm_reward_on_a_scene_with_a_distractor():
    from zsrm.envs.rollout import episode_steps, make_env
    from zsrm.envs.scripted import scripted_controller
    from zsrm.fullmodel import load_reward_backbone
    from zsrm.rewards import ZSRMReward

    reward = ZSRMReward(load_reward_backbone("student"))
    goal = "a yellow block on top of a red block"
    env = make_env("stack", objects=("yellow", "red", "green"))
    frames, truth = [], []
    for t, obs, info, _ in episode_steps(env, scripted_controller, seed=3):
        frames.append(obs["front"])
        truth.append(info["is_success"])
    rewards = reward({"front": np.stack(frames)}, goal)
    assert rewards[0] == 0 and truth[-1] and rewards[-1] == 1  # 0 at the start, 1 once stacked
    assert (rewards == np.array(truth)).mean() > 0.85


@pytest.mark.parametrize("spread", ["seen", "unseen"])
def test_push_close_starts_apart_with_the_pusher_clear_behind_the_mover(spread):
    env = PushingEnv(task="push_close", image_size=16, spread=spread)
    for seed in range(40):
        env.reset(seed=seed)
        mover, anchor = (env.object_positions()[c] for c in env.task.objects[:2])
        pusher = env.pusher_position
        assert np.linalg.norm(mover[:2] - anchor[:2]) > 0.10  # not yet close (Table 1: 10 cm)
        assert np.linalg.norm(pusher[:2] - mover[:2]) >= pushing.PUCK_HALF + 0.02 - 1e-6  # not inside the puck
        assert np.sign(pusher[0] - mover[0]) == np.sign(mover[0] - anchor[0])  # behind it, away from the anchor


@pytest.mark.parametrize("task", ["a red block on the left of a green block", "a yellow block on top of a red block"])
def test_a_scene_mirrored_left_to_right_renders_as_the_front_frame_flipped(task):
    """What ``zsrm distill --mirror`` relies on: the tabletop and its front camera are symmetric
    about x = 0, so the flipped frame is the frame of the mirrored scene."""
    import mujoco

    env = gym.make("zsrm/Tabletop-v0", task=task)
    obs, _ = env.reset(seed=1)
    rng = np.random.default_rng(1)
    for _ in range(10):
        obs, *_ = env.step(rng.uniform(-1, 1, 3).astype(np.float32))
    base = env.unwrapped
    model, data = base.model, base.data
    for j in np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE):
        adr = model.jnt_qposadr[j]
        data.qpos[adr] *= -1  # x, and the quaternion's y and z: a reflection through the x = 0 plane
        data.qpos[adr + 5:adr + 7] *= -1
    data.mocap_pos[:, 0] *= -1
    mujoco.mj_forward(model, data)
    mirrored = base.render_cameras(("front",))["front"].astype(int)
    frame = obs["front"].astype(int)
    differs = lambda a, b: (np.abs(a - b).max(-1) > 10).mean()
    # A few edge pixels of the gripper's rod differ (under 1%); the unflipped frame differs at ~8%.
    assert differs(mirrored, frame[:, ::-1]) < 0.01 < 0.05 < differs(mirrored, frame)
    env.close()


def test_near_start_draws_nearer_pucks_for_training_envs_only():
    from zsrm.rl.config import TrainConfig
    from zsrm.rl.envs import make_vec

    def gaps(env, seeds=range(30)):
        out = []
        for seed in seeds:
            env.reset(seed=seed)
            mover, anchor = (env.object_positions()[c] for c in env.task.objects[:2])
            out.append(abs(mover[0] - anchor[0]))
        return np.array(out)

    w = 2 * pushing.PUCK_HALF
    near, far = gaps(PushingEnv(task="push_close", image_size=16, near_start=0.8)), gaps(PushingEnv(image_size=16))
    assert near.mean() < far.mean() - 0.5 * w  # the gap is drawn in [0.8, 1.7] widths, not fixed at 1.7
    assert "near_start" not in TrainConfig(goal="push_close").to_dict()
    cfg = TrainConfig(goal="push_close", near_start=0.8)
    assert make_vec(cfg, 1, 0, training=True).envs[0].unwrapped.near_start == 0.8
    assert make_vec(cfg, 1, 0).envs[0].unwrapped.near_start is None  # evaluation starts as the scene does
    with pytest.raises(ValueError, match="near_start"):
        TrainConfig(goal="push_close", near_start=2.0)
    for training in (True, False):  # evaluation's envs refuse it too
        with pytest.raises(ValueError, match="pushing"):
            make_vec(TrainConfig(goal="stack", near_start=0.8), 1, 0, training=training)

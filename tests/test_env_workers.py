"""The training envs stepped by worker processes (``zsrm train --env-workers``): the same
numbers as one process, step by step and for a whole run, a run resumed from its checkpoint
included."""
import shutil

import numpy as np
import pytest

from zsrm.rl import TrainConfig, train
from zsrm.rl.envs import make_vec
from zsrm.rl.ppo import auto_env_workers
from zsrm.rl.workers import WorkerVecEnv

TINY = dict(n_envs=3, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=2, keypoints=4, image_size=32)


def test_workers_step_the_envs_as_one_process_does():
    cfg = TrainConfig(goal="push_close", reward="oracle", **TINY)
    one, split = make_vec(cfg, 3, seed=7), make_vec(cfg, 3, seed=7, workers=2)
    try:
        assert isinstance(split, WorkerVecEnv) and [list(g) for g in split.groups] == [[0, 1], [2]]
        assert split.observation_space == one.observation_space and split.action_space == one.action_space
        a, b = one.reset(), split.reset()
        assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
        rng = np.random.default_rng(0)
        for _ in range(30):  # 25 decisions an episode: one reset of every env on the way
            actions = rng.uniform(-1, 1, (3, *one.action_space.shape)).astype(np.float32)
            (oa, ra, da, ia), (ob, rb, db, ib) = one.step(actions), split.step(actions)
            assert all(np.array_equal(oa[k], ob[k]) for k in oa)
            assert np.array_equal(ra, rb) and np.array_equal(da, db)
            for x, y in zip(ia, ib):
                assert x.keys() == y.keys() and x.get("oracle_steps") == y.get("oracle_steps")
                if "terminal_observation" in x:
                    assert all(np.array_equal(x["terminal_observation"][k], y["terminal_observation"][k]) for k in oa)
        assert split.get_attr("spec", indices=[2])[0].id == one.get_attr("spec", indices=[2])[0].id
        assert len(split.env_states()) == 3
    finally:
        one.close()
        split.close()


def test_a_run_with_two_env_workers_is_the_run_with_one_and_resumes_to_it(tmp_path):
    from test_rl import eval_rows, kill_after_first_checkpoint, same_weights

    # rollouts of 3 envs x 8 decisions x action repeat 4 = 96 env steps: a checkpoint after each
    cfg = TrainConfig(goal="push_close", reward="oracle", steps=384, eval_every=192, checkpoint_every=96,
                      **{**TINY, "n_steps": 8, "batch_size": 24})
    one = train(cfg, tmp_path / "one", progress=False, env_workers=1)
    two = train(cfg, tmp_path / "two", progress=False, env_workers=2)
    assert two["final_episode_rewards"] == one["final_episode_rewards"]
    assert eval_rows(tmp_path / "two" / "eval.csv") == eval_rows(tmp_path / "one" / "eval.csv")
    assert same_weights(tmp_path / "two" / "policy" / "model.safetensors", tmp_path / "one" / "policy" / "model.safetensors")
    # killed after its first checkpoint with two workers, resumed with one and with two
    cut = tmp_path / "cut"
    assert 0 < kill_after_first_checkpoint(cfg.to_dict(), cut, env_workers=2) < 384
    shutil.copytree(cut, tmp_path / "cut2")
    for folder, workers in ((cut, 1), (tmp_path / "cut2", 2)):
        resumed = train(cfg, folder, progress=False, env_workers=workers)
        assert resumed["final_episode_rewards"] == one["final_episode_rewards"], workers
        assert eval_rows(folder / "eval.csv") == eval_rows(tmp_path / "one" / "eval.csv")
        assert same_weights(folder / "policy" / "model.safetensors", tmp_path / "one" / "policy" / "model.safetensors")


@pytest.mark.parametrize("n_envs, cores, workers", [(16, 2, 2), (16, 1, 1), (4, 2, 1), (16, 8, 2)])
def test_a_lone_run_steps_its_scenes_in_two_processes_when_it_has_the_cores(monkeypatch, n_envs, cores, workers):
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: set(range(cores)))
    assert auto_env_workers(TrainConfig(n_envs=n_envs)) == workers

"""zsrm sweep: trials on a local Ray, killed and resumed, finished trials skipped, gathered."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from zsrm.rl.sweep import gather, is_finished, keep_trial_summaries, start_ray, trial_grid

TINY = dict(steps=512, n_envs=2, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=2, keypoints=4,
            eval_every=128, checkpoint_every=128)


def test_trial_grid_names_and_configs():
    grid = trial_grid(["stack", "push_close"], ["oracle"], [0, 1], {"steps": 1000})
    assert [t["name"] for t in grid] == ["stack-oracle-0", "push_close-oracle-0", "stack-oracle-1",
                                         "push_close-oracle-1"]  # seed-major
    assert all(t["config"]["steps"] == 1000 for t in grid)


def test_two_trial_sweep_is_killed_and_resumed(tmp_path):
    code = ("import json, sys; from zsrm.rl.sweep import sweep; "
            "sweep(sys.argv[1], ['push_close'], ['oracle'], [0, 1], json.loads(sys.argv[2]), num_cpus=2)")
    args = [sys.executable, "-c", code, str(tmp_path), json.dumps(TINY)]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(args, env=env, start_new_session=True)
    states = [tmp_path / f"push_close-oracle-{s}" / "checkpoint" / "state.json" for s in (0, 1)]
    deadline = time.time() + 600
    while not any(p.is_file() for p in states) and proc.poll() is None and time.time() < deadline:
        time.sleep(0.5)
    os.killpg(proc.pid, signal.SIGKILL)  # the driver, Ray and its workers
    proc.wait()
    assert any(p.is_file() for p in states), "no trial wrote a checkpoint before the kill"
    assert not all((tmp_path / f"push_close-oracle-{s}" / "summary.json").is_file() for s in (0, 1))

    subprocess.run(args, env=env, check=True, timeout=900)  # resume
    names = [t["name"] for t in trial_grid(["push_close"], ["oracle"], [0, 1], TINY)]
    for t in trial_grid(["push_close"], ["oracle"], [0, 1], TINY):
        assert is_finished(tmp_path / t["name"], t["config"])
        assert json.loads((tmp_path / t["name"] / "summary.json").read_text())["env_steps"] == 512

    mtimes = [(tmp_path / n / "summary.json").stat().st_mtime_ns for n in names]
    subprocess.run(args, env=env, check=True, timeout=300)  # all finished: nothing runs again
    assert mtimes == [(tmp_path / n / "summary.json").stat().st_mtime_ns for n in names]

    kept = keep_trial_summaries(tmp_path, tmp_path / "kept", trial_grid(["push_close"], ["oracle"], [0, 1], TINY))
    summary = gather(kept)
    result = summary["push_close"]["oracle"]
    assert result["seeds"] == 2 and result["steps"] == 512
    assert [row["env_steps"] for row in result["curve"]] == [128, 256, 384, 512]


class SlowRay:
    """A stand-in for the ray module whose local node times out ``slow`` times before it starts."""

    def __init__(self, slow: int, message: str = "The current node timed out during startup."):
        self.slow, self.message, self.inits, self.shutdowns = slow, message, 0, 0

    def init(self, **kwargs):
        self.inits += 1
        if self.inits <= self.slow:
            raise Exception(self.message)

    def shutdown(self):
        self.shutdowns += 1


def test_a_ray_that_starts_slowly_is_tried_again():
    ray = SlowRay(slow=2)
    start_ray(ray, num_cpus=2, address=None)
    assert ray.inits == 3 and ray.shutdowns == 2
    with pytest.raises(Exception, match="timed out during startup"):
        start_ray(SlowRay(slow=3), num_cpus=2, address=None)
    other = SlowRay(slow=1, message="no such cluster")
    with pytest.raises(Exception, match="no such cluster"):  # other failures are not retried
        start_ray(other, num_cpus=2, address="ray://nowhere:10001")
    assert other.inits == 1


def test_gather_keeps_both_ways_of_acting_and_the_core_hours():
    def run(seed, mean, sampled, wall_s):
        return {"config": {"goal": "stack", "reward": "zsrm", "seed": seed}, "env_steps": 300, "wall_s": wall_s,
                "final_mean": mean[0], "final_se": 1.0, "final_success_rate": mean[1], "curve": [],
                "final_by_actions": {"mean": {"mean": mean[0], "se": 1.0, "success_rate": mean[1]},
                                     "sampled": {"mean": sampled[0], "se": 1.0, "success_rate": sampled[1]}}}

    cell = gather([run(0, (90.0, 1.0), (80.0, 0.8), 1800.0), run(1, (70.0, 0.6), (60.0, 0.4), 1800.0)])["stack"]["zsrm"]
    assert cell["core_hours"] == 1.0
    assert cell["final_by_actions"]["mean"] == {"final_mean": 80.0, "final_se": 10.0, "final_success_rate": 0.8}
    assert cell["final_by_actions"]["sampled"]["final_mean"] == 70.0
    assert cell["final_by_actions"]["sampled"]["final_success_rate"] == pytest.approx(0.6)
    older = run(2, (50.0, 0.5), (50.0, 0.5), 3600.0)
    del older["final_by_actions"]  # a run from before both were recorded: the cell has only final_*
    assert "final_by_actions" not in gather([run(0, (90.0, 1.0), (80.0, 0.8), 1800.0), older])["stack"]["zsrm"]


def test_settings_reach_every_trial_and_the_recorded_command():
    from zsrm.pipeline.learn import Sweep

    sweep = Sweep(tasks=("place_between",), rewards=("zsrm", "oracle"), seeds=(0,), root="runs/x",
                  settings=("zsrm-correct-every=5000", "gamma=0.99"))
    configs = {t["name"]: t["config"] for t in sweep.trials()}
    assert configs["place_between-zsrm-0"]["zsrm_correct_every"] == 5000
    assert configs["place_between-oracle-0"]["gamma"] == 0.99
    assert "zsrm_correct_every" not in configs["place_between-oracle-0"]  # only the zsrm reward reads it
    command = sweep.meta(1, 2)["command"]
    assert "--settings zsrm-correct-every=5000 gamma=0.99" in command and "--root runs/x" in command
    with pytest.raises(ValueError, match="KEY=VALUE with KEY a zsrm train setting"):
        Sweep(settings=("no-such-setting=1",)).overrides()


def test_the_per_task_preset_gives_each_task_its_own_learner():
    from zsrm.pipeline.learn import Sweep, Train, with_preset

    sweep = Sweep(config="per-task", tasks=("push_close", "place_between", "place_behind", "stack"),
                  rewards=("zsrm", "oracle"), seeds=(0,))
    configs = {t["name"]: t["config"] for t in sweep.trials()}
    assert configs["push_close-zsrm-0"]["learner"] == "sac" and configs["push_close-zsrm-0"]["steps"] == 500_000
    assert configs["place_between-zsrm-0"]["zsrm_correct_every"] == 10_000
    assert "zsrm_correct_every" not in configs["place_between-oracle-0"]  # only the zsrm reward is corrected
    assert configs["place_behind-oracle-0"]["steps"] == 500_000 and "learner" not in configs["place_behind-oracle-0"]
    assert configs["stack-zsrm-0"] == Sweep(tasks=("stack",), rewards=("zsrm",), seeds=(0,)).trials()[0]["config"]
    assert "--steps" not in sweep.meta(1, 8)["command"]  # each task's budget is the preset's
    tiny = {t["name"]: t["config"]["steps"] for t in Sweep(config="per-task", tasks=("push_close", "stack"),
                                                           rewards=("oracle",), seeds=(0,), steps=2048).trials()}
    assert tiny == {"push_close-oracle-0": 2048, "stack-oracle-0": 2048}  # a budget given holds for every task
    # zsrm train --config per-task reads the goal's entry; a setting given on the command line wins
    assert with_preset(Train(goal="push_close"), "per-task").learner == "sac"
    assert with_preset(Train(goal="place_front", reward="zsrm", zsrm_correct_every=5000),
                       "per-task").zsrm_correct_every == 5000
    assert with_preset(Train(goal="stack"), "per-task") == with_preset(Train(goal="stack"), "cpu")
    # by the goal's relation: any push goal is SAC's; an own scene's goals take the default
    assert with_preset(Train(goal="a blue puck close to a yellow puck"), "per-task").learner == "sac"
    own = Sweep(config="per-task", tasks=("a red cylinder behind a purple cylinder",), rewards=("oracle",), seeds=(0,),
                scene="examples.own_scene.adapter:OwnScene").trials()[0]["config"]
    assert own["steps"] == 300_000


def test_a_sweep_keeps_its_trials_where_trials_dir_says_and_the_canonical_file_matches_the_preset(tmp_path):
    import shutil

    from zsrm.pipeline.learn import Sweep

    results = Path(__file__).resolve().parents[1] / "results" / "rl"
    kept = results / "per-task" / "trials"
    for name in ("place_inside-random-0", "place_inside-oracle-0"):  # as the sweep's root would hold them
        (tmp_path / "root" / name).mkdir(parents=True)
        shutil.copy(kept / f"{name}.json", tmp_path / "root" / name / "summary.json")
    sweep = Sweep(tasks=("place_inside",), rewards=("oracle", "random"), seeds=(0,), config="per-task",
                  root=str(tmp_path / "root"), out=str(tmp_path / "out" / "learning.json"),
                  trials_dir=str(tmp_path / "kept"), gather_only=True)
    assert sweep.run() == 0
    assert sorted(p.name for p in (tmp_path / "kept").iterdir()) == ["place_inside-oracle-0.json",
                                                                    "place_inside-random-0.json"]
    assert not (tmp_path / "out" / "trials").exists()
    result = json.loads((tmp_path / "out" / "learning.json").read_text())
    assert f"--trials-dir {tmp_path / 'kept'}" in result["meta"]["command"]
    committed = json.loads((results / "learning.json").read_text())
    assert result["place_inside"]["oracle"]["final_mean"] == committed["place_inside"]["oracle"]["final_per_seed"][0]

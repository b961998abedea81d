"""Reward along a scripted trajectory (Figure 5): recording, scoring, table and plot."""
import csv

import numpy as np
import pytest

from zsrm.rewards import BaseReward, OracleReward
from zsrm.evaluation.curves import plot_curve, record_trajectory, reward_curve, summarise, write_csv

GOAL = "a yellow puck close to a blue puck"


@pytest.fixture(scope="module")
def trajectory():
    return record_trajectory(GOAL, cameras=("tilted", "front"), steps=30, seed=0, image_size=32)


def test_scripted_push_brings_yellow_to_blue(trajectory):
    d = trajectory.distances
    assert trajectory.objects == ("yellow", "blue")
    assert trajectory.observations["tilted"].shape == (len(trajectory), 32, 32, 3)
    assert d[0] > 0.2 and d[-1] < 0.08  # metres: from far apart to touching
    assert trajectory.infos[-1]["is_success"] and not trajectory.infos[0]["is_success"]


def test_rows_hold_every_model_and_the_oracle(trajectory, toy_vlm):
    models = [BaseReward(toy_vlm, camera="tilted", mode="cosine"), BaseReward(toy_vlm, camera="front"), OracleReward()]
    rows = reward_curve(trajectory, models)
    assert list(rows[0]) == ["step", "distance", "base_reward", "base_2_reward", "oracle_reward", "oracle"]
    assert [r["step"] for r in rows] == list(range(len(trajectory)))
    assert [r["oracle_reward"] for r in rows] == [r["oracle"] for r in rows]
    np.testing.assert_allclose([r["distance"] for r in rows], trajectory.distances)
    # All frames in one batched image forward per model.
    assert toy_vlm.image_calls == 2
    direct = models[0].score(trajectory.observations["tilted"], GOAL)
    np.testing.assert_allclose([r["base_reward"] for r in rows], direct, atol=1e-6)
    stats = summarise(rows)
    assert set(stats) == {"base_reward", "base_2_reward", "oracle_reward"}
    assert stats["oracle_reward"]["mean_when_goal_holds"] == 1.0
    assert stats["oracle_reward"]["spearman_with_closeness"] > 0.5  # success comes with closeness


def test_table_and_plot(trajectory, toy_vlm, tmp_path):
    rows = reward_curve(trajectory, {"base": BaseReward(toy_vlm, camera="tilted")})
    csv_path = write_csv(rows, tmp_path / "fig.csv")
    with csv_path.open() as f:
        table = list(csv.DictReader(f))
    assert len(table) == len(rows) and float(table[3]["base_reward"]) == pytest.approx(rows[3]["base_reward"], rel=1e-5)
    png = plot_curve(rows, trajectory, tmp_path / "fig.png", camera="tilted")
    assert png.stat().st_size > 10_000


def test_bad_input(toy_vlm):
    with pytest.raises(ValueError, match="no scripted trajectory"):
        record_trajectory("pendulum", steps=2)  # no scripted controller for the pendulum
    with pytest.raises(ValueError, match="no scripted trajectory"):
        record_trajectory("a yellow puck on the left of a blue puck", steps=2)  # pushing script: 'close to' only
    with pytest.raises(ValueError, match="non-empty"):
        record_trajectory("", steps=2)
    with pytest.raises(ValueError, match="at least one reward model"):
        reward_curve(record_trajectory(GOAL, steps=1, image_size=32), [])

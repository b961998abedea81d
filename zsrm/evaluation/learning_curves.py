"""Learning curves of a sweep (Figure 6 of the paper): one panel per task, one line per reward,
the mean and standard error over seeds of the oracle episode reward against env steps; and
Figure 4, the double pendulum's panel with the base and oracle rewards
(:func:`plot_figure4`), whose oracle metric is the env's episode return.

>>> summary = {"stack": {"oracle": {"curve": [{"env_steps": 1000, "mean": 3.0, "se": 1.0}],
...                                 "final_mean": 3.0, "final_se": 1.0, "seeds": 3}}}
>>> plot_learning_curves(summary, "/tmp/zsrm-doctest-curves.png").name
'zsrm-doctest-curves.png'
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from zsrm.evaluation.plots import pyplot, save_figure

REWARD_COLOURS = {"zsrm": "tab:blue", "oracle": "tab:green", "vice": "tab:purple", "base": "tab:orange",
                  "curiosity": "tab:red", "random": "tab:gray"}
PENDULUM = "pendulum"  # the catalogue name of the double pendulum's task (Figure 4)
FIGURE4_REWARDS = ("base", "oracle")


def y_label(task: str) -> str:
    """What a task's oracle metric is: the steps in the goal relation, or the pendulum's return."""
    if task == PENDULUM:
        return "oracle episode return (env reward, 100 steps)"
    return "oracle episode reward (of 100)"


def plot_learning_curves(summary: dict, path: str | Path, title: str = "") -> Path:
    """``summary``: ``task -> reward -> {curve, final_mean, final_se, seeds}`` (:func:`zsrm.rl.sweep.gather`).
    Rewards without a curve (the random policy) are drawn as a flat band at their final mean."""
    plt = pyplot()
    tasks = list(summary)
    fig, axes = plt.subplots(1, len(tasks), figsize=(4.2 * len(tasks), 3.4), squeeze=False)
    for ax, task in zip(axes[0], tasks):
        x_max = max((row["env_steps"] for r in summary[task].values() for row in r.get("curve", [])), default=1)
        for reward, result in summary[task].items():
            colour = REWARD_COLOURS.get(reward)
            label = f"{reward} ({result['seeds']} seed{'' if result['seeds'] == 1 else 's'})"
            curve = result.get("curve") or []
            if curve:
                x = np.array([row["env_steps"] for row in curve])
                y = np.array([row["mean"] for row in curve])
                se = np.array([row["se"] for row in curve])
                ax.plot(x, y, color=colour, label=label)
                ax.fill_between(x, y - se, y + se, color=colour, alpha=0.2, linewidth=0)
            else:
                m, se = result["final_mean"], result["final_se"]
                ax.axhline(m, color=colour, linestyle="--", label=label)
                ax.axhspan(m - se, m + se, color=colour, alpha=0.15, linewidth=0)
        ax.set_title(task)
        ax.set_xlim(0, x_max)
        ax.set_ylim(bottom=0)
        ax.set_xlabel("env steps")
        ax.grid(alpha=0.3)
        if ax is axes[0][0] or y_label(task) != y_label(tasks[0]):
            ax.set_ylabel(y_label(task))
    for ax in axes[0]:  # each panel lists its own rewards and seeds (they differ while a sweep runs)
        ax.legend(fontsize=7, loc="upper left")
    if title:
        fig.suptitle(title)
    return save_figure(fig, path)


def plot_figure4(summary: dict, path: str | Path, rewards=FIGURE4_REWARDS) -> Path:
    """Figure 4: the double pendulum with the base and oracle rewards, the mean and standard
    error over seeds of the oracle episode return against env steps, from a sweep's summary
    (``summary["pendulum"][reward]``, :func:`zsrm.rl.sweep.gather`). Of ``rewards``, those the
    summary holds are drawn; ValueError if it holds none of them.

    >>> curve = [{"env_steps": 1000, "mean": 90.0, "se": 5.0}, {"env_steps": 2000, "mean": 300.0, "se": 20.0}]
    >>> summary = {"pendulum": {r: {"curve": curve, "final_mean": 300.0, "final_se": 20.0, "seeds": 3}
    ...                         for r in ("base", "oracle")}}
    >>> plot_figure4(summary, "/tmp/zsrm-doctest-figure4.png").name
    'zsrm-doctest-figure4.png'
    """
    results = {r: summary.get(PENDULUM, {})[r] for r in rewards if r in summary.get(PENDULUM, {})}
    if not results:
        raise ValueError(f"the summary holds no {PENDULUM} runs with the {' or '.join(rewards)} reward: "
                         f"run zsrm sweep --tasks {PENDULUM} --rewards {' '.join(rewards)} first")
    return plot_learning_curves({PENDULUM: results}, path,
                                title="double inverted pendulum (Figure 4)")

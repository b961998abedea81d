"""Table 2 of the paper: the distilled policies on the 18 training and 18 test tasks.

Each policy runs ``seeds`` seeded episodes per task, on scenes with the seen start-state
spread (one block width, as the task policies were trained and rolled out) and the unseen
one (two), and is scored with the oracle episode reward (control steps of 100 in the goal
relation). Where the stacking task policies were trained and rolled out in choice scenes (a
third block beside the moved one: the base must be found by colour), the stacking goals, the
test ones too, are scored in choice scenes. Per policy, spread and split: the mean and
standard error over all the split's episodes. The ceiling, ``oracle_task_policies``, is the task policies' own oracle episode
reward over the rollouts the policies were distilled from.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from stable_baselines3.common.vec_env import VecEnvWrapper

from zsrm.common.files import write_json, write_text
from zsrm.envs.rollout import run_vec_episodes
from zsrm.evaluation.plots import pyplot, save_figure
from zsrm.policy.models import DistilledPolicy, embed_goals
from zsrm.rl.config import STACKING, TrainConfig, goal_relation
from zsrm.rl.envs import make_vec
from zsrm.rl.evaluate import mean_se_cell
from zsrm.rl.goals import goal_camera
from zsrm.tasks.catalogue import TEST_TASKS, TRAIN_TASKS, choice_colours
from zsrm.tasks.language import parse_goal
from zsrm.tasks.relations import holds_in_world

EVAL_SEED = 3_000_000  # evaluation scenes: seeds apart from the training and collection envs'
POLICY_NAMES = {"none": "No Conditioning", "primitive": "Primitive Code Cond.", "language": "Language Cond.",
                "grounded": "Grounded Language Cond. (zsrm)"}  # table order
SPREADS = ("seen", "unseen")
SPLITS = ("train", "test")


def task_seed(index: int) -> int:
    """The first scene seed of the ``index``-th goal of a split: Table 2's scenes of that goal."""
    return EVAL_SEED + 1000 * index


class OnThirdBlock(VecEnvWrapper):
    """Adds ``info["on_third"]``: the control steps (of the decision's ``action_repeat``) with the
    goal's moved block on top of the scene's third block instead of its base; read after each
    decision, so a stack that comes or goes within a decision counts for all of it or none."""

    def __init__(self, venv, mover: str, third: str):
        super().__init__(venv)
        self.mover, self.third = mover, third
        self.repeat = venv.get_attr("action_repeat")[0]

    def reset(self):
        return self.venv.reset()

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        for info in infos:
            pos = info["object_positions"]
            info["on_third"] = self.repeat * int(self.third in pos and holds_in_world(
                "on_top_of", [pos[self.mover], pos[self.third]]))
        return obs, rewards, dones, infos


def task_rewards(policy: DistilledPolicy, goal: str, embedding: torch.Tensor, seeds: int, spread: str,
                 task_seed: int, choice: bool = False) -> list[float]:
    """Oracle episode rewards of ``seeds`` seeded episodes of one goal. ``choice``: a stacking
    goal's scenes are choice scenes (a third block beside the moved one, ``zsrm train --choice``);
    a test goal's seeds are shared out between its two possible third colours, so no choice
    favours a primitive code."""
    return task_episodes(policy, goal, embedding, seeds, spread, task_seed, choice)["episode_rewards"]


def task_episodes(policy: DistilledPolicy, goal: str, embedding: torch.Tensor, seeds: int, spread: str,
                  task_seed: int, choice: bool = False, wrap=None, also: tuple[str, ...] = ()) -> dict:
    """:func:`task_rewards`'s episodes as :func:`~zsrm.envs.rollout.run_vec_episodes` returns
    them; ``wrap(venv, colour)`` wraps each group's envs (colour: its third block, or None) to
    add the ``also`` info keys."""
    cfg = TrainConfig(goal=goal, image_size=policy.cfg.image_size, action_repeat=policy.cfg.action_repeat,
                      choice=choice and goal_relation(goal) in STACKING)
    groups = [(None, np.arange(seeds))]
    if cfg.choice:  # one third colour for a training goal, two for a test goal
        colours = choice_colours(parse_goal(goal))
        groups = [(c, idx) for c, idx in zip(colours, np.array_split(np.arange(seeds), len(colours))) if len(idx)]
    camera = policy.cfg.camera
    if camera != goal_camera(goal):  # make_vec renders the goal's camera alone
        raise ValueError(f"the policy reads camera {camera!r}; the scenes of {goal!r} show {goal_camera(goal)}")
    episodes: dict[str, list] = {}
    for colour, idx in groups:
        venv = make_vec(cfg, len(idx), task_seed + int(idx[0]), spread, distractors=(colour,) if colour else ())
        venv = wrap(venv, colour) if wrap else venv
        embeddings = embedding.expand(len(idx), -1)
        try:
            result = run_vec_episodes(venv, lambda obs: policy.act(obs[camera], embeddings).numpy(), also=also)
        finally:
            venv.close()
        for k, v in result.items():
            episodes.setdefault(k, []).extend(v)
    return episodes


def weights_key(policy: DistilledPolicy) -> str:
    """The first 12 hex digits of the SHA-256 of a policy's weights (which one a cached cell scored)."""
    import hashlib

    digest = hashlib.sha256()
    for name, tensor in policy.state_dict().items():
        digest.update(name.encode())
        digest.update(tensor.detach().cpu().contiguous().numpy().tobytes())
    return digest.hexdigest()[:12]


def evaluate_policies(policies: dict[str, DistilledPolicy], vlm, splits: dict[str, list[str]], seeds: int,
                      spreads=SPREADS, progress: bool = True, cache: str | Path | None = None,
                      choice: bool = False) -> dict:
    """``<policy>.<spread>.<split>.{mean, se, episodes}`` and the per-task means; ``choice``: the
    stacking goals (training and test) in choice scenes, as their task policies were. With ``cache``,
    each (policy, spread, split) cell is saved there as it finishes and reused while the policy's
    weights, the goals and the seeds are the same: a killed evaluation resumes at the first
    unfinished cell, and policies distilled at different times are scored as they come."""
    from tqdm import tqdm

    from zsrm.common.files import ZsrmFileError, read_json

    out: dict = {}
    keys = {name: weights_key(policy) for name, policy in policies.items()}
    runs = [(n, s, sp) for n in policies for s in spreads for sp in splits]
    for name, spread, split in tqdm(runs, desc="eval-multitask", disable=not progress):
        policy, goals = policies[name], splits[split]
        key = {"weights": keys[name], "goals": goals, "seeds": seeds, "spread": spread, "eval_seed": EVAL_SEED,
               **({"choice": True} if choice else {}), **({"text_span": True} if policy.cfg.text_span else {})}
        path = Path(cache) / f"{name}-{spread}-{split}.json" if cache else None
        try:
            cell = read_json(path) if path else {}
        except (FileNotFoundError, ZsrmFileError):
            cell = {}
        if cell.get("key") != key:
            embeddings = embed_goals(vlm, goals, policy.cfg.text_embedding)
            per_task = [task_rewards(policy, goal, embeddings[i:i + 1], seeds, spread, task_seed(i), choice)
                        for i, goal in enumerate(goals)]
            cell = {"key": key, "result": {
                **mean_se_cell([r for rewards in per_task for r in rewards]),
                "per_task": {goal: float(np.mean(r)) for goal, r in zip(goals, per_task)}}}
            if path:
                write_json(path, cell)
        out.setdefault(name, {}).setdefault(spread, {})[split] = cell["result"]
    return out


def primitive_mapping(policy: DistilledPolicy, vlm, goals: list[str]) -> dict[str, str]:
    """Each goal's nearest training task (the primitive code the primitive policy is given)."""
    codes = policy.nearest_codes(embed_goals(vlm, goals, policy.cfg.text_embedding))
    return {goal: policy.cfg.goals[int(c)] for goal, c in zip(goals, codes)}


def split_goals(max_tasks: int | None = None) -> dict[str, list[str]]:
    """The 18 training and 18 test tasks' goal sentences (the first ``max_tasks`` of each)."""
    return {"train": [t.text for t in TRAIN_TASKS][:max_tasks], "test": [t.text for t in TEST_TASKS][:max_tasks]}


def table_markdown(table: dict) -> str:
    """Table 2 as markdown: mean and s.e. per policy, spread and split."""
    head = "| (oracle episode reward) | " + " | ".join(
        f"{spread} {split} mean | s.e." for spread in SPREADS for split in SPLITS) + " |"
    lines = [head, "|---" * (1 + 2 * len(SPREADS) * len(SPLITS)) + "|"]
    for name in POLICY_NAMES:
        if name in table:
            cells = [f"{table[name][s][p]['mean']:.2f} | {table[name][s][p]['se']:.2f}"
                     for s in SPREADS for p in SPLITS]
            lines.append(f"| {POLICY_NAMES[name]} | " + " | ".join(cells) + " |")
    oracle = table["oracle_task_policies"]
    lines += ["", f"Schedule `{table['schedule']}`, image tower `{table['tower']}`; {table['meta']['seeds']} seeds "
              f"per task, {table['meta']['tasks_per_split']} tasks per split. The {oracle['tasks']} zsrm-trained task "
              f"policies themselves (seen spread, the rollouts distilled from): {oracle['mean']:.2f} +- "
              f"{oracle['se']:.2f}."
              + (f" The grounded policy's own keypoints look at: {table['meta']['keypoint_view']}."
                 if "grounded" in table and "keypoint_view" in table["meta"] else "")
              + (f" The paper's policies' image tower reads {table['image_view']} frames."
                 if "image_view" in table else "")
              + (" The language policy reads its goal embeddings centred and scaled (`--centre-text`)."
                 if "centred" in table.get("language_text", "") else "")
              + (" The language policy reads each goal's embedding projected onto the training goals' span "
                 "(`--text-span`)." if "span" in table.get("language_text", "") else "")
              + (" Stacking goals in choice scenes (a third block beside the moved one)."
                 if table.get("scenes") == "choice" else "")]
    return "\n".join(lines) + "\n"


def plot_table(table: dict, path: str | Path) -> Path:
    """Bars of the mean (s.e. whiskers) per spread and split, one colour per policy; the task
    policies' own mean as a dashed line."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    groups = [(s, p) for s in SPREADS for p in SPLITS]
    names = [n for n in POLICY_NAMES if n in table]
    width = 0.8 / max(1, len(names))
    for k, name in enumerate(names):
        x = np.arange(len(groups)) + (k - (len(names) - 1) / 2) * width
        ax.bar(x, [table[name][s][p]["mean"] for s, p in groups], width,
               yerr=[table[name][s][p]["se"] for s, p in groups], capsize=3, label=POLICY_NAMES[name])
    ax.axhline(table["oracle_task_policies"]["mean"], color="k", linestyle="--", linewidth=1,
               label="task policies (seen)")
    ax.set_ylim(0, max(1.0, ax.get_ylim()[1]))
    ax.set_xticks(np.arange(len(groups)), [f"{s}\n{p} tasks" for s, p in groups])
    ax.set_ylabel("oracle episode reward (of 100)")
    view = (f", {table['image_view']} frames" if "image_view" in table else "") + (
        ", choice scenes" if table.get("scenes") == "choice" else "")
    ax.set_title(f"Table 2: multi-task policies ({table['schedule']} schedule, {table['tower']} tower{view})")
    # Below the axes: inside, it would hide the bars.
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3, frameon=False)
    ax.grid(axis="y", alpha=0.3)
    return save_figure(fig, path)


def table_rows(table: dict) -> list[dict]:
    """Table 2 as rows (one per policy, spread and split) for the CSV."""
    return [{"policy": name, "spread": spread, "split": split, "mean": table[name][spread][split]["mean"],
             "se": table[name][spread][split]["se"], "episodes": table[name][spread][split]["episodes"]}
            for name in POLICY_NAMES if name in table for spread in SPREADS for split in SPLITS]


def write_table(table: dict, path: str | Path) -> list[Path]:
    """``path`` (JSON), the CSV, markdown and plot beside it (``.csv``, ``.md``, ``.png``)."""
    from zsrm.evaluation.curves import write_csv

    path = Path(path)
    return [write_json(path, table), write_csv(table_rows(table), path.with_suffix(".csv")),
            write_text(path.with_suffix(".md"), table_markdown(table)), plot_table(table, path.with_suffix(".png"))]

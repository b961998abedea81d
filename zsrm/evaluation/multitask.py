"""Table 2 of the paper: the distilled policies on the 18 training and 18 test tasks.

Each policy runs ``seeds`` seeded episodes per task, on scenes with the seen start-state
spread (one block width, as the task policies were trained and rolled out) and the unseen
one (two), and is scored with the oracle episode reward (control steps of 100 in the goal
relation). Where the stacking task policies were trained and rolled out in choice scenes (a
third block beside the moved one: the base must be found by colour), the stacking goals, the
test ones too, are scored in choice scenes. Per policy, spread and split: the mean and
standard error over all the split's episodes, and the same per relation (on top of, left of,
right of: ``relations``). The ceiling, ``oracle_task_policies``, is the task policies' own oracle
episode reward over the rollouts the policies were distilled from, also per relation.
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
from zsrm.policy.training import DAGGER_SUFFIX, MIRROR_SUFFIX, MIRROR_TEACHERS_SUFFIX
from zsrm.rl.config import STACKING, TrainConfig, goal_relation
from zsrm.rl.envs import make_vec
from zsrm.rl.evaluate import mean_se_cell
from zsrm.rl.goals import goal_camera
from zsrm.tasks.catalogue import MULTITASK_RELATIONS, TEST_TASKS, TRAIN_TASKS, choice_colours
from zsrm.tasks.language import parse_goal
from zsrm.tasks.relations import RELATIONS, holds_in_world

EVAL_SEED = 3_000_000  # evaluation scenes: seeds apart from the training and collection envs'
PAPER_POLICIES = {"none": "No Conditioning", "primitive": "Primitive Code Cond.", "language": "Language Cond."}
# Table order: the paper's three, zsrm's grounded variant, each distilled with zsrm's DAgger rounds,
# then each with zsrm's mirror methods (zsrm.policy.mirror), without and with DAgger.
_BASES = [*PAPER_POLICIES.items(), ("grounded", "Grounded Language Cond.")]
_MIRRORS = [(MIRROR_SUFFIX, " + mirror"), (MIRROR_TEACHERS_SUFFIX, " + mirrored teachers")]
POLICY_NAMES = {**PAPER_POLICIES, "grounded": "Grounded Language Cond. (zsrm)",
                **{f"{n}{DAGGER_SUFFIX}": f"{label} + DAgger (zsrm)" for n, label in _BASES},
                **{f"{n}{suffix}{dagger}": f"{label}{words}{' + DAgger' if dagger else ''} (zsrm)"
                   for suffix, words in _MIRRORS for dagger in ("", DAGGER_SUFFIX) for n, label in _BASES}}
SPREADS = ("seen", "unseen")
SPLITS = ("train", "test")


def relation_cells(goals: list[str], rewards: list[list[float]]) -> dict:
    """``{relation: {mean, se, episodes}}`` over the episodes of the goals of each relation (read
    from the parsed goal), in MULTITASK_RELATIONS order; ``rewards[i]`` are ``goals[i]``'s episodes."""
    by_relation: dict[str, list[float]] = {}
    for goal, episodes in zip(goals, rewards):
        by_relation.setdefault(parse_goal(goal).relation, []).extend(episodes)
    order = [r for r in MULTITASK_RELATIONS if r in by_relation] + sorted(set(by_relation) - set(MULTITASK_RELATIONS))
    return {r: mean_se_cell(by_relation[r]) for r in order}


def ceiling(data) -> dict:
    """``oracle_task_policies``: the task policies' oracle episode rewards over the rollouts in
    ``data`` (a :class:`~zsrm.policy.rollouts.RolloutData`), all tasks and per relation."""
    return {**mean_se_cell(data.episode_rewards), "tasks": len(data.goals),
            "relations": relation_cells(data.goals, [info["episode_rewards"] for info in data.infos])}


def taught_ceiling(data, taught: dict[str, str]) -> dict:
    """``oracle_teachers``: :func:`ceiling` with each task's episodes those of the task policy that
    taught it (``taught``: goal -> its mirror goal, for the tasks ``zsrm distill --mirror-teachers``
    taught with their mirror task's policy): the bar of the policies that teachers distilled."""
    rewards = {info["goal"]: info["episode_rewards"] for info in data.infos}
    per_task = [rewards[taught.get(goal, goal)] for goal in data.goals]
    return {**mean_se_cell([r for episodes in per_task for r in episodes]), "tasks": len(data.goals),
            "relations": relation_cells(data.goals, per_task)}


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
    """``<policy>.<spread>.<split>.{mean, se, episodes}``, the per-task means and the cells per relation
    (``relations``, :func:`relation_cells`); ``choice``: the
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
        if cell.get("key") != key or "relations" not in cell.get("result", {}):  # cells cached before relations
            embeddings = embed_goals(vlm, goals, policy.cfg.text_embedding)
            per_task = [task_rewards(policy, goal, embeddings[i:i + 1], seeds, spread, task_seed(i), choice)
                        for i, goal in enumerate(goals)]
            cell = {"key": key, "result": {
                **mean_se_cell([r for rewards in per_task for r in rewards]),
                "per_task": {goal: float(np.mean(r)) for goal, r in zip(goals, per_task)},
                "relations": relation_cells(goals, per_task)}}
            if path:
                write_json(path, cell)
        out.setdefault(name, {}).setdefault(spread, {})[split] = cell["result"]
    return out


def best_policy(table: dict) -> dict | None:
    """zsrm's best one-for-all policy: of zsrm's own (the grounded variant and any DAgger one), the
    highest on the training tasks (seen spread), so no test task chooses it; with its test score over
    each relation's ceiling per spread (None without one of zsrm's own)."""
    ours = [n for n in POLICY_NAMES if n in table and n not in PAPER_POLICIES]
    if not ours:
        return None
    name = max(ours, key=lambda n: table[n]["seen"]["train"]["mean"])
    best = {"policy": name, "chosen_by": "zsrm's own policies' highest mean on the training tasks, seen spread",
            "test_over_ceiling": test_over(table[name], table["oracle_task_policies"])}
    if MIRROR_TEACHERS_SUFFIX in name and "oracle_teachers" in table:  # and over the teachers it learnt from
        best["test_over_teachers"] = test_over(table[name], table["oracle_teachers"])
    return best


def test_over(cells: dict, ceiling: dict) -> dict:
    """A policy's test score over a ceiling's, per relation and spread (None over a ceiling of 0)."""
    tested = cells["seen"]["test"].get("relations", {})
    return {r: {s: cells[s]["test"]["relations"][r]["mean"] / top["mean"] if top["mean"] else None for s in SPREADS}
            for r, top in ceiling.get("relations", {}).items() if r in tested}


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
                 if table.get("scenes") == "choice" else "")
              + (f" + DAgger: {table['dagger']['rounds']} rounds of DAgger-style relabelling after behaviour "
                 "cloning (zsrm's method, `zsrm distill --dagger-rounds`), not the paper's behaviour cloning alone."
                 if "dagger" in table else "")
              + mirror_notes(table)
              + (f" zsrm's best one-for-all policy: {POLICY_NAMES[table['best']['policy']]} ({table['best']['chosen_by']})."
                 if "best" in table else "")]
    return "\n".join(lines + relations_markdown(table)) + "\n"


def mirror_notes(table: dict) -> str:
    """What the table's mirror rows were distilled with (zsrm.policy.mirror)."""
    notes = ""
    if any(n.removesuffix(DAGGER_SUFFIX).removesuffix(MIRROR_TEACHERS_SUFFIX).endswith(MIRROR_SUFFIX)
           for n in table if n in POLICY_NAMES):
        notes += (" + mirror: each frame, with probability 1/2, mirrored left to right in distillation, its action's "
                  "x negated and its goal's left and right swapped (`zsrm distill --mirror`).")
    if "mirror_teachers" in table:
        taught = "; ".join(f"{goal} <- {by}" for goal, by in table["mirror_teachers"].items())
        notes += (" + mirrored teachers: a task is taught by its mirror task's policy, mirrored, where the zsrm "
                  f"reward rates that policy higher (`zsrm distill --mirror-teachers`): {taught}.")
    return notes


def table_relations(table: dict) -> list[str]:
    """The relations a table has cells for (none in tables written before they were kept)."""
    cells = [table[n][s][p].get("relations", {}) for n in POLICY_NAMES if n in table for s in SPREADS for p in SPLITS]
    return [r for r in MULTITASK_RELATIONS if cells and all(r in c for c in cells)]


def relations_markdown(table: dict) -> list[str]:
    """Per relation: each policy's mean +- s.e. per spread and split, and the relation's ceiling."""
    relations = table_relations(table)
    if not relations:
        return []
    lines = ["", "Per relation (mean +- s.e.; the ceiling: the task policies over their own rollouts, seen spread, "
             "training tasks):", "", "| relation | policy | " + " | ".join(f"{s} {p}" for s in SPREADS for p in SPLITS)
             + " |", "|---" * (2 + len(SPREADS) * len(SPLITS)) + "|"]
    ceilings = table["oracle_task_policies"].get("relations", {})
    teachers = table.get("oracle_teachers", {}).get("relations", {})  # --mirror-teachers rows' teachers
    for relation in relations:
        for name in POLICY_NAMES:
            if name in table:
                cells = [table[name][s][p]["relations"][relation] for s in SPREADS for p in SPLITS]
                lines.append(f"| {RELATIONS[relation].phrase} | {POLICY_NAMES[name]} | "
                             + " | ".join(f"{c['mean']:.1f} +- {c['se']:.1f}" for c in cells) + " |")
        for label, tops in (("the task policies (ceiling)", ceilings), ("the task policies that taught (mirrored)",
                                                                        teachers)):
            if relation not in tops:
                continue
            top = tops[relation]
            lines.append(f"| {RELATIONS[relation].phrase} | {label} | {top['mean']:.1f} +- "
                         f"{top['se']:.1f} |" + " |" * (len(SPREADS) * len(SPLITS) - 1))
    return lines


def plot_bars(ax, table: dict, relation: str | None = None) -> None:
    """Bars of the mean (s.e. whiskers) per spread and split, one colour per policy, of all tasks or of
    one ``relation``'s; the task policies' own mean (the ceiling) as a dashed line."""
    groups = [(s, p) for s in SPREADS for p in SPLITS]
    names = [n for n in POLICY_NAMES if n in table]
    width = 0.8 / max(1, len(names))
    for k, name in enumerate(names):
        cells = [table[name][s][p] if relation is None else table[name][s][p]["relations"][relation]
                 for s, p in groups]
        x = np.arange(len(groups)) + (k - (len(names) - 1) / 2) * width
        ax.bar(x, [c["mean"] for c in cells], width, yerr=[c["se"] for c in cells], capsize=2,
               color=f"C{k}", label=POLICY_NAMES[name])
    top = table["oracle_task_policies"]
    top = top if relation is None else top.get("relations", {}).get(relation)
    if top:
        ax.axhline(top["mean"], color="k", linestyle="--", linewidth=1, label="task policies (seen train): ceiling")
    ax.set_xticks(np.arange(len(groups)), [f"{s}\n{p}" for s, p in groups])
    ax.grid(axis="y", alpha=0.3)


def plot_table(table: dict, path: str | Path) -> Path:
    """All tasks on top; below, where the table has them, one panel per relation on a shared scale."""
    plt = pyplot()
    relations = table_relations(table)
    if relations:
        fig, axes = plt.subplot_mosaic([["all"] * len(relations), relations], figsize=(9, 8),
                                       height_ratios=(1.2, 1))
        ax, panels = axes["all"], [axes[r] for r in relations]
    else:
        fig, ax = plt.subplots(figsize=(7.5, 4.2))
        panels = []
    plot_bars(ax, table)
    ax.set_ylim(0, max(1.0, ax.get_ylim()[1]))
    ax.set_ylabel("oracle episode reward (of 100)")
    view = (f", {table['image_view']} frames" if "image_view" in table else "") + (
        ", choice scenes" if table.get("scenes") == "choice" else "")
    ax.set_title(f"Table 2: multi-task policies ({table['schedule']} schedule, {table['tower']} tower{view})")
    for k, (panel, relation) in enumerate(zip(panels, relations)):
        plot_bars(panel, table, relation)
        panel.set_ylim(0, 100)
        panel.set_title(RELATIONS[relation].phrase, fontsize=10)
        if k == 0:
            panel.set_ylabel("per relation (S: seen, U: unseen)")
        else:
            panel.tick_params(labelleft=False)
    # Below the axes: inside, it would hide the bars; tick labels of a panel of its own, shorter.
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3, frameon=False)
    for panel in panels:
        panel.set_xticks(panel.get_xticks(), [f"{s[0].upper()}\n{p}" for s in SPREADS for p in SPLITS], fontsize=8)
    return save_figure(fig, path)


def table_rows(table: dict) -> list[dict]:
    """Table 2 as rows (one per policy, spread, split and relation, ``all`` first) for the CSV."""
    rows = []
    for name in (n for n in POLICY_NAMES if n in table):
        for spread in SPREADS:
            for split in SPLITS:
                cell = table[name][spread][split]
                for relation, c in [("all", cell), *cell.get("relations", {}).items()]:
                    rows.append({"policy": name, "spread": spread, "split": split, "relation": relation,
                                 "mean": c["mean"], "se": c["se"], "episodes": c["episodes"]})
    return rows


def write_table(table: dict, path: str | Path) -> list[Path]:
    """``path`` (JSON), the CSV, markdown and plot beside it (``.csv``, ``.md``, ``.png``)."""
    from zsrm.evaluation.curves import write_csv

    path = Path(path)
    return [write_json(path, table), write_csv(table_rows(table), path.with_suffix(".csv")),
            write_text(path.with_suffix(".md"), table_markdown(table)), plot_table(table, path.with_suffix(".png"))]

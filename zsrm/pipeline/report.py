"""The report of ``zsrm reproduce``: ``index.html`` and the same as ``README.md``, read top to
bottom: what ran, on what machine, with which VLM; what the run learned; then the figures the
committed results hold (``results/``), each with the command that reproduces it.

The HTML marks every figure it shows; once the page has loaded, a small script writes how many
loaded into ``<body data-figures-loaded="N/M">`` (the headless-browser test reads it).
"""
from __future__ import annotations

import html
import json
import platform
import shutil
import time
from pathlib import Path

import numpy as np

from zsrm.common.files import write_json, write_text
from zsrm.common.machine import describe

RESULTS = Path("results")


def machine() -> str:
    return f"{platform.platform()}, {describe()}, no GPU used"


class Report:
    """Sections of text, tables and figures, rendered as Markdown and as HTML."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.md: list[str] = []
        self.html: list[str] = []
        self.figures = 0

    def heading(self, text: str, level: int = 2):
        self.md += ["#" * level + " " + text, ""]
        self.html.append(f"<h{level}>{html.escape(text)}</h{level}>")

    def text(self, text: str):
        self.md += [text, ""]
        self.html.append(f"<p>{html.escape(text)}</p>")

    def command(self, cmd: str):
        self.md += [f"`{cmd}`", ""]
        self.html.append(f"<pre><code>{html.escape(cmd)}</code></pre>")

    def table(self, header: list[str], rows: list[list]):
        self.md += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        self.md += ["| " + " | ".join(map(str, r)) + " |" for r in rows] + [""]
        cells = "".join(f"<th>{html.escape(h)}</th>" for h in header)
        body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
        self.html.append(f"<table><tr>{cells}</tr>{body}</table>")

    def markdown_block(self, text: str):
        """Markdown written elsewhere (a table): as is in README.md, preformatted in the HTML."""
        self.md += [text, ""]
        self.html.append(f"<pre>{html.escape(text)}</pre>")

    def figure(self, source: Path, caption: str):
        """Copy ``source`` into the report's figures/ and show it."""
        if not source.is_file():
            self.text(f"(missing: {source})")
            return
        dest = self.folder / "figures" / source.name
        dest.parent.mkdir(parents=True, exist_ok=True)
        if source.resolve() != dest.resolve():
            shutil.copyfile(source, dest)
        rel = f"figures/{source.name}"
        self.figures += 1
        self.md += [f"![{caption}]({rel})", "", f"*{caption}*", ""]
        self.html.append(f'<figure><img class="figure" src="{html.escape(rel)}" alt="{html.escape(caption)}">'
                         f"<figcaption>{html.escape(caption)}</figcaption></figure>")

    def write(self, title: str) -> Path:
        write_text(self.folder / "README.md", "\n".join([f"# {title}", ""] + self.md) + "\n")
        page = ["<!doctype html><html><head><meta charset='utf-8'>", f"<title>{html.escape(title)}</title>",
                "<style>body{font-family:sans-serif;max-width:1000px;margin:2em auto;line-height:1.4}"
                "img{max-width:100%}table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px}"
                "pre{background:#f4f4f4;padding:6px}</style></head><body>", f"<h1>{html.escape(title)}</h1>",
                *self.html, COUNT_FIGURES, "</body></html>"]
        return write_text(self.folder / "index.html", "\n".join(page) + "\n")


COUNT_FIGURES = """<script>
window.addEventListener("load", function () {
  var figures = document.querySelectorAll("img.figure"), ok = 0;
  figures.forEach(function (img) { if (img.complete && img.naturalWidth > 0) ok++; });
  document.body.setAttribute("data-figures-loaded", ok + "/" + figures.length);
});
</script>"""


def write_report(folder: Path, scale: str, vlm: str, log: list[dict], workdir: Path, wall_s: float,
                 demo_task: str | None = None, config: str = "cpu") -> Path:
    """Write the report of a ``zsrm reproduce`` run; for a demo-kind scale (``demo_task``, the task it
    trains) also ``results/demo.json``."""
    folder.mkdir(parents=True, exist_ok=True)
    report = Report(folder)
    report.text(f"zsrm reproduce --scale {scale}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, on "
                f"{machine()}. VLM: {vlm}" + (" (zsrm's offline stand-in for CLIP)" if vlm == "scene" else "") +
                f". Wall time {wall_s / 60:.1f} min.")
    report.heading("Stages")
    report.table(["stage", "what", "seconds", "cached", "command"],
                 [[e["stage"], e["what"], f"{e['seconds']:.0f}", "yes" if e.get("cached") else "no", e["command"]]
                  for e in log])
    if demo_task is not None:
        result = demo_result(log, wall_s, demo_task, config)
        write_json(RESULTS / "demo.json" if scale == "demo" else folder / "demo.json", result)
        demo_section(report, result, workdir)
    else:
        run_section(report, workdir)
    committed_results(report)
    return report.write(f"zsrm report ({scale} scale)")


def demo_result(log: list[dict], wall_s: float, task: str, config: str = "cpu") -> dict:
    """``results/demo.json``: the demo's learning signal (zsrm-trained policy against random)."""
    by_stage = {entry["stage"]: entry["result"] for entry in log}
    trained, rand = by_stage["policy_zsrm"], by_stage["policy_random"]
    return {"wall_s": round(wall_s, 1), "task": task,
            "zsrm_policy_mean": trained["final_mean"], "zsrm_policy_se": trained["final_se"],
            "random_policy_mean": rand["final_mean"], "random_policy_se": rand["final_se"],
            "zsrm_policy_env_steps": trained["env_steps"], "episodes": trained["final_episodes"],
            "stage_seconds": {e["stage"]: e["seconds"] for e in log},
            "stages_cached": [e["stage"] for e in log if e.get("cached")],
            "config": config, "expected_range": expected_range(task, learning=LEARNING_BY_CONFIG.get(config))}


# The committed sweep of each learner preset a demo can run: where its seeds ended.
LEARNING_BY_CONFIG = {"cpu": RESULTS / "rl" / "v3" / "learning.json", "v2": RESULTS / "rl" / "v2" / "learning.json"}
LEARNING_BY_CONFIG["v3"] = LEARNING_BY_CONFIG["cpu"]  # the default learner since 2026-12-06


def expected_range(task: str, reward: str = "zsrm", learning: Path | None = LEARNING_BY_CONFIG["cpu"]) -> dict | None:
    """Where a run of ``task`` with ``reward`` is expected to end: the committed seeds' mean +- two
    standard deviations (the default learner's: results/rl/v3/learning.json). Float results move
    across CPUs, so another machine's run lands somewhere in the seeds' spread, not on one number."""
    if learning is None or not learning.is_file():
        return None
    cell = json.loads(learning.read_text()).get(task, {}).get(reward)
    finals = (cell or {}).get("final_per_seed") or []
    if len(finals) < 2:
        return None
    mean, sd = float(np.mean(finals)), float(np.std(finals, ddof=1))
    return {"low": round(mean - 2 * sd, 1), "high": round(mean + 2 * sd, 1), "mean": round(mean, 1),
            "sd": round(sd, 1), "seeds": len(finals), "seeds_min": round(min(finals), 1),
            "seeds_max": round(max(finals), 1), "file": str(learning),
            "why": "float results move across CPUs: the same command and seed gave 69.8 on one x86_64 machine and "
                   "56.1 on another; on one machine a rerun is identical"}


def demo_section(report: Report, result: dict, workdir: Path):
    from zsrm.evaluation.learning_curves import plot_learning_curves

    task = result["task"]
    report.heading("A policy trained from a sentence")
    report.text(f"PPO trained on {task} with the zsrm reward (the shipped student reward model, binarised: "
                f"1 when the goal sentence beats its negatives on the frame) for {result['zsrm_policy_env_steps']} "
                f"env steps, against a uniform random policy; oracle episode reward (steps of 100 in the goal "
                f"relation, read from the true state for evaluation only) over {result['episodes']} seeded episodes.")
    report.table(["policy", "oracle episode reward", "s.e."],
                 [["trained with the zsrm reward", f"{result['zsrm_policy_mean']:.1f}", f"{result['zsrm_policy_se']:.1f}"],
                  ["random", f"{result['random_policy_mean']:.1f}", f"{result['random_policy_se']:.1f}"]])
    gap = result["zsrm_policy_mean"] - result["random_policy_mean"]
    margin = result["zsrm_policy_se"] + result["random_policy_se"]
    report.text(f"Learning signal: the trained policy is {gap:+.1f} against random; "
                + ("more than" if gap > margin else "NOT more than") +
                f" the two standard errors combined ({margin:.1f}).")
    spread = result.get("expected_range")
    if spread:
        report.text(f"Expect a number in a range, not this one: float results move across CPUs, and the same seed "
                    f"ends elsewhere on another machine (69.8 on one x86_64 machine, 56.1 on another). Expected: "
                    f"{spread['low']:.1f} to {spread['high']:.1f}, the mean +- two standard deviations of the "
                    f"committed runs of this task and reward ({spread['seeds']} seeds in {spread['file']}, which end "
                    f"between {spread['seeds_min']:.1f} and {spread['seeds_max']:.1f}). On one machine a rerun gives "
                    f"the same number.")
    summary = json.loads((workdir / "policy_zsrm" / "summary.json").read_text())
    rand = json.loads((workdir / "policy_random" / "summary.json").read_text())
    curves = {task: {"zsrm": {"curve": summary["curve"], "seeds": 1,
                              "final_mean": summary["final_mean"], "final_se": summary["final_se"]},
                     "random": {"curve": [], "seeds": 1, "final_mean": rand["final_mean"], "final_se": rand["final_se"]}}}
    png = plot_learning_curves(curves, workdir / "gifs" / "demo_learning.png")
    report.figure(png, "oracle episode reward of the zsrm-trained policy while it trains (s.e. over evaluation episodes)")
    gifs = json.loads((workdir / "gifs" / "stage.json").read_text())["result"]
    picked = ("the first of seeds 0-9 in which it reaches the goal" if gifs["zsrm_episode_reward"] > 0
              else "it reached the goal in none of seeds 0-9")
    report.figure(workdir / "gifs" / "zsrm_policy.gif",
                  f"the policy trained with the zsrm reward, seed {gifs.get('seed', 0)} ({picked}; oracle episode "
                  f"reward {gifs['zsrm_episode_reward']:.0f})")
    report.figure(workdir / "gifs" / "random_policy.gif",
                  f"a random policy, same seed (oracle episode reward {gifs['random_episode_reward']:.0f})")
    report.command(f"zsrm train --goal {task} --reward zsrm --seed 0 --steps {result['zsrm_policy_env_steps']}")


def run_section(report: Report, workdir: Path):
    """What a cpu or paper run built: its Figure 6 sweep and its Table 2."""
    report.heading("What this run trained")
    learning = workdir / "policies" / "learning.json"
    if learning.is_file():
        learning_table(report, json.loads(learning.read_text()))
        report.figure(learning.with_suffix(".png"), "this run: oracle episode reward while training, mean and s.e. "
                                                    "over seeds")
    table2 = workdir / "table2" / "table2.json"
    if table2.is_file():
        report.markdown_block(table2.with_suffix(".md").read_text())
        report.figure(table2.with_suffix(".png"), "this run: Table 2, the distilled policies")


def _load(name: str):
    path = RESULTS / name
    return json.loads(path.read_text()) if path.is_file() else None


def committed_results(report: Report):
    """The figures of the committed results (the cpu scale, run on a 2-core CPU machine)."""
    report.heading("Committed results (cpu scale)")
    report.text("What make results and the sweeps have produced on this project's 2-core CPU machine, "
                "committed under results/.")
    report.heading("Grounding: Grad-CAM finds the objects (Figure 3)", 3)
    report.figure(RESULTS / "figure3.png", "Grad-CAM heat maps of object phrases and their argmax")
    grounding = _load("grounding.json") or {}
    # n/a: a relation with no true or labelled instance in the data (inside of, without the box)
    report.table(["relation", "labeler F1"], [[k.split(".", 1)[1], "n/a" if v is None else f"{v:.2f}"]
                                               for k, v in grounding.items() if k.startswith("f1.")])
    report.command("zsrm eval-grounding data/grounding --out results/grounding.json --figure results/figure3.png")
    report.heading("Base reward against the full reward along trajectories (Figure 5)", 3)
    report.figure(RESULTS / "figure5.png", "base reward along a scripted push: it does not capture 'close to'")
    for task in ("stack", "place_right", "push_close"):
        report.figure(RESULTS / "reward_curves" / f"{task}.png", f"base and zsrm reward along {task} episodes")
    reward = _load("reward_eval.json") or {}
    models = [m for m in reward if m != "meta"]
    tasks = list(reward.get("zsrm", {}))
    rows = [[task, *(f"{reward[m].get(task, {}).get('f1', float('nan')):.2f}" for m in models)] for task in tasks]
    report.table(["task", *(f"{m} F1" for m in models)], rows)
    report.command(reward.get("meta", {}).get("command", "zsrm eval-reward"))
    learning_section(report)
    report.heading("Multi-task policy (Table 2)", 3)
    if (RESULTS / "table2.md").is_file():
        report.markdown_block((RESULTS / "table2.md").read_text())
        report.figure(RESULTS / "table2.png", "Table 2: language, primitive-code and unconditioned policies")
    else:
        report.text("Not produced yet at the cpu scale: the 18 task policies of Table 2 (zsrm multitask-policies, "
                    "then multitask-rollouts, distill, eval-multitask) have not been run on this machine.")


def learning_section(report: Report):
    report.heading("Learning from the rewards (Figure 6)", 3)
    learning = _load("rl/learning.json")
    if not learning:
        report.text("No sweep results committed yet (zsrm sweep writes results/rl/learning.json).")
        return
    learning_table(report, learning)
    report.figure(RESULTS / "rl" / "learning.png", "oracle episode reward while training, mean and s.e. over seeds")
    report.command(learning.get("meta", {}).get("command", "zsrm sweep"))


def learning_table(report: Report, learning: dict):
    rows = [[task, reward, f"{v['final_mean']:.1f}", f"{v['final_se']:.1f}", v["seeds"], v["steps"]]
            for task, rewards in learning.items() if task != "meta" for reward, v in rewards.items()]
    report.table(["task", "reward", "oracle episode reward", "s.e. over seeds", "seeds", "env steps"], rows)

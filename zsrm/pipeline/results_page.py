"""``results/README.md`` and README.md's headline table, written from the committed result files.

Each canonical figure is one :class:`Figure`: the file under ``results/`` it is read from, how
its value is read and written, and the command that made the file. ``zsrm results-page`` writes
the page and the headline table between README.md's two markers; ``tests/test_results_page.py``
fails when either differs from what the files say, so no number is typed by hand. After a
result file changes, run ``zsrm results-page`` again.

>>> figure = Figure("Example", "example.json", lambda d: f"{d['ratio']:.2f}", "zsrm example")
>>> figure.row({"ratio": 4.1439})
'| Example | 4.14 | [`example.json`](example.json) | `zsrm example` |'
"""
from __future__ import annotations

import csv
import fnmatch
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from zsrm.common.files import check_writable, write_text
from zsrm.tasks.catalogue import LEARNING_TASKS

HEADLINE_START = "<!-- headline: written by `zsrm results-page` from results/; do not edit by hand -->"
HEADLINE_END = "<!-- end of headline -->"


@dataclass(frozen=True)
class Figure:
    name: str  # what is measured, in a few words
    file: str  # relative to results/
    value: Callable[[dict], str]  # the value as written, from the file's JSON
    command: str | Callable[[dict], str]  # the command that writes the file (or how to read it from the file)
    headline: bool = True  # also a row of README.md's headline table

    def row(self, data: dict, link_prefix: str = "") -> str:
        command = self.command(data) if callable(self.command) else self.command
        return f"| {self.name} | {self.value(data)} | [`{self.file}`]({link_prefix}{self.file}) | `{command}` |"


def _recorded_command(d: dict) -> str:
    """The command a result file records (its ``meta.command``): zsrm's source names no example scene."""
    return d["meta"]["command"]


def _pm(entry: dict, mean: str = "final_mean", se: str = "final_se") -> str:
    return f"{entry[mean]:.1f} +- {entry[se]:.1f}"


def _slash(values, fmt: str = "{:.2f}") -> str:
    return " / ".join(fmt.format(v) for v in values)


def _figure5(rows: dict) -> str:
    from zsrm.evaluation.curves import summarise

    rho = summarise(rows["rows"])["base_reward"]["spearman_with_closeness"]
    return f"rank correlation of the base reward with closeness {rho:.2f} (it does not rise as the pucks meet)"


def _own_scene(d: dict) -> str:
    labeler = ", ".join(f"{rel.replace('_', ' ')} {f1:.2f}" for rel, f1 in d["labeler_f1"].items())
    rewards = "; ".join(f"{v['zsrm']:.2f} / {v['base']:.2f}" for v in d["reward_f1"].values())
    ppo = d.get("ppo")
    learned = (f"; PPO on \"{ppo['goal']}\", zsrm / oracle / random {ppo['zsrm']['mean']:.1f} / {ppo['oracle']['mean']:.1f} / "
               f"{ppo['random']['mean']:.1f} (the oracle learns little: docs/own-scene.md)" if ppo
               else "; PPO not run (the oracle does not learn its goals yet)")
    side = d.get("ppo_sideways")
    if side:
        learned += (f"; sideways, \"{side['goal']}\" from a column start: zsrm / oracle / random "
                    f"{side['zsrm']['mean']:.1f} / {side['oracle']['mean']:.1f} / {side['random']['mean']:.1f}")
    return f"labeler {labeler}; reward {rewards}{learned}"


def _scene_chain(d: dict) -> str:
    """A ``zsrm own-scene`` summary: labeler, the worst localisation against half a width, reward."""
    labeler = ", ".join(f"{rel.replace('_', ' ')} {f1:.2f}" for rel, f1 in d["labeler_f1"].items())
    worst = max((c["median_error_px"] / c["half_width_px"], obj, role) for obj, cells in d["localisation"].items()
                for role, c in cells.items() if c["median_error_px"] is not None)
    rewards = "; ".join(f"{v['zsrm']:.2f} / {v['base']:.2f}" for v in d["reward_f1"].values())
    return (f"labeler {labeler}; worst localisation {worst[0]:.2f} of half a width ({worst[1]}, {worst[2]}); "
            f"reward zsrm / base {rewards}; usable: {'yes' if d['usable'] else 'no'}")


def _benchmark(d: dict) -> str:
    """benchmarks/suites.py: per goal, zsrm / base F1 against the benchmark's own predicate."""
    return "; ".join(f"\"{g}\" {r['zsrm']['f1']:.2f} / {r['base']['f1']:.2f} (zsrm AUROC {r['zsrm']['auroc']:.2f}; "
                     f"{r['positives']} of {r['frames']} frames hold)" for g, r in d["reward"].items())


def _final_means(d: dict, rewards: tuple[str, ...], note: str = "") -> str:
    """Each Figure 6 task's final oracle episode reward under ``rewards``, in that order."""
    return ("; ".join(f"{t} {_slash((d[t][r]['final_mean'] for r in rewards), '{:.1f}')}"
                      for t in ("stack", "place_right", "push_close")) + f" ({' / '.join(rewards)}{note})")


def _figure6(d: dict) -> str:
    return _final_means(d, ("zsrm", "oracle", "base"))


def _figure6_vice(d: dict) -> str:
    """zsrm, the oracle and VICE per task, with how many of the sweep's trials have finished."""
    meta = d["meta"]
    return _final_means(d, ("zsrm", "oracle", "vice"), f"; {meta['trials_finished']} of {meta['trials_planned']} trials")


def _learning(d: dict) -> str:
    return _final_means(d, ("zsrm", "oracle", "random"))


def _nine(d: dict) -> str:
    """zsrm's final success rate per task, the oracle's and random's beside it."""
    rate = {t: tuple(d[t][r]["final_success_rate"] for r in ("zsrm", "oracle", "random"))
            for t in LEARNING_TASKS if t in d}
    return "; ".join(f"{t} {_slash(v)}" for t, v in rate.items()) + " (zsrm / oracle / random)"


def _table2(d: dict) -> str:
    policies = ("language", "primitive", "none")
    paper = "; ".join(f"{spread} {_slash((d[p][spread]['test']['mean'] for p in policies), '{:.1f}')}"
                      for spread in ("seen", "unseen")) + " (language / primitive / none)"
    best = d["best"]
    ratios = ", ".join(f"{r.replace('_', ' ')} {_slash(v[s] for s in ('seen', 'unseen'))}"
                       for r, v in best["test_over_ceiling"].items())
    teachers = ", ".join(f"{r.replace('_', ' ')} {_slash(v[s] for s in ('seen', 'unseen'))}"
                         for r, v in best.get("test_over_teachers", {}).items())
    return (f"{paper}; zsrm's best ({best['policy']}), test / ceiling, seen / unseen: {ratios}"
            + (f"; test / the teachers that taught it: {teachers}" if teachers else ""))


def _colour(d: dict) -> str:
    cells = (("seen", "train"), ("seen", "test"), ("unseen", "test"))
    return "; ".join(f"{p} {_slash((d[p][s][split]['mean'] for s, split in cells), '{:.1f}')}"
                     for p in ("language", "primitive", "none")) + " (seen train / seen test / unseen test)"


def _choice(d: dict) -> str:
    c = d["checks"]
    best = d[c["policy"]]["test"]
    return (f"{c['policy']} on base {best['on_base']['mean']:.1f}, test / train {c['test_over_train']:.2f}, "
            f"above none by {c['gap_to_none']:.1f} (twice the two s.e. added: {c['two_se_added']:.1f}), on the third block "
            f"{c['third_over_base']:.2f} of its steps on the base")


def _reward_f1(d: dict) -> str:
    zsrm, base = [v["f1"] for v in d["zsrm"].values()], [v["f1"] for v in d["base"].values()]
    return (f"{min(zsrm):.2f} to {max(zsrm):.2f} over {len(zsrm)} tasks (the base reward: "
            f"{min(base):.2f} to {max(base):.2f})")


def _scripted(d: dict) -> str:
    rates = [v for k, v in d.items() if k != "meta"]
    spread = f"{min(rates):.2f}" if min(rates) == max(rates) else f"{min(rates):.2f} to {max(rates):.2f}"
    return f"{spread} on each of {len(rates)} tasks"



FIGURES = [
    # the paper's figures
    Figure("Figure 3: Grad-CAM localisation, median error front / left / tilted (px)", "grounding.json",
           lambda d: _slash(d[f"median_px_error.{c}"] for c in ("front", "left", "tilted")),
           "zsrm eval-grounding data/grounding-box --labels labels-refined --out results/grounding.json "
           "--figure results/figure3.png"),
    Figure("Figure 3: labeler F1, left of / in front of / in between / on top of / close to / inside of",
           "grounding.json",
           lambda d: _slash(d[f"f1.{r}"] for r in ("left_of", "in_front_of", "in_between", "on_top_of", "close_to",
                                                   "inside_of")),
           "zsrm eval-grounding data/grounding-box --labels labels-refined --out results/grounding.json"),
    Figure("Figure 4: pendulum oracle return, base / oracle reward", "rl/summary.json",
           lambda d: f"{_pm(d['pendulum']['base'])} / {_pm(d['pendulum']['oracle'])}", _recorded_command),
    Figure("Figure 5: base reward along a scripted push", "figure5.csv", _figure5,
           "zsrm reward-curve --out results/figure5"),
    Figure("Figure 6: final oracle episode reward", "rl/summary.json", _figure6, _recorded_command),
    Figure("Figure 6, VICE (updated on oracle-labelled frames) beside zsrm and the oracle", "rl/summary.json",
           _figure6_vice, _recorded_command),
    Figure("Figures 4 and 6 with the v2 learner (the default until 2026-12-06): pendulum base / oracle; "
           "zsrm / oracle / base per task", "rl/v2/summary.json",
           lambda d: f"pendulum {_pm(d['pendulum']['base'])} / {_pm(d['pendulum']['oracle'])}; {_figure6(d)}",
           _recorded_command, headline=False),
    Figure("Table 2: distilled policies on the blue test tasks (grey frames)", "table2.json", _table2,
           "zsrm eval-multitask --policies runs/multitask/distill runs/multitask/distill-dagger "
           "runs/multitask/distill-mirror-teachers --seeds 50 --out results/table2.json"),
    # zsrm's own claims
    Figure("Scripted controllers reach every goal (success)", "scripted_success.json", _scripted,
           "zsrm scripted-eval --episodes 20 --out results/scripted_success.json"),
    Figure("Goal sentences read right / must-refuse refused", "goals.json",
           lambda d: f"{d['accuracy']:.3f} / {d['refusal_accuracy']:.3f}", "zsrm eval-goals --out results/goals.json"),
    Figure("Scene VLM presence AUROC, red / green / yellow / blue", "vlm_presence.json",
           lambda d: _slash((d[f"auroc.{c}"] for c in ("red", "green", "yellow", "blue")), "{:.3f}"),
           "zsrm eval-vlm --vlm scene --images 500 --seed 0 --out results/vlm_presence.json"),
    Figure("Pendulum VLM names the pose right", "pendulum_pose.json", lambda d: f"{d['accuracy']:.3f}",
           "zsrm eval-pose --vlm scene-pendulum --images 400 --out results/pendulum_pose.json"),
    Figure("Full reward model (shipped student), F1 against the oracle", "reward_eval.json", _reward_f1,
           "zsrm eval-reward --zsrm student --tasks stack place_left place_right push_close place_below "
           "place_between place_front place_behind place_inside --distractor-tasks stack "
           "--out results/reward_eval.json"),
    Figure("Full model on an own scene (examples/own_scene): labeler F1 for the goals' relations; binarised reward "
           "F1 on three goals, zsrm / base; PPO on two goals (behind, and right of with the v3 learner), 300k steps, "
           "3 seeds",
           "own_scene.json", _own_scene, "python benchmarks/own_scene.py; python benchmarks/own_scene.py --sideways "
           "--work runs/scenes/own_scene"),
    Figure("A scene written from scratch, from its XML alone (examples/slate_scene), through `zsrm own-scene`: "
           "labeler F1 for the goals' relations; the worst object's median Grad-CAM error over half its width; "
           "binarised reward F1 on three goals", "scenes/slate_scene.json", _scene_chain, _recorded_command),
    Figure("The first example (examples/own_scene) through `zsrm own-scene`", "scenes/own_scene.json", _scene_chain,
           _recorded_command, headline=False),
    Figure("robosuite Stack (a Panda, two cubes) through `zsrm own-scene`: binarised reward F1, zsrm / base, against "
           "robosuite's own `_check_success()` (docs/benchmarks.md)", "benchmarks/robosuite.json", _benchmark,
           _recorded_command),
    Figure("LIBERO-Spatial (tasks 0 and 6) through `zsrm own-scene`: binarised reward F1, zsrm / base, against "
           "LIBERO's BDDL `On` predicate (docs/benchmarks.md)", "benchmarks/libero.json", _benchmark,
           _recorded_command),
    Figure("Learning from pixels, each task's own learner (--config per-task: SAC for push_close; the correction and "
           "500k for in between and in front of; 500k for behind; for inside of 500k, gamma 0.99 and the correction "
           "with the height check; else v3, 300k) on the nine relations' tasks: final success rate (the goal holds at "
           "an episode's last step), 3 seeds", "rl/learning.json", _nine, _recorded_command),
    Figure("Learning from pixels, the default learner (v3) on the nine relations' tasks: final success rate, "
           "300k env steps, 3 seeds", "rl/v3/learning.json", _nine, _recorded_command, headline=False),
    Figure("Learning from pixels, v3 at 500k env steps on four placing tasks (in between, in front of, behind, inside of): "
           "final success rate, 3 seeds", "rl/500k/learning.json", _nine, _recorded_command, headline=False),
    Figure("Learning from pixels, v3 with the zsrm reward corrected by the labeler on the policy's frames "
           "(--zsrm-correct-every 5000): final success rate, 300k env steps, 3 seeds", "rl/corrected/learning.json",
           _nine, _recorded_command, headline=False),
    Figure("Learning from pixels, v3 with the zsrm reward corrected every 10000 env steps (--zsrm-correct-every "
           "10000; inside of left out, where the labeler is fooled): final success rate, 300k env steps, 3 seeds",
           "rl/correct10k/learning.json", _nine, _recorded_command, headline=False),
    Figure("Learning from pixels, v3 with the zsrm reward corrected every 10000 env steps at 500k env steps (in "
           "between, in front of): final success rate, 3 seeds", "rl/correct10k-500k/learning.json", _nine,
           _recorded_command, headline=False),
    Figure("Learning from pixels, SAC on pretrained keypoints (--config sac, 500k env steps): final success rate",
           "rl/sac/learning.json", _nine, _recorded_command, headline=False),
    Figure("Learning from pixels, the v2 learner (the default until 2026-12-06), final oracle episode reward",
           "rl/v2/learning.json", _learning, _recorded_command),
    Figure("Table 2 in colour frames (the paper's setting): the paper's three, behaviour cloning",
           "multitask/table2_colour.json", _colour,
           "zsrm eval-multitask --policies runs/multitask/distill-colour --seeds 50 "
           "--out results/multitask/table2_colour.json"),
    Figure("Choice scenes (a third block; colour decides the base): zsrm's best on the blue stacking goals",
           "multitask/choice_scenes.json", _choice,
           "python benchmarks/choice_scenes.py --policies runs/multitask/distill runs/multitask/distill-dagger "
           "runs/multitask/distill-mirror-teachers --names none language grounded grounded_dagger "
           "grounded_mirror_teachers_dagger --best table --out results/multitask/choice_scenes.json"),
    Figure("`make demo`: zsrm-trained policy / random on place_right", "demo.json",
           lambda d: f"{_pm(d, 'zsrm_policy_mean', 'zsrm_policy_se')} / "
                     f"{_pm(d, 'random_policy_mean', 'random_policy_se')}",
           "make demo"),
    Figure("Bad files and paths end in one clean line", "robustness.json",
           lambda d: f"{d['clean']} of {d['tried']} cases, {d['ran_code']} ran code from a file",
           "OMP_NUM_THREADS=1 python benchmarks/robustness.py --out results/robustness.json"),
    Figure("A sweep on a Ray cluster, a worker node killed mid-trial", "cluster.json",
           lambda d: f"{d['trials_finished']} of {d['trials_planned']} trials finished on {d['nodes']} nodes, "
                     f"{d['trials_lost']} lost, the same figures as on one node: "
                     f"{'yes' if d['identical_to_single_node'] else 'no'}",
           "OMP_NUM_THREADS=1 python benchmarks/cluster.py --out results/cluster.json", headline=False),
    # speed
    Figure("Env steps/s, one / three 64 px cameras", "env_speed.json",
           lambda d: _slash((d["steps_per_s_1cam_64"], d["steps_per_s_3cam_64"]), "{:.0f}"),
           "python benchmarks/env_speed.py --out results/env_speed.json"),
    Figure("Batched rewards vs one call per env (speedup)", "reward_batching.json", lambda d: f"{d['ratio']:.1f}x",
           "python benchmarks/reward_batching.py --out results/reward_batching.json"),
    Figure("Grad-CAM, batched head-only gradients vs one backward per phrase (speedup)", "gradcam_speed.json",
           lambda d: f"{d['ratio']:.2f}x", "python benchmarks/gradcam_speed.py --out results/gradcam_speed.json"),
    Figure("Rewards/s, student vs fine-tuned VLM", "reward_speed.json",
           lambda d: f"{d['student_rewards_per_s']:,.0f} vs {d['vlm_rewards_per_s']:,.0f} ({d['ratio']:.1f}x)",
           "python benchmarks/reward_speed.py --vlm runs/zsrm/vlm --student runs/zsrm/student "
           "--out results/reward_speed.json"),
    Figure("Whole `zsrm train` runs, env steps/s: default vs v1", "ppo_speed.json",
           lambda d: f"{d['configs']['cpu']['train_steps_per_s']:.0f} vs {d['configs']['v1']['train_steps_per_s']:.0f} "
                     f"({d['speedup']:.2f}x)",
           "python benchmarks/ppo_speed.py --out results/ppo_speed.json"),
]

# Side experiments, under results/side/: a glob relative to results/ and what the files show.
SIDE = [
    ("side/box/grounding_*.json", "the box located by Grad-CAM of three box-aware VLMs, without the silhouette "
     "refinement: 3.6 to 16.7 px median error, `f1.inside_of` 0.00 for all three (docs/grounding.md)"),
    ("side/reward_eval_finetuned_vlm.json", "the fine-tuned scene VLM and the student trained beside it, on the scenes "
     "before issue 11 (4 tasks; not rerun since)"),
    ("side/pendulum_pose_scene.json", "the scene VLM, which never saw the pendulum, calls every frame upright "
     "(accuracy 0.24)"),
    ("side/multitask/table2_seed0.*", "Table 2 with raw (uncentred) goal embeddings, distillation seed 0"),
    ("side/multitask/table2_seeds.json", "raw goal embeddings over four seeds: language above primitive with two "
     "seeds of four"),
    ("side/multitask/table2_span_*", "raw goal embeddings projected onto the training goals' span (`--text-span`): "
     "no change beyond the standard errors"),
    ("side/multitask/table2_centred_span_*", "centred goal embeddings, projected as well: no change beyond the "
     "standard errors; centring alone is what helps"),
    ("side/multitask/table2_view_colour.*", "the paper's three policies reading colour frames: none follows blue "
     "goals (test 0.4 to 1.3)"),
    ("side/multitask/table2_joint.*", "the VLM's joint image-text embedding of the goal, colour frames: no better"),
    ("side/multitask/table2_grounded*", "zsrm's grounded policy with each `--keypoint-view` (none, shape, grey, "
     "colour) and distillation seed 1"),
    ("side/multitask/blue_sensitivity*.json", "moving the blue block moves the policies' keypoints and actions as much "
     "as moving a training colour's: seeing blue is not what differs"),
    ("side/multitask/goal_probe_*.json", "the distilled policies reading another goal's sentence on a goal's scenes: "
     "the goal's colours do not matter to them"),
    ("side/multitask/grounded_nearest_goal_*.json", "the grounded policy reading its nearest training goal instead of "
     "the test goal scores 0.00 on every test task: a primitive code does not help it"),
    ("side/multitask/task_policy_distractor.json", "the two-block task policies with a third block added: disrupted, "
     "but not stacking on it as their base"),
    ("side/multitask/choice/task_policy_distractor.json", "the choice-scene task policies stack on their base, almost "
     "never on the third block"),
    ("side/multitask/choice/base_probe.json", "which block each distilled policy stacks on in choice scenes: only the "
     "grounded one finds its base by colour"),
    ("side/multitask/grounded_none_dagger/*", "the grounded policy seeing only its grounding (`--keypoint-view none`), "
     "3 DAgger rounds: the student stacks at 92.5 to 92.7 on the training tasks and places at 0 to 9.9 (`distill.json` "
     "and each round's record of `zsrm distill --policies grounded --dagger-rounds 3 --out runs/multitask/distill-dagger-none`)"),
    ("side/multitask/table2_dagger9.*", "zsrm's grounded policy after nine DAgger rounds instead of six: no better on "
     "the right of (test 18.2 / 19.7, seen / unseen)"),
    ("side/multitask/table2_mirror.*", "zsrm's grounded policy distilled with half its frames mirrored left to right "
     "(`zsrm distill --mirror`): behaviour cloning places left and right alike but weakly (19.9 / 14.7, test, seen); "
     "after six DAgger rounds left of 64.8, right of still 17.1"),
    ("side/multitask/table2_mirror_teachers_seed1.*", "zsrm's grounded policy from mirrored teachers with distillation "
     "seed 1 (Table 2's is seed 0): behaviour cloning places left at 61.5 and right at 20.9, six DAgger rounds take "
     "both above 66 (test over ceiling 1.15 / 1.08 left, 1.61 / 1.49 right)"),
    ("side/multitask/choice_mirror_teachers_bc.json", "choice scenes: zsrm's grounded policy from mirrored teachers, "
     "behaviour cloning alone, stacks on its base at 44.5 / 45.7 (training / blue goals); its six DAgger rounds take "
     "it down to 28.3 / 25.6"),
    ("side/multitask/relation_word_probe.json", "the grounded policies reading their placing goal with left and right "
     "swapped (probes/relation_word_probe.py): zsrm's best drops from 59.4 to 4.4 on the test goals, so it places by the "
     "word, not by the start layout alone"),
    ("side/multitask/v1/**", "Table 2 as measured before 2026-12-05, from the v1 task policies (200k steps, action "
     "repeat 2; placing at 1 to 49): the table, distillation seeds 1-3, choice scenes and their task policies"),
    ("side/scenes/*_vlm_seeds.json", "the stand-in VLM's pretraining seeds with and without zoomed views on both "
     "example scenes (probes/vlm_seed_probe.py): the masking check against each object's true localisation error"),
    ("side/scenes/slate_scene_nozoom.json", "the slate scene through zsrm own-scene without zoomed views (--zoom 0, "
     "the default before 2026-12-05): not usable, one object's Grad-CAM point sits 2.6 px from it on the left "
     "camera, over half its width (2.1 px)"),
    ("side/scenes/own_scene_nozoom.json", "the first example through zsrm own-scene without zoomed views"),
    ("side/scenes/own_scene_8k_images.json", "the first example through zsrm own-scene with 8000 exploration "
     "images and 4000 student steps (the shipped student's recipe; its VLM stage copied from the default run, so "
     "its wall time leaves that stage out): not better than the default on the left-of goal"),
    ("side/scenes/own_scene_a32639f_rerun.json", "the code that wrote results/own_scene.json (a32639f) rerun on "
     "another CPU (session of 2026-12-07 afternoon): other numbers than the committed file's"),
    ("side/scenes/slate_scene_epyc_avx512.json", "the slate scene's one command rerun on the CPU that reproduces "
     "results/own_scene.json (AMD EPYC family 26, AVX-512): usable there too, another VLM seed kept"),
    ("side/scenes/own_scene_student_seeds.json", "the first example's reward F1 per student: three student seeds on "
     "the old settings' labels and three on the one command's, a longer student and swapped text towers "
     "(docs/own-scene.md)"),
    ("side/scenes/own_scene_student_ensembles.json", "the first example's students alone and their mean margins "
     "in twos and threes (probes/student_ensemble.py)"),
    ("side/scenes/own_scene_epyc_one_student.json", "the first example's one command with one student (--students 1, "
     "the default before 2026-12-07) on the AMD EPYC CPU that reproduces results/own_scene.json"),
    ("side/scenes/own_scene_student_ensembles_intel.json", "the first example's three default students alone, in pairs "
     "and all three by mean margin, on the Intel Xeon CPU that wrote results/scenes/own_scene.json"),
    ("side/scenes/own_scene_seed0_intel.json", "the first example through zsrm own-scene with the old script's "
     "settings (seed 0 alone, no zoomed views, one student) on the Intel Xeon CPU of results/scenes/own_scene.json"),
    ("side/scenes/own_scene_seed0.json", "the first example through zsrm own-scene with seed 0 alone and no zoomed "
     "views, the settings results/own_scene.json was made with: its numbers to the digit, on its CPU"),
    ("side/own_scene/starts.json", "random and forward-leaning policies per start layout and pusher step of the "
     "example scene (probes/own_scene_starts.py): why its goals train in compact scenes with 1 cm steps"),
    ("side/rl/push_close_sides.json", "a push_close oracle policy (v3, seed 1) succeeds as often whichever side its "
     "puck starts on (17 of 52 and 14 of 48 episodes): not one fixed push (probes/push_sides.py)"),
    ("side/rl/reward_eval_student_hold_free.json", "a student shown blocks held anywhere in reach (4000 images, "
     "--p-hold-free 0.5): in between 0.93, inside of lost; not shipped (docs/training.md, issue 52)"),
    ("side/rl/reward_hacking_place_between_500k.json", "a place_between zsrm policy (500k, seed 1) holds the yellow "
     "block 0.27 m above the table wherever the others are: the student pays in 0.95 of decisions, the oracle "
     "in 0.44, the goal labeler (Grad-CAM + Table 1) in 0.43, agreeing with the oracle in 0.994 "
     "(probes/reward_hacking.py --labeler)"),
    ("side/rl/reward_hacking_place_between_ceiling0.18.json", "the same with --lift-ceiling 0.18 (300k, seed 0): "
     "held 0.12 m up, the student pays in 0.78, the oracle in 0.53"),
    ("side/rl/reward_hacking_place_inside_corrected.json", "a place_inside zsrm policy trained with the corrected "
     "reward (--zsrm-correct-every 5000 --gamma 0.99, seed 0; scored 0): the block rests 0.18 m from the box, the "
     "goal labeler says inside of in 0.29 of decisions, the oracle in none (probes/reward_hacking.py --labeler)"),
    ("side/grounding/box_area_check.json", "the goal labeler on place_inside frames where the yellow block rests "
     "away from the box (3 motions x 6 episodes): inside of said in 368 of 1728 without the box check (the box's "
     "Grad-CAM point on the block), 4 with it (--zsrm-correct-box-area 0.0115); the scripted goal frames' recall "
     "0.94 both ways (probes/box_area_check.py)"),
    ("side/rl/reward_hacking_place_inside_box_area.json", "a place_inside zsrm policy trained with the box check "
     "(--zsrm-correct-every 10000 --zsrm-correct-box-area 0.0115 --gamma 0.99, seed 1; scored 19.7): the reward pays "
     "in 0.72 of decisions, the oracle in 0.21; the block held 8 cm up over the box, which the goal labeler on the "
     "tilted camera calls inside of in 0.57 of those frames (height and depth look alike there)"),
    ("side/rl/reward_hacking_place_inside_height.json", "a place_inside zsrm policy trained with the height check "
     "and labelled exploration renders (--zsrm-correct-height --zsrm-correct-explore 1024, seed 2; scored 21.3): the "
     "reward pays in 0.05 of decisions, the oracle in 0.21; where only the oracle pays the block is held 5.7 cm up "
     "(its centre), 0.6 cm off the box's centre: low in the box, not let go, which the oracle reads on the table "
     "plane as inside of and a ceiling of half a block width does not"),
    ("side/grounding/inside_front_check.json", "the goal labeler's front check (--zsrm-correct-front) and height "
     "check (--zsrm-correct-height) on place_inside frames of the block held 8 cm up, 0-4 cm in front of the box, "
     "never let go (4 episodes each): the tilted camera's labeler says inside of in 149 and 222 of 384 frames at 4 "
     "and 3 cm, 73 and 144 with the front check, 0 with the height check (none of the 1536 held frames); the "
     "scripted goal frames' recall 0.94, 0.91 and 0.91 (probes/inside_front_check.py)"),
    ("side/rl/push_close_ends.json", "a push_close oracle policy (500k, seed 0) by start side, and its 20 of 30 "
     "episodes that never succeed: the pucks end 14.5 cm apart (close to: under 10), the nearest 14.3: the push "
     "stops short (probes/push_sides.py)"),
    ("side/rl/push_scripts.json", "scripts on push_close's true state: one that steers the pusher back onto its puck's "
     "line succeeds in 40 of 40 episodes at action repeat 4, pushing straight in 0.15, zsrm's controller (made for "
     "action repeat 1) 0.93 / 0.78 / 0.30 at 1 / 2 / 4 (probes/push_scripts.py)"),
    ("side/rl/push_state/*.json", "PPO on push_close's true state (a probe): v3's settings 0.38, as on pixels, and "
     "0.04-0.39 under 19 others; relative positions in 10 cm units 0.89 on seeds 0-2 and 0.46 on 3-5 (500k); SAC 0.88 "
     "(3 seeds), 0.80 with one gradient step per 4 decisions, 0.47 with 1 cm of noise on each position "
     "(probes/push_state_ppo.py, each file's meta.command)"),
    ("side/rl/push_pixel_sac/**", "stable-baselines3's SAC on push_close (probes/push_pixel_sac.py, each summary's "
     "meta.command): from pixels 0.30 at 300k, PPO's plateau; on the frozen keypoints of a PPO policy 0.47-0.63 "
     "(3 seeds, 7 min a run); PPO 200k at 64 px then SAC 300k: 0.54 (oracle) and 0.48 (zsrm) on PPO seed 0, "
     "0.44 over the PPO stage's seeds 0-2 (oracle); with the pixel CNN at stride 2, 0.80 on PPO seed 0 and 0.52 "
     "over seeds 0-2; on a keypoint autoencoder's keypoints (no reward, no PPO stage; --anneal-lr) 0.51 (oracle) and "
     "0.56 (zsrm) over 3 SAC seeds, at 476k SAC steps 0.70 and 0.59; the same learner on place_front (zsrm, "
     "seed 0, 300k SAC steps) 0.70, where PPO reads 0.47"),
    ("side/rl/keypoint_precision*.json", "how many cm a frozen extractor's keypoints miss push_close's pusher and pucks "
     "by (probes/keypoint_precision.py): the pucks about 1 cm for all, the pusher 4-5 cm for most PPO extractors and "
     "1-3 cm for those SAC did well on, 0.5-0.9 cm trained on true places, 0.4-0.6 cm for the keypoint autoencoder "
     "with inverse dynamics"),
    ("side/rl/keypoint_ae/*/*", "keypoint autoencoders of push_close's tilted camera (place_front's front camera in "
     "place_front/) trained on random-action frames "
     "(probes/keypoint_autoencoder.py; each training.json's meta.command): the frozen extractors SAC reads"),
]

# Files beside the figures: plots and tables of them, the models and runs they come from.
OTHER = [
    ("README.md", "this page"),
    ("figure3.png", "Figure 3: Grad-CAM heat maps and their points"),
    ("figure5.png", "Figure 5's plot"),
    ("vlm_presence.png", "the scene VLM's presence ROC curves"),
    ("table2.*", "Table 2 as CSV, markdown and a bar plot"),
    ("reward_curves/*", "base and zsrm reward along scripted episodes of each task (written with reward_eval.json)"),
    ("multitask/policies.*", "the 18 zsrm-trained task policies' training summary (300k steps each)"),
    ("multitask/task_policies/**", "the 18 task policies themselves, read by `zsrm multitask-rollouts`"),
    ("multitask/trials/*", "their trial summaries, so a rerun of the sweep skips them"),
    ("multitask/table2_colour.*", "Table 2 in colour frames as CSV, markdown and a bar plot"),
    ("own_scene/*", "the own-scene stages' measurements (the labeler, the reward, each stage's seconds), written by "
     "benchmarks/own_scene.py before it became a call of zsrm own-scene (2026-12-05)"),
    ("own_scene/pilots/**", "runs on the example's goals in settings that did not learn: every object anywhere "
     "(300k steps); compact scenes with 2 cm pusher steps (500k); the sideways goal's first column starts "
     "(docs/own-scene.md, step 12)"),
    ("own_scene/sideways/**", "the sideways goal's PPO sweep (python benchmarks/own_scene.py --sideways): its "
     "summary, curves and trial summaries, gathered into own_scene.json's ppo_sideways"),
    ("own_scene/trials/*", "the trial summaries of benchmarks/own_scene.py's PPO sweep (learning.json, .png)"),
    ("rl/**", "learning runs, Figures 4 and 6 trials, the training-speed profile, pilots and reward-hacking "
     "diagnostics (docs/training.md, docs/training-speed.md)"),
]


def _read(results: Path, file: str) -> dict:
    path = results / file
    if path.suffix == ".csv":
        with path.open() as f:
            return {"rows": [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]}
    return json.loads(path.read_text())


def figure_rows(results: Path, link_prefix: str = "", headline_only: bool = False) -> list[str]:
    """One markdown table row per figure, its value read from its file."""
    return [f.row(_read(results, f.file), link_prefix) for f in FIGURES if f.headline or not headline_only]


def headline(results: Path = Path("results")) -> str:
    """README.md's headline table, between its markers: figure, value, file (commands on the page)."""
    rows = [" | ".join(row.split(" | ")[:3]) + " |" for row in figure_rows(results, "results/", headline_only=True)]
    return "\n".join([HEADLINE_START, "| result | value | file |", "|---|---|---|", *rows, HEADLINE_END])


def page(results: Path = Path("results")) -> str:
    """results/README.md: every canonical figure with its value and command, then what else is here."""
    lines = ["# Results", "",
             "Written by `zsrm results-page` from the files it names; do not edit by hand. Each figure's value is",
             "read from its file, so this page and README.md's headline table change only when a file does.",
             "Measured on the project's 2-core x86_64 CPU machine (no GPU) unless a file says otherwise;",
             "`make results` reruns every command.", "",
             "## Canonical figures", "", "| figure | value | file | command |", "|---|---|---|---|",
             *figure_rows(results), "",
             "## Side experiments (`side/`)", "",
             "Measured on the way to the figures above: what was tried, what did not help, and why.", "",
             *(f"* `{pattern}`: {what}" for pattern, what in SIDE), "",
             "## Other files", "", *(f"* `{pattern}`: {what}" for pattern, what in OTHER), ""]
    return "\n".join(lines)


def unlisted(results: Path = Path("results"), files: list[str] | None = None) -> list[str]:
    """Files under results/ that neither a figure nor a line of the page names."""
    patterns = [f.file for f in FIGURES] + [p for p, _ in SIDE + OTHER]
    files = files if files is not None else [str(p.relative_to(results)) for p in results.rglob("*") if p.is_file()]
    # fnmatch's * spans folders too
    return sorted(f for f in files if not any(fnmatch.fnmatch(f, p.replace("**", "*")) for p in patterns))


def readme_with_headline(readme: str, results: Path = Path("results")) -> str:
    """README.md's text with the table between its markers replaced by :func:`headline`."""
    start, end = readme.index(HEADLINE_START), readme.index(HEADLINE_END) + len(HEADLINE_END)
    return readme[:start] + headline(results) + readme[end:]


@dataclass
class ResultsPage:
    """Write results/README.md and README.md's headline table from the result files."""

    results: str = "results"  # the results folder
    readme: str = "README.md"  # the README whose headline table to rewrite ('' to skip)
    check: bool = False  # write nothing; exit 1 if either file differs from what would be written

    def run(self) -> int:
        results = Path(self.results)
        if not self.check:
            for path in [results / "README.md", *([Path(self.readme)] if self.readme else [])]:
                check_writable(path)
        wanted = {results / "README.md": page(results)}
        if self.readme:
            wanted[Path(self.readme)] = readme_with_headline(Path(self.readme).read_text(), results)
        stale = [path for path, text in wanted.items() if not path.is_file() or path.read_text() != text]
        for path in stale:
            print(f"{'differs' if self.check else 'wrote'}: {path}")
            if not self.check:
                write_text(path, wanted[path])
        return 1 if self.check and stale else 0

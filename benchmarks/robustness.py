"""results/robustness.json: every bad file and bad path ends in one clean line (issue 16).

For each class of hostile input, the number of cases tried at the command line, how many ended
in one clean line (exit status 2, one line on stderr ``zsrm CMD: error: ...`` naming the file
or path; for kills and mid-run full disks: the rerun resumed to the same result), and how many
ran code from a file (a pickle whose loading would create a marker file; must be 0):

* corrupt_weights: model.safetensors (or adapters.safetensors) empty, truncated, random
  bytes, cut inside its header, for each saved kind (scene VLM, student, adapted VLM,
  open_clip, PPO policy), through ``zsrm reward --vlm``, ``zsrm eval-reward --zsrm`` and
  ``zsrm rollout``;
* bad_configs: config.json a list, a required key missing, a string where a number (or a
  boolean) belongs, an unknown key; a checkpoint's state.json and optimizer.json damaged;
  a data manifest damaged;
* mismatched_sizes: a config whose sizes are not those of the weights; a checkpoint of another
  model;
* pickled_state: pickles in place of weights, of a resume checkpoint's optimizer state
  (finetune, pretrain-vlm, train) and of a data shard;
* unwritable_output: every command that writes, its output below a regular file and in a
  read-only place;
* full_disk: every command that writes (but sweep, whose writes happen in Ray workers, plot and
  the multi-task commands, which need a sweep's results, and reproduce, which runs the commands
  counted here) with
  each atomic write failing with ENOSPC, and collect and label filling the disk mid-run, then
  rerun to the same data;
* kill_and_resume: collect, label, finetune, pretrain-vlm and train killed (SIGKILL) after
  their first shard or checkpoint, rerun, compared with an uninterrupted run.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/robustness.py --out results/robustness.json
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np

from zsrm.cli import main
from zsrm.testing import hostile as H

GOAL = "a red block on top of a blue block"
TRAIN = ["--goal", "push_close", "--steps", "256", "--n-envs", "2", "--n-steps", "32", "--batch-size", "32",
         "--eval-episodes", "2", "--eval-every", "128", "--checkpoint-every", "128", "--n-epochs", "1",
         "--keypoints", "4"]
COLLECT = ["--images", "24", "--shard-size", "6"]
FINETUNE = ["--student", "--steps", "120", "--batch-size", "32", "--checkpoint-every", "40", "--eval-every", "1000",
            "--val-pairs", "64", "--threads", "1"]
PRETRAIN = ["--arch", "tiny", "--scenes", "32", "--shard-size", "16", "--image-size", "32", "--steps", "60",
            "--batch-size", "16", "--checkpoint-every", "20", "--warmup-steps", "5", "--threads", "1"]


class Tally:
    def __init__(self):
        self.classes: dict[str, dict] = {}

    def add(self, cls: str, case: str, clean: bool, ran_code: bool = False, detail: str = "") -> None:
        c = self.classes.setdefault(cls, {"tried": 0, "clean": 0, "ran_code": 0, "cases": []})
        c["tried"] += 1
        c["clean"] += int(clean)
        c["ran_code"] += int(ran_code)
        c["cases"].append({"case": case, "clean": clean, **({"detail": detail[:300]} if detail else {})})
        print(f"{cls:18s} {'clean' if clean else 'NOT CLEAN':9s} {case}: {detail[:150]}", flush=True)


def cli(argv: list[str]) -> tuple[int, str]:
    """``zsrm ARGV`` in this process: (exit status, stderr)."""
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exit_:
            rc = exit_.code
        except Exception as exc:  # a traceback: not clean
            rc, err = -1, io.StringIO(f"{type(exc).__name__}: {exc}\nTraceback")
    return rc, err.getvalue()


def one_clean_line(rc: int, err: str, names: str | Path | None = None) -> bool:
    """Exit status 2, no traceback, and the error as one line ``zsrm CMD: error: ...`` naming
    ``names``, last on stderr (a progress bar the command drew before may come first)."""
    lines = [line for line in err.strip().splitlines() if line.strip()]
    errors = [line for line in lines if ": error: " in line]
    return (rc == 2 and "Traceback" not in err and len(errors) == 1 and lines[-1] == errors[0]
            and errors[0].startswith("zsrm ") and (names is None or str(names) in errors[0]))


def check(tally: Tally, cls: str, case: str, argv: list, names=None, marker: Path | None = None) -> None:
    rc, err = cli(argv)
    ran = bool(marker and marker.exists())
    tally.add(cls, case, one_clean_line(rc, err, names) and not ran, ran, err.strip())


def loaders(model: str, folder: Path, image: Path, tmp: Path) -> list[tuple[str, list]]:
    """The commands that load a saved folder of this kind: (name, argv)."""
    if model == "policy":
        return [("rollout", ["rollout", folder, "--episodes", "1"])]
    out = [("reward", ["reward", "--vlm", folder, "--goal", GOAL, image])]
    if model in ("student", "adapted"):
        out.append(("eval-reward", ["eval-reward", "--zsrm", folder, "--out", tmp / "x.json", "--curves", ""]))
    return out


def model_cases(tally: Tally, models: dict, image: Path, tmp: Path, marker: Path) -> None:
    for kind, model in models.items():
        for damage, apply in H.WEIGHT_DAMAGE.items():
            folder = H.broken_copy(model, f"w-{damage}")
            apply(folder / model.weights)
            for name, argv in loaders(kind, folder, image, tmp):
                check(tally, "corrupt_weights", f"{kind} {damage} ({name})", argv, folder / model.weights)
        folder = H.broken_copy(model, "w-pickle")
        H.write_pickle_bomb(folder / model.weights, marker)
        for name, argv in loaders(kind, folder, image, tmp):
            check(tally, "pickled_state", f"{kind} weights a pickle ({name})", argv, folder / model.weights, marker)
        for damage, change in H.config_damage(model.resize, model.required).items():
            folder = H.broken_copy(model, f"c-{damage}")
            (folder / "config.json").write_text(json.dumps(change(json.loads((folder / "config.json").read_text()))))
            cls, named = ("mismatched_sizes", folder / model.weights) if damage == "sizes_not_the_weights" else \
                ("bad_configs", folder / "config.json")
            for name, argv in loaders(kind, folder, image, tmp):
                check(tally, cls, f"{kind} {damage} ({name})", argv, named)


def stage_data(tmp: Path) -> Path:
    """A small collected and labelled dataset (the scene VLM's Grad-CAM captions)."""
    data = tmp / "data"
    assert cli(["collect", "--out", data, *COLLECT, "--quiet"])[0] == 0
    assert cli(["label", data, "--quiet"])[0] == 0
    return data


def checkpoint_cases(tally: Tally, data: Path, tmp: Path, marker: Path) -> None:
    """A resume checkpoint of finetune, pretrain-vlm and train: pickled optimiser state (optimizer.pt),
    damaged state.json / optimizer.json, the optimiser of another model."""
    runs = {
        "finetune": ["finetune", "--data", data, "--out", tmp / "ft", *FINETUNE[:1], "--steps", "2",
                     "--checkpoint-every", "1", "--batch-size", "8", "--val-pairs", "8", "--quiet"],
        "pretrain-vlm": ["pretrain-vlm", "--out", tmp / "pt", "--workdir", tmp / "pt.work", *PRETRAIN[:8],
                         "--steps", "2", "--batch-size", "8", "--checkpoint-every", "1", "--quiet"],
        "train": ["train", "--out", tmp / "rl", *TRAIN[:2], "--steps", "128", *TRAIN[4:]],
    }
    ckpts = {"finetune": tmp / "ft.work" / "checkpoint", "pretrain-vlm": tmp / "pt.work" / "checkpoint",
             "train": tmp / "rl" / "checkpoint"}
    for stage, argv in runs.items():
        rc, err = cli(argv)
        assert rc == 0, f"{stage}: {err[-3000:]}"
        for name in ("summary.json",):
            (tmp / "rl" / name).unlink(missing_ok=True)
        good = ckpts[stage].with_name("checkpoint.good")
        shutil.copytree(ckpts[stage], good)
        for damage in ("pickle", "state_list", "state_string_step", "optimizer_json_list", "other_model"):
            shutil.rmtree(ckpts[stage])
            shutil.copytree(good, ckpts[stage])
            named, cls = _damage_checkpoint(ckpts[stage], damage, marker, stage)
            check(tally, cls, f"{stage} resume, {damage.replace('_', ' ')}", argv, named, marker)


def _damage_checkpoint(folder: Path, damage: str, marker: Path, stage: str) -> tuple[Path, str]:
    if damage == "pickle":
        for name in ("optimizer.json", "optimizer.safetensors"):
            (folder / name).unlink()
        H.write_pickle_bomb(folder / "optimizer.pt", marker, torch_format=True)
        return folder / "optimizer.pt", "pickled_state"
    if damage.startswith("state"):
        state = json.loads((folder / "state.json").read_text())
        key = "env_steps" if stage == "train" else "step"
        (folder / "state.json").write_text(json.dumps([state] if damage == "state_list" else
                                                      {**state, key: str(state[key])}))
        return folder / "state.json", "bad_configs"
    saved = json.loads((folder / "optimizer.json").read_text())
    if damage == "optimizer_json_list":
        (folder / "optimizer.json").write_text(json.dumps([saved]))
        return folder / "optimizer.json", "bad_configs"
    group = saved["param_groups"][0]  # the optimiser of another model: one parameter fewer
    group["params"] = group["params"][:-1]
    (folder / "optimizer.json").write_text(json.dumps(saved))
    return folder / "optimizer.json", "mismatched_sizes"


def data_cases(tally: Tally, data: Path, tmp: Path, marker: Path) -> None:
    """A damaged manifest (eval-grounding, finetune read it) and a pickled shard (label reads it)."""
    for damage in ("not_json", "a_list", "missing_shards"):
        folder = tmp / f"data-{damage}"
        shutil.copytree(data, folder)
        manifest = json.loads((folder / "manifest.json").read_text())
        (folder / "manifest.json").write_text({"not_json": "{oops", "a_list": json.dumps([manifest]),
                                               "missing_shards": json.dumps({**manifest, "shards": None})}[damage])
        check(tally, "bad_configs", f"data manifest {damage} (eval-grounding)",
              ["eval-grounding", folder, "--out", tmp / "g.json"], folder / "manifest.json")
    folder = tmp / "data-pickle"
    shutil.copytree(data, folder)
    shutil.rmtree(folder / "labels")
    np.save(folder / "bomb.npy", np.array([H._Bomb(marker)], dtype=object), allow_pickle=True)
    (folder / "bomb.npy").replace(folder / "shard_00000.npz")
    check(tally, "pickled_state", "data shard a pickle (label)", ["label", folder, "--quiet"],
          folder / "shard_00000.npz", marker)


def writers(tmp: Path, out: Path, data: Path) -> dict[str, list]:
    """Every command that writes, at a tiny scale, its output (folder) at ``out``."""
    return {
        "collect": ["collect", "--out", out, "--images", "4", "--shard-size", "2", "--quiet"],
        "render": ["render", "stack", "--size", "32", "--out", out / "x.png"],
        "scripted-eval": ["scripted-eval", "--tasks", "stack", "--episodes", "1", "--out", out / "x.json"],
        "reward-curve": ["reward-curve", "--steps", "3", "--out", out / "fig"],
        "eval-reward": ["eval-reward", "--zsrm", "student", "--tasks", "stack", "--scripted-episodes", "1",
                        "--random-episodes", "1", "--curves", "", "--out", out / "x.json", "--quiet"],
        "label": ["label", data, "--labels", out, "--quiet"],
        "finetune": ["finetune", "--data", data, "--out", out, "--student", "--steps", "2", "--batch-size", "8",
                     "--val-pairs", "8", "--workdir", tmp / f"ft-{out.name}.work", "--quiet"],
        "eval-grounding": ["eval-grounding", data, "--out", out / "x.json"],
        "reward-data": ["reward-data", "--out", out, "--images", "4", "--shard-size", "2", "--quiet"],
        "pretrain-vlm": ["pretrain-vlm", "--out", out, "--workdir", tmp / f"pt-{out.name}.work", *PRETRAIN[:8],
                         "--steps", "2", "--batch-size", "8", "--quiet"],
        "eval-vlm": ["eval-vlm", "--images", "10", "--out", out / "x.json", "--min-auroc", "0", "--quiet"],
        "demo": ["demo", "--out", out, "--episodes", "1"],
        "train": ["train", "--out", out, *TRAIN],
        "rollout": ["rollout", "random:stack", "--episodes", "1", "--out", out / "x.json"],
        "sweep": ["sweep", "--root", out, "--tasks", "stack", "--rewards", "random", "--seeds", "0",
                  "--out", tmp / f"sweep-{out.name}.json"],
        "plot": ["plot", "--summary", tmp / "learning.json", "--figure6", out / "figure6.png"],
        "reproduce": ["reproduce", "--workdir", out, "--report", tmp / f"report-{out.name}"],
        "multitask-policies": ["multitask-policies", "--root", out, "--out", tmp / f"policies-{out.name}.json"],
        "multitask-rollouts": ["multitask-rollouts", "--out", out],
        "distill": ["distill", "--out", out],
        "eval-multitask": ["eval-multitask", "--out", out / "table2.json"],
    }


def output_cases(tally: Tally, data: Path, tmp: Path) -> None:
    for where, out in H.unwritable_paths(tmp).items():
        for command, argv in writers(tmp, out, data).items():
            check(tally, "unwritable_output", f"{command}, output {where}", argv, out)
    for command in writers(tmp, tmp, data):
        if command in ("sweep", "plot", "reproduce") or "multitask" in command or command == "distill":
            continue  # sweep's trials write from Ray workers, which this process cannot make full; plot and
            # the multi-task stages need a sweep's results; reproduce runs the stages counted here one by one
        argv = writers(tmp, tmp / "full" / command, data)[command]
        with H.full_disk():
            rc, err = cli(argv)
        tally.add("full_disk", f"{command}, every write", one_clean_line(rc, err) and "no space left" in err,
                  detail=err.strip())
    for command in ("collect", "label"):
        full_disk_resume(tally, command, data, tmp)


def same_data(a: Path, b: Path) -> bool:
    """The same shards (arrays, NaN equal to NaN) and JSON files in two folders (and their oracle/)."""
    def files(folder):
        return sorted(p.relative_to(folder) for p in [*folder.glob("*"), *folder.glob("oracle/*")]
                      if p.suffix in (".npz", ".json") and p.name != "manifest.json")

    if not files(a) or files(a) != files(b):
        return False
    from zsrm.data.shards import load_npz

    for rel in files(a):
        if rel.suffix == ".json" and json.loads((a / rel).read_text()) != json.loads((b / rel).read_text()):
            return False
        if rel.suffix == ".npz":
            x, y = load_npz(a / rel), load_npz(b / rel)
            if set(x) != set(y) or not all(np.array_equal(x[k], y[k], equal_nan=x[k].dtype.kind == "f") for k in x):
                return False
    return True


def full_disk_resume(tally: Tally, command: str, data: Path, tmp: Path) -> None:
    """The disk fills after a few writes; the rerun (disk free again) must give the same data."""
    target = tmp / f"full-{command}"
    if command == "collect":
        argv, compare = ["collect", "--out", target, *COLLECT, "--quiet"], (target, data)
    else:
        shutil.copytree(data, target)
        shutil.rmtree(target / "labels")
        argv, compare = ["label", target, "--quiet"], (target / "labels", data / "labels")
    with H.full_disk(after=4 if command == "collect" else 6):
        rc, err = cli(argv)
    first = one_clean_line(rc, err) and "no space left" in err
    rc2, err2 = cli(argv)
    tally.add("full_disk", f"{command}, disk full mid-run then rerun", first and rc2 == 0 and same_data(*compare),
              detail=err.strip())


def zsrm_process(argv: list) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "zsrm.cli", *map(str, argv)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env={**os.environ, "OMP_NUM_THREADS": "1"})


def kill_when(proc: subprocess.Popen, ready, timeout: float = 600) -> bool:
    """SIGKILL ``proc`` as soon as ``ready()``; whether it was killed before it finished."""
    deadline = time.time() + timeout
    while proc.poll() is None and not ready() and time.time() < deadline:
        time.sleep(0.02)
    killed = proc.poll() is None
    proc.send_signal(signal.SIGKILL) if killed else None
    proc.wait()
    return killed


def kill_cases(tally: Tally, data: Path, tmp: Path) -> None:
    def shards_done(folder):
        def ready():
            try:
                return len(json.loads((folder / "manifest.json").read_text())["shards"]) >= 1
            except (OSError, ValueError, KeyError):
                return False
        return ready

    stages = {
        "collect": (lambda out: ["collect", "--out", out, *COLLECT, "--quiet"], shards_done, lambda out: out),
        "label": (lambda out: ["label", out, "--quiet"], lambda out: shards_done(out / "labels"),
                  lambda out: out / "labels"),
        "finetune": (lambda out: ["finetune", "--data", data, "--out", out, *FINETUNE, "--quiet"],
                     lambda out: (lambda: (out.with_name(out.name + ".work") / "checkpoint" / "state.json").is_file()),
                     lambda out: out),
        "pretrain-vlm": (lambda out: ["pretrain-vlm", "--out", out, "--workdir", out.with_name(out.name + ".work"),
                                      *PRETRAIN, "--quiet"],
                         lambda out: (lambda: (out.with_name(out.name + ".work") / "checkpoint" / "state.json").is_file()),
                         lambda out: out),
        "train": (lambda out: ["train", "--out", out, *TRAIN],
                  lambda out: (lambda: (out / "checkpoint" / "state.json").is_file()), lambda out: out),
    }
    for stage, (argv, ready, result) in stages.items():
        whole, killed = tmp / f"kill-{stage}-whole", tmp / f"kill-{stage}-killed"
        if stage == "label":
            for folder in (whole, killed):
                shutil.copytree(data, folder)
                shutil.rmtree(folder / "labels")
        assert cli(argv(whole))[0] == 0, stage
        was_killed = kill_when(zsrm_process(argv(killed)), ready(killed))
        rc, err = cli(argv(killed))
        same = same_result(stage, result(whole), result(killed))
        tally.add("kill_and_resume", stage, was_killed and rc == 0 and same,
                  detail=f"killed mid-run: {was_killed}; rerun exit {rc}; same result: {same}")


def same_result(stage: str, a: Path, b: Path) -> bool:
    if stage in ("collect", "label"):
        return same_data(a, b)
    if stage == "train":  # PPO resumes with the same step count and a curve that continues
        sa, sb = (json.loads((p / "summary.json").read_text()) for p in (a, b))
        steps = [row["env_steps"] for row in sb["curve"]]
        return sa["env_steps"] == sb["env_steps"] == 256 and steps == sorted(set(steps)) == [128, 256]
    from safetensors.torch import load_file

    x, y = load_file(str(a / "model.safetensors")), load_file(str(b / "model.safetensors"))
    return set(x) == set(y) and all(bool((x[k] == y[k]).all()) for k in x)


def run(keep: Path | None) -> dict:
    tmp = Path(keep or tempfile.mkdtemp(prefix="zsrm-robustness-"))
    tmp.mkdir(parents=True, exist_ok=True)
    marker = tmp / "CODE-RAN-FROM-A-FILE"
    tally, t0 = Tally(), time.time()
    try:
        cases(tally, tmp, marker)
    finally:
        if keep is None:
            shutil.rmtree(tmp, ignore_errors=True)
    return report(tally, time.time() - t0)


def cases(tally: Tally, tmp: Path, marker: Path) -> None:
    models = H.saved_models(tmp / "models")
    image = tmp / "frame.png"
    from PIL import Image

    Image.fromarray(np.zeros((32, 32, 3), np.uint8)).save(image)
    model_cases(tally, models, image, tmp, marker)
    data = stage_data(tmp)
    checkpoint_cases(tally, data, tmp, marker)
    data_cases(tally, data, tmp, marker)
    output_cases(tally, data, tmp)
    kill_cases(tally, data, tmp)


def report(tally: Tally, seconds: float) -> dict:
    tried = sum(c["tried"] for c in tally.classes.values())
    clean = sum(c["clean"] for c in tally.classes.values())
    ran = sum(c["ran_code"] for c in tally.classes.values())
    return {
        "classes": {k: {"tried": v["tried"], "clean": v["clean"], "ran_code": v["ran_code"],
                        "clean_fraction": v["clean"] / v["tried"]} for k, v in tally.classes.items()},
        "tried": tried, "clean": clean, "ran_code": ran, "clean_fraction": clean / tried,
        "cases": {k: v["cases"] for k, v in tally.classes.items()},
        "meta": {
            "command": "OMP_NUM_THREADS=1 .venv/bin/python benchmarks/robustness.py --out results/robustness.json",
            "clean": "exit status 2 and one stderr line 'zsrm CMD: error: ...' naming the file or path (full disk: "
                     "saying no space is left); for kill_and_resume and a full disk mid-run: the rerun finished and "
                     "gave the same shards and captions (collect, label), bit-identical final weights (finetune, "
                     "pretrain-vlm), or the same final step count with a curve that continues (train: PPO's "
                     "env seeds restart at the checkpoint, so the policy is not bit-identical)",
            "ran_code": "cases after which the marker file a pickle's __reduce__ would create exists",
            "seconds": round(seconds, 1),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores, no GPU",
        },
    }


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/robustness.json")
    parser.add_argument("--keep", default=None, help="work in this folder and keep it (default: a temporary one)")
    args = parser.parse_args()
    result = run(Path(args.keep) if args.keep else None)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps({k: result[k] for k in ("classes", "tried", "clean", "ran_code", "clean_fraction")}, indent=1))
    print(f"wrote {args.out}")

"""``zsrm own-scene``: the whole chain on a scene zsrm was not built for, in one command.

    zsrm own-scene --scene mylab.scenes:Mugs --out runs/mugs \\
        --goals "a red mug on the left of a blue plate" "a red mug behind a green bowl"

Stages, each a zsrm command run in this process, skipped when its output is there (a killed run
loses no finished stage), each with one progress line:

1. ``vlm``: ``pretrain-vlm --scene`` for each of ``--vlm-seeds``: the stand-in VLM learns the
   objects' names from presence captions of renders and of zoomed views of them (refused
   before training when the captions never vary); each seed is checked on held-out renders, by presence AUROC and masking
   agreement (:mod:`zsrm.grounding.selfcheck`: does hiding an object's Grad-CAM point lower that
   object's score most?), and the seed whose least-agreeing object agrees most is kept. Both
   read the images and which objects each render holds, never where (``vlm.json``);
2. ``reward-data --scene``: exploration labelled by the kept VLM's Grad-CAM;
3. ``collect --scene --seed 1`` and ``label``: held-out exploration (its true positions are
   evaluation only);
4. ``eval-grounding``: the labeler against the scene's oracle per relation, and each object's
   localisation error against the true pixels per camera (evaluation only);
5. ``finetune --student``: the reward model, on stage 2's Grad-CAM captions: ``--students`` of them,
   seeds 0..N-1 (``student/``, ``student-seed1/``, ...), one reward of their mean image-text score
   (the ensemble ``students/``; with ``--students 1`` the one ``student/``);
6. ``eval-reward --scene``: the binarised reward's F1 against the oracle per goal, base beside;
7. ``sweep --scene`` (with ``--ppo-goal``): PPO with the oracle, zsrm and random rewards.

**Gates.** After the stages that can fail without a word, one line each names what failed and
what to try: an object present in every render or below the presence floor, no seed whose
Grad-CAM agrees with its own scores on every object (the masking check), an object whose
median localisation error is over half its width on a camera its goals read it on, a relation
of the goals below ``--labeler-floor``, a goal whose reward F1 is below ``--reward-floor`` or
not above the base reward. A failed gate stops the chain (``--keep-going`` runs on) and the
command exits 1: the chain is not usable as it stands. The report (``report.md``,
``summary.json``, ``localisation.png``) is written in every case.
"""
from __future__ import annotations

import shlex
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from zsrm.common import files, machine
from zsrm.rl.config import PresetName

SUMMARY, REPORT, FIGURE = "summary.json", "report.md", "localisation.png"
PRESENCE_FLOOR = 0.95  # eval-vlm's --min-auroc
CHECK_IMAGES = 300  # held-out renders of each VLM check
# The lowest per-object masking agreement a VLM must reach. Measured on 16 stand-in VLMs of two
# scenes (probes/vlm_seed_probe.py, results/side/scenes/): all 7 below 0.85 lost an object (the best
# of them read 0.81); those that kept every object within half its width read 0.86 to 0.99. A filter,
# not a proof: the localisation gate, against the true pixels, has the last word.
MASKING_FLOOR = 0.85


@dataclass
class Gate:
    stage: str
    ok: bool
    line: str


@dataclass
class SceneChain:
    """Run the whole own-scene chain on an adapter and its goals (resumable; a report at the end).

    Each stage is a zsrm command run in this process and skipped when its output is there; gates
    after the stages that can fail silently print one line and exit 1 (docs/own-scene.md).
    """

    scene: str  # your scene's adapter: module:Class or a registered id (docs/own-scene.md)
    goals: tuple[str, ...] = field(metadata={"split": False})  # goal sentences over its objects: the labeler and the reward are judged on them
    out: str  # folder of every stage's data, models and the report
    results: str | None = None  # also write the summary JSON here (e.g. results/scenes/NAME.json)
    vlm_seeds: tuple[int, ...] = (0, 1, 2, 3)  # stand-in VLM pretraining seeds; kept: the one whose Grad-CAM agrees best with its own scores (the masking check)
    pretrain_scenes: int = 800  # renders per pretraining (x3 cameras)
    pretrain_steps: int = 2000  # pretraining steps
    arch: str = "tiny"  # the stand-in VLM's architecture preset (tiny, default)
    zoom: float = 0.5  # share of each pretraining batch shown as zoomed views (presence captions of a window of a render); 0: none, as before 2026-12-05
    images: int = 4000  # exploration images the reward model trains on
    eval_images: int = 1000  # held-out exploration images (evaluation)
    finetune_steps: int = 3000  # the student's steps
    students: int = 3  # students trained, seeds 0..N-1; the reward is their mean image-text score (students/); 1: one student (student/), as before 2026-12-07
    ppo_goal: str | None = None  # also train PPO on this goal, with the oracle, zsrm and random rewards
    ppo_seeds: tuple[int, ...] = (0, 1, 2)  # PPO seeds
    ppo_steps: int = 300_000  # env steps per PPO run
    ppo_config: PresetName = "cpu"  # the PPO runs' TrainConfig preset (zsrm train --config)
    labeler_floor: float = 0.85  # gate: the labeler's F1 on each relation the goals use
    reward_floor: float = 0.85  # gate: each goal's binarised reward F1
    keep_going: bool = False  # run every stage even after a gate fails
    until: str | None = None  # stop after this stage (vlm, reward-data, held-out, eval-grounding, finetune, eval-reward, sweep)
    threads: int = 1  # torch threads of each stage
    num_cpus: int = 2  # Ray CPUs of the PPO sweep
    quiet: bool = False  # no progress bars inside the stages
    dry_run: bool = False  # print the stages and stop

    # --- the chain ---------------------------------------------------------------------------
    def run(self) -> int:
        from zsrm.envs.adapter import load_adapter
        from zsrm.tasks.scene_goals import parse_scene_goal

        adapter = load_adapter(self.scene)
        if not self.goals:
            raise ValueError("give --goals: goal sentences over the scene's objects")
        self.goal_objects = {g: parse_scene_goal(g, adapter.objects, self.scene) for g in self.goals}
        if self.ppo_goal:
            parse_scene_goal(self.ppo_goal, adapter.objects, self.scene)
        self.vlm_seeds, self.ppo_seeds = tuple(map(int, self.vlm_seeds)), tuple(map(int, self.ppo_seeds))
        if not self.vlm_seeds:
            raise ValueError("give at least one --vlm-seeds")
        self.students = int(self.students)
        if self.students < 1:
            raise ValueError(f"--students must be >= 1 (1: one student, as before), got {self.students}")
        out = files.check_writable(self.out, folder=True)
        if self.results:
            files.check_writable(self.results)
        stages = self.stages(out)
        if self.until and self.until not in [s[0] for s in stages]:
            raise ValueError(f"--until {self.until!r}: the stages are {', '.join(s[0] for s in stages)}")
        self.check_settings(out)
        torch_threads(self.threads)
        seconds, gates = self.run_stages(out, stages)
        if self.dry_run:
            return 0
        summary = self.summary(out, adapter, seconds, gates)
        files.write_json(out / SUMMARY, summary, indent=1)
        if self.results:
            files.write_json(self.results, summary, indent=1)
        write_report(out, summary)
        failed = sum(not g.ok for g in gates)
        if failed:
            print(f"the chain is not usable as it stands: {failed} gate{'s' if failed > 1 else ''} failed (above)",
                  file=sys.stderr)
        print(f"report: {out / REPORT}" + (f"; summary: {self.results}" if self.results else ""))
        return 1 if failed else 0

    def run_stages(self, out: Path, stages) -> tuple[dict, list[Gate]]:
        """Each stage not done yet, its time, and the gates after it (stopping at a failed one
        unless ``keep_going``)."""
        seconds_file = out / "stage_seconds.json"
        seconds = files.read_json(seconds_file, "the stage times") if seconds_file.is_file() else {}
        gates: list[Gate] = []
        for i, (name, run, done) in enumerate(stages, 1):
            head = f"[{i}/{len(stages)}] {name}"
            if self.dry_run:
                print(f"{head}: {done}")
                continue
            if done.is_file() and name == "eval-reward" and not set(self.goals) <= set(
                    files.read_json(done, "the reward evaluation").get("zsrm", {})):
                done.unlink()  # goals added since: score them all again
            if done.is_file():
                print(f"{head}: done ({done})", flush=True)
            else:
                print(f"{head} ...", flush=True)
                t = time.time()
                run()
                seconds[name] = round(time.time() - t, 1) if name != "vlm" else vlm_seconds(out, self.vlm_seeds)
                files.write_json(seconds_file, seconds, indent=1)
                print(f"{head}: done in {seconds[name]:.0f} s", flush=True)
            new = self.gates_after(name, out)
            for g in new:  # right after the stage: what failed, and what to try
                print(f"{'ok' if g.ok else 'FAILED'} [{g.stage}] {g.line}", file=sys.stdout if g.ok else sys.stderr,
                      flush=True)
            gates += new
            if (any(not g.ok for g in gates) and not self.keep_going) or name == self.until:
                break
        return seconds, gates

    def command(self) -> str:
        """The command line of these options (those not at their defaults), to rerun it."""
        import dataclasses

        words = ["zsrm", "own-scene"]
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            default = f.default if f.default is not dataclasses.MISSING else None
            if value == default or (isinstance(value, tuple) and value == tuple(default or ())) or \
                    f.name in ("quiet", "dry_run", "keep_going", "until"):
                continue
            flag = "--" + f.name.replace("_", "-")
            if isinstance(value, bool):
                words.append(flag)
            else:
                words += [flag, *map(str, value if isinstance(value, tuple) else (value,))]
        return shlex.join(words)

    SETTINGS = ("scene", "vlm_seeds", "pretrain_scenes", "pretrain_steps", "arch", "zoom", "images", "eval_images",
                "finetune_steps", "students")
    # a chain.json written before a setting existed: the value the chain ran with then
    LEGACY = {"students": 1}

    def check_settings(self, out: Path) -> None:
        """A folder's stages were made with one set of settings: a rerun with others is refused
        (its finished stages would be skipped), in one line."""
        mine = {k: list(v) if isinstance(v, tuple) else v for k, v in ((k, getattr(self, k)) for k in self.SETTINGS)}
        path = out / "chain.json"
        if path.is_file():
            have = {**self.LEGACY, **files.read_json(path, "the chain's settings")}
            diff = [f"{k}: {have.get(k)!r} there, {mine[k]!r} here" for k in mine if have.get(k) != mine[k]]
            if diff:
                keep = f"--students {have['students']}, " if have.get("students") != mine["students"] else ""
                raise ValueError(f"{out} holds a chain run with other settings ({'; '.join(diff)}): give {keep}"
                                 "another --out, or delete it")
        elif not self.dry_run:
            files.write_json(path, mine, indent=1)

    def stages(self, out: Path) -> list[tuple[str, callable, Path]]:
        """(name, run, the file it leaves when finished)."""
        from zsrm.pipeline.build import Collect, Label, RewardData
        from zsrm.pipeline.learn import Sweep
        from zsrm.pipeline.measure import EvalGrounding, EvalReward

        q, scene = self.quiet, self.scene
        stages = []
        stages.append(("vlm", lambda: self.pretrain_vlms(out), out / "vlm.json"))
        vlm = lambda: str(self.chosen_vlm(out))  # noqa: E731  (known once the vlm stage has run)
        train, held_out, reward = out / "train-data", out / "eval-data", self.reward_model(out)
        stages += [
            ("reward-data", lambda: RewardData(scene=scene, vlm=vlm(), out=str(train), images=self.images,
                                               shard_size=250, quiet=q).run(), train / "labels" / "manifest.json"),
            ("held-out", lambda: (Collect(scene=scene, out=str(held_out), images=self.eval_images, shard_size=250,
                                          seed=1, quiet=q).run(),
                                  Label(data=str(held_out), vlm=vlm(), quiet=q).run()),
             held_out / "labels" / "manifest.json"),
            ("eval-grounding", lambda: EvalGrounding(data=str(held_out), out=str(out / "grounding.json")).run(),
             out / "grounding.json"),
            ("finetune", lambda: self.train_students(out, train, vlm()),
             reward / ("config.json" if self.students > 1 else "training.json")),
            ("eval-reward", lambda: EvalReward(scene=scene, data=str(held_out), zsrm=str(reward), base=vlm(),
                                               tasks=tuple(self.goals), out=str(out / "reward_eval.json"), curves="",
                                               quiet=q).run(), out / "reward_eval.json"),
        ]
        if self.ppo_goal:
            stages.append(("sweep", lambda: Sweep(scene=scene, tasks=(self.ppo_goal,), rewards=("oracle", "zsrm", "random"),
                                                  seeds=tuple(self.ppo_seeds), steps=self.ppo_steps, vlm=vlm(),
                                                  reward_model=str(reward), root=str(out / "rl"),
                                                  num_cpus=self.num_cpus, config=self.ppo_config,
                                                  out=str(out / "learning.json")).run(),
                           out / "learning.json"))
        return stages

    # --- the stand-in VLM: several seeds, one kept ---------------------------------------------
    def pretrain_vlms(self, out: Path) -> None:
        """Pretrain a stand-in VLM per seed, each checked on held-out renders (presence AUROC,
        masking agreement); keep the one whose least-agreeing object agrees most (``vlm.json``).
        A killed run resumes at the seed it was on."""
        from zsrm.pipeline.build import PretrainVlm

        checks = {}
        for seed in self.vlm_seeds:
            folder = out / f"vlm-seed{seed}"
            if not (folder / "config.json").is_file():
                print(f"  pretrain-vlm seed {seed} ...", flush=True)
                t = time.time()
                PretrainVlm(scene=self.scene, out=str(folder), workdir=str(out / f"pretrain-seed{seed}"), arch=self.arch,
                            scenes=self.pretrain_scenes, shard_size=100, steps=self.pretrain_steps, batch_size=64,
                            checkpoint_every=500, warmup_steps=50, threads=self.threads, seed=seed, zoom=self.zoom,
                            quiet=self.quiet).run()
                files.write_json(folder / "seconds.json", {"pretrain": round(time.time() - t, 1)})
            path = folder / "check.json"
            if not path.is_file():
                t = time.time()
                check = check_vlm(folder, self.scene, n_images=CHECK_IMAGES, progress=not self.quiet)
                files.write_json(path, {**check, "seconds": round(time.time() - t, 1)}, indent=1)
            checks[seed] = files.read_json(path, "a VLM check")
            worst = checks[seed]["masking"]["min"]
            print(f"  seed {seed}: lowest masking agreement {worst if worst is None else round(worst, 3)}, lowest "
                  f"presence AUROC {min((v for v in checks[seed]['presence_auroc'].values() if v is not None), default=None)}",
                  flush=True)
        best = max(checks, key=lambda s: (checks[s]["masking"]["min"] or 0.0,
                                          np.mean([v or 0.0 for v in checks[s]["presence_auroc"].values()]), -s))
        files.write_json(out / "vlm.json", {
            "chosen": str(out / f"vlm-seed{best}"), "seed": best, "masking_floor": MASKING_FLOOR,
            "rule": "every seed pretrained and checked; kept: the highest lowest per-object masking agreement "
                    "(then the mean presence AUROC). Both read held-out renders and which objects each holds, never "
                    "where",
            "checks": {str(s): c for s, c in checks.items()}}, indent=1)

    @staticmethod
    def chosen_vlm(out: Path) -> Path:
        """The VLM the ``vlm`` stage kept in the chain folder ``out``."""
        return Path(files.read_json(out / "vlm.json", "the kept VLM")["chosen"])

    # --- the reward model: one student per seed, their mean score ------------------------------
    def reward_model(self, out: Path) -> Path:
        """The folder the rewards score with: the ensemble ``students/``, or with one student ``student/``."""
        return out / ("students" if self.students > 1 else "student")

    def student_folders(self, out: Path) -> list[Path]:
        """One student per seed 0..N-1: seed 0 in ``student/`` (as before ``--students``), seed S in
        ``student-seedS/``."""
        return [out / ("student" if seed == 0 else f"student-seed{seed}") for seed in range(self.students)]

    def train_students(self, out: Path, data: Path, vlm: str) -> None:
        """``finetune --student --seed S`` for each seed not done yet (a student is done once its
        ``training.json`` is there: a killed run keeps the finished ones, and the one it was on
        resumes from its checkpoint), then, with more than one, the ensemble ``students/``."""
        from zsrm.fullmodel.ensemble import write_ensemble
        from zsrm.pipeline.build import Finetune

        folders = self.student_folders(out)
        for seed, folder in enumerate(folders):
            if (folder / "training.json").is_file():
                continue
            if len(folders) > 1:
                print(f"  finetune --student --seed {seed} ({seed + 1} of {len(folders)}) ...", flush=True)
            Finetune(data=str(data), student=True, vlm=vlm, out=str(folder), steps=self.finetune_steps, seed=seed,
                     threads=self.threads, quiet=self.quiet).run()
        if len(folders) > 1:
            write_ensemble(self.reward_model(out), folders, meta={
                "rule": "the mean of the members' image-text cosines (each member's unit embeddings side by side, "
                        "scaled by 1/sqrt(N)); the binarised reward's argmax is taken on the mean",
                "seeds": list(range(len(folders)))})

    # --- gates -----------------------------------------------------------------------------
    def read_on(self) -> dict[str, set[str]]:
        """Object -> the camera roles the goals read it on."""
        from zsrm.tasks.relations import RELATIONS

        roles: dict[str, set[str]] = {}
        for goal in self.goal_objects.values():
            for o in goal.objects:
                roles.setdefault(o, set()).add(RELATIONS[goal.relation].camera)
        return roles

    def gates_after(self, stage: str, out: Path) -> list[Gate]:
        if stage == "vlm":
            return vlm_gates(files.read_json(out / "vlm.json", "the kept VLM"))
        if stage == "eval-grounding":
            report = files.read_json(out / "grounding.json", "the grounding report")
            loc = object_localisation(out, report)
            return localisation_gates(loc, self.read_on()) + labeler_gates(report, self.relations(), self.labeler_floor)
        if stage == "eval-reward":
            return reward_gates(files.read_json(out / "reward_eval.json", "the reward evaluation"), self.goals,
                                self.reward_floor)
        return []

    def relations(self) -> list[str]:
        return sorted({g.relation for g in self.goal_objects.values()})

    # --- the summary -----------------------------------------------------------------------
    def summary(self, out: Path, adapter, seconds: dict, gates: list[Gate]) -> dict:
        def read(name):
            return files.read_json(out / name, name) if (out / name).is_file() else None

        grounding, reward, learning, vlm = (read("grounding.json"), read("reward_eval.json"), read("learning.json"),
                                            read("vlm.json"))
        result: dict = {"scene": adapter.name, "goals": list(self.goals)}
        if grounding:
            world = grounding["relations"]["vs_world"]
            result["labeler_f1"] = {r: world[r]["f1"] for r in self.relations()}
            result["labeler"] = {r: {k: v[k] for k in ("precision", "recall", "f1", "support")} for r, v in world.items()}
            result["localisation"] = object_localisation(out, grounding)
        if reward:
            result["reward_f1"] = {g: {m: reward[m][g]["f1"] for m in ("zsrm", "base")} for g in self.goals}
            result["reward"] = {g: {m: {k: reward[m][g][k] for k in ("f1", "precision", "recall", "auroc", "positives",
                                                                     "frames")} for m in ("zsrm", "base")}
                                for g in self.goals}
        if vlm:
            result["vlm"] = {"seed": vlm["seed"], "rule": vlm["rule"],
                             "checks": {s: {"masking_min": c["masking"]["min"], "presence_auroc": c["presence_auroc"]}
                                        for s, c in vlm["checks"].items()}}
        if learning and self.ppo_goal in learning:
            result["ppo"] = ppo_cells(learning, self.ppo_goal)
        result["gates"] = [{"stage": g.stage, "ok": g.ok, "line": g.line} for g in gates]
        result["usable"] = all(g.ok for g in gates)
        result["meta"] = {
            "command": self.command(), "wall_s": round(sum(seconds.values()), 1),
            "stage_seconds": seconds, "bare_xml": bool(adapter.xml and not adapter.env_id),
            "students": self.students, "reward_model": self.reward_model(out).name,
            "machine": machine.describe(), "out": str(out),
            "numbers": "Float results move across CPUs (docs/own-scene.md); on one machine a rerun is identical"}
        return result


def torch_threads(n: int) -> None:
    if n > 0:
        import torch

        torch.set_num_threads(n)


# --- checks and gates (functions, so that tests and other commands read them) ----------------
def check_vlm(folder: Path, scene: str, n_images: int = 300, seed: int = 0, progress: bool = False) -> dict:
    """A stand-in VLM of an own scene: presence AUROC per object and masking agreement (Grad-CAM
    as zsrm label runs it) on held-out renders; reads which objects each render holds, never where."""
    from zsrm.data.own_renders import disc_radius, render_own_scenes
    from zsrm.envs.adapter import ROLES, load_adapter
    from zsrm.evaluation.vlm_presence import own_presence_eval
    from zsrm.grounding.annotate import LabelConfig
    from zsrm.grounding.gradcam import GradCAM
    from zsrm.grounding.selfcheck import masking_agreement
    from zsrm.vlm import load_vlm
    from zsrm.vlm.presence import min_visible_pixels

    vlm, adapter = load_vlm(str(folder)), load_adapter(scene)
    presence, _ = own_presence_eval(vlm, scene, n_images=n_images, seed=seed, progress=progress)
    renders = render_own_scenes(adapter, range(n_images // len(ROLES)), seed=seed + 1, stream="eval")
    cfg = LabelConfig()
    grad = GradCAM(vlm, target=cfg.target, contrast=adapter.objects, locate=cfg.locate, cell_centres=cfg.cell_centres,
                   presence_threshold=None, batch_size=cfg.batch_size, template=cfg.template)
    size = renders["images"].shape[1]
    first = renders["images"][:8]
    grad.set_centres(grad.calibrate(first), (size, size))
    if cfg.locate == "fine":
        grad.set_centres(grad.calibrate(first, fine=True), (size, size), fine=True)
    present = renders["visible"] >= min_visible_pixels(size)
    # each object hidden under a disc of its own median visible area (segmentation counts: which
    # pixels a render shows of it, read here for the disc's size only)
    radius = np.array([disc_radius(renders["visible"][present[:, j], j]) if present[:, j].any() else 2.0
                       for j in range(len(adapter.objects))])
    masking = masking_agreement(vlm, grad, renders["images"], present, adapter.objects, radius)
    return {"presence_auroc": {k.split(".", 1)[1]: v for k, v in presence.items() if k.startswith("auroc.")},
            "presence_counts": presence["meta"]["counts"], "masking": masking,
            "mask_radius_px": {o: round(float(r), 2) for o, r in zip(adapter.objects, radius)}}


def ppo_cells(learning: dict, goal: str) -> dict:
    """A goal's PPO result in a scene's summary, from a sweep's gathered ``learning.json``: per
    reward (oracle, zsrm, random) the final mean, its s.e. over seeds, each seed's, and the steps."""
    cells = {r: {"mean": c["final_mean"], "se": c["final_se"], "seeds": c["seeds"],
                 "final_per_seed": c["final_per_seed"], "steps": c["steps"]}
             for r, c in learning[goal].items() if r in ("oracle", "zsrm", "random")}
    if "oracle" in cells and "zsrm" in cells and cells["oracle"]["mean"]:
        cells["zsrm_over_oracle"] = cells["zsrm"]["mean"] / cells["oracle"]["mean"]
    return {"goal": goal, **cells}


def vlm_seconds(out: Path, seeds) -> float:
    """The vlm stage's time: each tried seed's pretraining and check, as each recorded it."""
    total = 0.0
    for seed in seeds:
        folder = out / f"vlm-seed{seed}"
        for name, key in (("seconds.json", "pretrain"), ("check.json", "seconds")):
            if (folder / name).is_file():
                total += files.read_json(folder / name, "a VLM's times").get(key, 0.0)
    return round(total, 1)


def vlm_gates(vlm: dict) -> list[Gate]:
    """Presence of each object for the kept VLM: learnable (absent from some renders) and learnt."""
    check = vlm["checks"][str(vlm["seed"])]
    gates = []
    for obj, counts in check["presence_counts"].items():
        auroc = check["presence_auroc"][obj]
        if counts["absent"] == 0:
            gates.append(Gate("vlm", False, f"{obj!r} is present in every render: the VLM cannot learn which word "
                                            "is it; let scenes hold subsets (bodies, or an env with objects=)"))
        elif auroc is None or not auroc >= PRESENCE_FLOOR:
            gates.append(Gate("vlm", False, f"{obj!r}: presence AUROC {auroc} < {PRESENCE_FLOOR}; try more "
                                            "--pretrain-steps or --pretrain-scenes, or --arch default"))
    worst, floor = check["masking"]["min"], vlm.get("masking_floor", MASKING_FLOOR)
    if worst is None or worst < floor:
        low = [o for o, v in check["masking"]["agreement"].items() if v is None or v < floor]
        gates.append(Gate("vlm", False, f"no seed's Grad-CAM points at every object: hiding the point of "
                          f"{', '.join(map(repr, low))} rarely lowers its score most (agreement {worst}); try more "
                          "--vlm-seeds, --pretrain-steps or --zoom"))
    if not gates:
        gates.append(Gate("vlm", True, f"seed {vlm['seed']} kept; presence AUROC >= {PRESENCE_FLOOR} for every "
                                       f"object, lowest masking agreement {worst:.2f}"))
    return gates


def object_widths(out: Path, scene: str) -> dict[str, dict[str, float]]:
    """Object -> role -> its width in pixels: the diameter of a disc of its median visible area in
    the first pretraining's renders (MuJoCo segmentation, evaluation only)."""
    from zsrm.data.own_renders import disc_radius
    from zsrm.envs.adapter import ROLES, load_adapter
    from zsrm.vlm.presence import min_visible_pixels

    adapter = load_adapter(scene)
    renders = sorted(out.glob("pretrain-seed*/own-renders"))
    if not renders:
        return {}
    visible, camera = [], []
    for shard in sorted(renders[0].glob("*.npz")):
        with np.load(shard) as z:
            visible.append(z["visible"])
            camera.append(z["camera"])
    if not visible:
        return {}
    visible, camera = np.concatenate(visible), np.concatenate(camera)
    size = int(files.read_json(renders[0] / "manifest.json", "the renders' settings")["image_size"])
    out_widths: dict[str, dict[str, float]] = {}
    for j, obj in enumerate(adapter.objects):
        for r, role in enumerate(ROLES):
            v = visible[(camera == r) & (visible[:, j] >= min_visible_pixels(size)), j]
            if len(v):
                out_widths.setdefault(obj, {})[role] = 2 * disc_radius(v)
    return out_widths


def object_localisation(out: Path, grounding: dict) -> dict:
    """Object -> role -> ``{"median_error_px", "half_width_px"}``: Grad-CAM's median error against
    the true pixels on the held-out data (eval-grounding's flat keys) and half the object's width."""
    widths = object_widths(out, grounding["meta"]["own_scene"]["adapter"])
    table: dict = {}
    prefix = "median_px_error_by_colour."
    for key, err in grounding.items():
        if not key.startswith(prefix):
            continue
        role, obj = key[len(prefix):].split(".", 1)
        width = widths.get(obj, {}).get(role, grounding[f"block_width_px.{role}"])  # no renders: the adapter's width
        table.setdefault(obj, {})[role] = {"median_error_px": None if err is None else round(float(err), 2),
                                           "half_width_px": round(float(width) / 2, 2)}
    return table


def localisation_gates(loc: dict, read_on: dict[str, set[str]]) -> list[Gate]:
    gates = []
    for obj, roles in sorted(read_on.items()):
        for role in sorted(roles):
            cell = loc.get(obj, {}).get(role)
            if cell is None or cell["median_error_px"] is None:
                gates.append(Gate("eval-grounding", False, f"{obj!r} was never located on the {role} camera"))
            elif cell["median_error_px"] > cell["half_width_px"]:
                gates.append(Gate("eval-grounding", False, f"{obj!r} not localised on the {role} camera: median error "
                                  f"{cell['median_error_px']:.1f} px > half its width {cell['half_width_px']:.1f} px; "
                                  "try more --vlm-seeds or --pretrain-steps, or --arch default"))
    if not gates:
        gates.append(Gate("eval-grounding", True, "every goal object localised within half its width on the cameras "
                                                  "its goals read"))
    return gates


def labeler_gates(grounding: dict, relations, floor: float) -> list[Gate]:
    world = grounding["relations"]["vs_world"]
    gates = []
    for rel in relations:
        f1 = world.get(rel, {}).get("f1")
        if f1 is None or not f1 >= floor:
            gates.append(Gate("eval-grounding", False, f"the labeler reads {rel!r} at F1 {f1} < {floor} against the "
                              "scene's oracle: captions of it are unreliable; see the localisation lines, or a scene "
                              "whose random exploration shows the relation more often"))
    if not gates:
        gates.append(Gate("eval-grounding", True, f"labeler F1 >= {floor} on " + ", ".join(relations)))
    return gates


def reward_gates(reward: dict, goals, floor: float) -> list[Gate]:
    gates = []
    for g in goals:
        z, b = reward["zsrm"][g]["f1"], reward["base"][g]["f1"]
        if z is None or not z >= floor:
            gates.append(Gate("eval-reward", False, f"reward F1 {z} < {floor} on {g!r}: the reward would mislead PPO; "
                              "check the labeler on its relation and more --images or --finetune-steps"))
        elif b is not None and not z > b:
            gates.append(Gate("eval-reward", False, f"reward F1 {z:.3f} on {g!r} is not above the base reward's {b:.3f}"))
    if not gates:
        gates.append(Gate("eval-reward", True, f"reward F1 >= {floor} and above the base reward on every goal"))
    return gates


# --- the report --------------------------------------------------------------------------------
def write_report(out: Path, summary: dict) -> Path:
    """``report.md`` (and ``localisation.png``) of a chain's summary."""
    lines = [f"# {summary['scene']}", "", f"Usable: **{'yes' if summary['usable'] else 'no'}**", ""]
    lines += [f"* {'ok' if g['ok'] else 'FAILED'} [{g['stage']}] {g['line']}" for g in summary["gates"]]
    if "localisation" in summary:
        roles = sorted({r for cells in summary["localisation"].values() for r in cells})
        lines += ["", "## Localisation (median Grad-CAM error / half the object's width, px; held-out data)", "",
                  "| object | " + " | ".join(roles) + " |", "|---|" + "---|" * len(roles)]
        for obj, cells in summary["localisation"].items():
            lines.append(f"| {obj} | " + " | ".join(
                f"{cells[r]['median_error_px']} / {cells[r]['half_width_px']}" if r in cells else "-" for r in roles) + " |")
        if plot_localisation(summary["localisation"], out / FIGURE):
            lines += ["", f"![localisation]({FIGURE})"]
    if "labeler" in summary:
        lines += ["", "## Labeler against the scene's oracle (held-out data)", "", "| relation | F1 | support |",
                  "|---|---|---|"]
        lines += [f"| {r} | {_fmt(v['f1'])} | {v['support']} |" for r, v in summary["labeler"].items()]
    if "reward" in summary:
        lines += ["", "## Binarised reward against the oracle (held-out frames holding the goal's objects)", "",
                  "| goal | zsrm F1 | base F1 | zsrm AUROC | positives / frames |", "|---|---|---|---|---|"]
        lines += [f"| {g} | {_fmt(v['zsrm']['f1'])} | {_fmt(v['base']['f1'])} | {_fmt(v['zsrm']['auroc'])} | "
                  f"{v['zsrm']['positives']} / {v['zsrm']['frames']} |" for g, v in summary["reward"].items()]
    if "ppo" in summary:
        p = summary["ppo"]
        lines += ["", f"## PPO on {p['goal']!r} (final oracle episode reward, mean +- s.e. over seeds)", ""]
        lines += [f"* {r}: {p[r]['mean']:.1f} +- {p[r]['se']:.1f}" for r in ("oracle", "zsrm", "random") if r in p]
    meta = summary["meta"]
    n = meta.get("students", 1)  # a summary written before --students: one student
    lines += ["", "Reward model: " + (f"the mean image-text score of {n} students, seeds 0-{n - 1} (`students/`)"
                                      if n > 1 else "one student, seed 0 (`student/`)") + "."]
    lines += ["", f"Command: `{meta['command']}`; {meta['wall_s']:.0f} s of stages on {meta['machine']}. "
              f"{meta['numbers']}.", ""]
    path = out / REPORT
    with files.atomic_path(path) as tmp:
        Path(tmp).write_text("\n".join(lines))
    return path


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.3f}"


def plot_localisation(loc: dict, path: Path) -> bool:
    """Bars of each object's median error beside half its width, one panel per camera."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    roles = sorted({r for cells in loc.values() for r in cells})
    if not roles:
        return False
    fig, axes = plt.subplots(1, len(roles), figsize=(4 * len(roles), 3), squeeze=False)
    objects = list(loc)
    x = np.arange(len(objects))
    for ax, role in zip(axes[0], roles):
        err = [loc[o].get(role, {}).get("median_error_px") or 0 for o in objects]
        half = [loc[o].get(role, {}).get("half_width_px") or 0 for o in objects]
        ax.bar(x - 0.2, err, 0.4, label="median error")
        ax.bar(x + 0.2, half, 0.4, label="half width")
        ax.set_xticks(x, objects, rotation=30, ha="right", fontsize=8)
        ax.set_title(role)
        ax.set_ylabel("pixels")
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    with files.atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)
    return True


__all__ = ["Gate", "SceneChain", "check_vlm", "labeler_gates", "localisation_gates", "object_localisation",
           "object_widths", "reward_gates", "vlm_gates", "write_report"]

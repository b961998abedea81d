"""Hostile inputs, made small and on the spot: damaged weights and configs, pickles that would
run code, paths that cannot be written, a disk that fills up. Shared by
``tests/test_hostile_inputs.py`` and ``benchmarks/robustness.py``.

* :func:`saved_models`: one tiny saved folder of every kind the registry loads (scene VLM,
  student, adapted VLM, open_clip model, PPO policy), with what to load it with and which
  config key changes the model's sizes.
* :data:`WEIGHT_DAMAGE`, :func:`config_damage`: what a broken copy of such a folder looks like.
* :func:`write_pickle_bomb`: a pickle whose loading would create a marker file (so a test can
  tell whether anything ran).
* :func:`full_disk`: every atomic write from now on fails with ENOSPC (after ``after`` good ones).

>>> import tempfile
>>> path = Path(tempfile.mkdtemp()) / "w.safetensors"
>>> _ = path.write_bytes(b"12345678" * 8)
>>> _ = WEIGHT_DAMAGE["empty"](path)
>>> path.stat().st_size
0
"""
from __future__ import annotations

import builtins
import errno
import json
import os
import pickle
import shutil
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

# Damaged weights files: each turns a good safetensors file into a bad one in place.
WEIGHT_DAMAGE: dict[str, Callable[[Path], None]] = {
    "empty": lambda p: p.write_bytes(b""),
    "truncated": lambda p: p.write_bytes(p.read_bytes()[: max(9, p.stat().st_size - 64)]),
    "random_bytes": lambda p: p.write_bytes(os.urandom(4096)),
    "cut_in_header": lambda p: p.write_bytes(p.read_bytes()[:8 + int.from_bytes(p.read_bytes()[:8], "little") // 2]),
}



def unwritable_paths(tmp: Path) -> dict[str, Path]:
    """Places no command can write: below a regular file (for any user), and a read-only place
    (/sys, which refuses even root; a folder without write permission when not root)."""
    blocker = tmp / "a-file"
    blocker.write_text("not a folder\n")
    paths = {"below_a_file": blocker / "out"}
    if _sys_refuses():
        paths["read_only"] = Path("/sys/zsrm-robustness/out")
    elif os.geteuid() != 0:
        locked = tmp / "read-only"
        locked.mkdir(exist_ok=True)
        locked.chmod(0o555)
        paths["read_only"] = locked / "out"
    return paths


def _sys_refuses() -> bool:
    try:
        Path("/sys/zsrm-robustness-probe").mkdir()
    except OSError:
        return True
    Path("/sys/zsrm-robustness-probe").rmdir()
    return False


class _Bomb:
    """Unpickling this creates ``marker``: proof that a loader ran code from a file."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return builtins.open, (self.marker, "w")


def write_pickle_bomb(path: Path, marker: Path, torch_format: bool = False) -> Path:
    """A pickle (``torch.save`` format with ``torch_format``) that would create ``marker`` if loaded."""
    payload = {"state": {0: {"exp_avg": _Bomb(marker)}}, "param_groups": []}
    if torch_format:
        import torch

        torch.save(payload, path)
    else:
        path.write_bytes(pickle.dumps(payload))
    return path


def config_damage(size_change: Callable[[dict], None], required: str) -> dict[str, Callable[[dict], object]]:
    """Broken config.json contents from a good one: (name -> new content)."""
    def sizes(c):
        c = json.loads(json.dumps(c))
        size_change(c)
        return c

    def string_number(c):
        c = json.loads(json.dumps(c))
        size_change(c, as_string=True)
        return c

    return {
        "a_list": lambda c: [c],
        f"missing_{required}": lambda c: {k: v for k, v in c.items() if k != required},
        "string_for_number": string_number,
        "unknown_key": lambda c: {**c, "surprise": 1},
        "sizes_not_the_weights": sizes,
    }


@dataclass
class SavedModel:
    """A saved folder of one kind, its loader, and the config change that resizes its model."""

    folder: Path
    weights: str  # the weights file in the folder
    load: Callable[[Path], object]
    resize: Callable  # (config, as_string=False) -> None, in place
    required: str  # a config key it cannot do without


def _set(path: tuple, value_of: Callable):
    def resize(c, as_string=False):
        d = c
        for key in path[:-1]:
            d = d[key]
        d[path[-1]] = str(d[path[-1]]) if as_string else value_of(d[path[-1]])
    return resize


def saved_models(root: Path) -> dict[str, SavedModel]:
    """One tiny saved folder of each kind under ``root`` (made once per root)."""
    from zsrm.vlm import create_scene_vlm, load_vlm
    from zsrm.vlm.compat import import_sentence_transformers

    import_sentence_transformers()  # first, outside any model's attribute lookup (a failed import there reads oddly)
    root.mkdir(parents=True, exist_ok=True)
    scene = root / "scene"
    if not scene.exists():
        create_scene_vlm("tiny", seed=0, image_size=32).save(scene)
    out = {"scene": SavedModel(scene, "model.safetensors", load_vlm, _set(("config", "embed_dim"), lambda v: 2 * v),
                               "config")}
    out.update(_fullmodels(root, scene))
    out["open_clip"] = _open_clip_model(root)
    out["policy"] = _policy(root)
    return {k: SavedModel(v.folder, v.weights, (lambda f, load=v.load: load(str(f))), v.resize, v.required)
            for k, v in out.items()}


def _fullmodels(root: Path, scene: Path) -> dict[str, SavedModel]:
    import torch

    from zsrm.fullmodel import load_reward_backbone
    from zsrm.fullmodel.adapted import AdaptedVLM
    from zsrm.fullmodel.student import StudentConfig, StudentRewardNet
    from zsrm.vlm import load_vlm

    student, adapted = root / "student", root / "adapted"
    if not student.exists():
        torch.manual_seed(0)
        StudentRewardNet(StudentConfig(image_size=32, widths=(8, 8, 8, 8), embed_dim=8, text_hidden=16),
                         load_vlm(str(scene)), str(scene)).save(student)
    if not adapted.exists():
        AdaptedVLM(load_vlm(str(scene)), grid=2, text_hidden=0).save(adapted)
    return {"student": SavedModel(student, "model.safetensors", load_reward_backbone,
                                  _set(("config", "embed_dim"), lambda v: 2 * v), "text_vlm"),
            "adapted": SavedModel(adapted, "adapters.safetensors", load_reward_backbone,
                                  _set(("grid",), lambda v: v + 1), "grid")}


TINY_OPEN_CLIP = {"embed_dim": 16, "vision_cfg": {"image_size": 32, "layers": [1, 1, 1, 1], "width": 8},
                  "text_cfg": {"context_length": 77, "vocab_size": 49408, "width": 16, "heads": 2, "layers": 1}}


def _open_clip_model(root: Path) -> SavedModel:
    from zsrm.vlm import create_open_clip_vlm, load_vlm
    from zsrm.vlm.compat import import_open_clip

    configs = root / "open_clip_configs"
    configs.mkdir(exist_ok=True)
    for name, width in (("zsrm-hostile-rn", 8), ("zsrm-hostile-rn-wide", 16)):
        cfg = {**TINY_OPEN_CLIP, "vision_cfg": {**TINY_OPEN_CLIP["vision_cfg"], "width": width}}
        (configs / f"{name}.json").write_text(json.dumps(cfg))
    import_open_clip().add_model_config(configs)
    folder = root / "open_clip"
    if not folder.exists():
        create_open_clip_vlm("zsrm-hostile-rn", pretrained="none").save(folder)

    def resize(c, as_string=False):  # another architecture's name; a string where an object belongs
        if as_string:
            c["quick_gelu"] = "no"
        else:
            c["model_name"] = "zsrm-hostile-rn-wide"
            c.pop("model_cfg", None)
    return SavedModel(folder, "model.safetensors", load_vlm, resize, "model_name")


def _policy(root: Path) -> SavedModel:
    import gymnasium as gym
    import numpy as np
    from stable_baselines3.common.policies import MultiInputActorCriticPolicy

    from zsrm.rl.config import TrainConfig
    from zsrm.rl.features import FEATURES_KEY, IMAGE_KEY
    from zsrm.rl.policy import PolicyBundle, policy_kwargs

    folder = root / "policy"
    if not folder.exists():
        cfg = TrainConfig(keypoints=4)
        obs = gym.spaces.Dict({FEATURES_KEY: gym.spaces.Box(0.0, np.inf, (8, 4, 4), np.float32),
                               IMAGE_KEY: gym.spaces.Box(0, 255, (3, 32, 32), np.uint8)})
        policy = MultiInputActorCriticPolicy(obs, gym.spaces.Box(-1.0, 1.0, (3,), np.float32), lambda _: 3e-4,
                                             **policy_kwargs(cfg))
        PolicyBundle(policy, cfg).save(folder)
    return SavedModel(folder, "model.safetensors", lambda f: PolicyBundle.load(f),
                      _set(("action_dim",), lambda v: v + 1), "config")


def broken_copy(model: SavedModel, name: str) -> Path:
    """A fresh copy of ``model``'s folder named ``name`` beside it (so relative specs still resolve)."""
    target = model.folder.parent / name
    shutil.rmtree(target, ignore_errors=True)
    shutil.copytree(model.folder, target)
    return target


@contextmanager
def full_disk(after: int = 0):
    """Atomic writes (:mod:`zsrm.common.files`) fail with ENOSPC from the ``after``-th on, as on a
    full disk: the temporary file is written, its rename never happens."""
    from zsrm.common import files

    real, count = files._replace, [0]

    def replace(src, dst):
        count[0] += 1
        if count[0] > after:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(dst))
        real(src, dst)

    files._replace = replace
    try:
        yield count
    finally:
        files._replace = real

"""Reading a collected (and labelled) exploration dataset.

>>> data = ExplorationData("data/explore")                     # doctest: +SKIP
>>> images = data.load(["images_front"])["images_front"]      # doctest: +SKIP
>>> captions = data.captions()  # Grad-CAM captions, for training  # doctest: +SKIP
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from zsrm.common.files import ZsrmFileError, read_json
from zsrm.data.shards import MANIFEST, load_npz, read_manifest
from zsrm.tasks.lexicon import BOX

LABELS = "labels"  # the default labels folder inside a dataset folder
ORACLE = "oracle"  # inside the labels folder: true-coordinate captions, for evaluation only


def with_box(objects: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Per-object arrays (N, 4, ...) of the colours with the box's (N, ...) as one more object
    after them: (N, 5, ...). The box is stored apart so that the colour arrays of every dataset
    keep their shape; the labeler and evaluation relate the five together.

    >>> with_box(np.zeros((2, 4, 3)), np.ones((2, 3))).shape
    (2, 5, 3)
    """
    return np.concatenate([objects, np.asarray(box, objects.dtype)[:, None]], axis=1)


class ExplorationData:
    """A folder written by ``zsrm collect`` (shards of images, true positions, object lists)."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self.manifest = read_manifest(self.folder)
        if self.manifest.get("kind") != "exploration":
            raise ValueError(f"{self.folder} holds a {self.manifest.get('kind')} folder, not collected data")
        self.config = self.manifest["config"]
        try:
            self.colours: tuple[str, ...] = tuple(self.manifest["colours"])
            self.scenes: tuple[str, ...] = tuple(self.config["scenes"])
            self.cameras: tuple[str, ...] = tuple(self.config["cameras"])
            self.block_width_px: dict[str, dict[str, float]] = dict(self.manifest["block_width_px"])
        except (KeyError, TypeError, ValueError) as err:
            raise ZsrmFileError(f"{self.folder / MANIFEST} is damaged: {type(err).__name__} {err}; "
                                "not a folder written by zsrm collect") from None
        # scene -> camera -> pixel-to-table map of the tilted camera (absent in older folders)
        self.table_homography: dict[str, dict[str, list]] = self.manifest.get("table_homography", {})
        # scene -> camera -> pixel rays (zsrm.envs.cameras.pixel_rays; own scenes collected from 2026-12-07)
        self.pixel_rays: dict[str, dict[str, dict]] = self.manifest.get("pixel_rays", {})

    @property
    def scene_adapter(self) -> str | None:
        """The adapter (``module:Class``) of data collected from a user's own scene (``zsrm collect
        --scene``); None for data of zsrm's scenes."""
        info = self.manifest.get("scene_adapter")
        return info.get("name") if isinstance(info, dict) else None

    @property
    def has_box(self) -> bool:
        """Collected with ``p_box``: some tabletop scenes hold the box, whose arrays are
        ``box_present`` (N,), ``box_position`` (N, 3), ``box_pixels_<camera>`` (N, 2)."""
        return bool(self.config.get("p_box"))

    @property
    def objects(self) -> tuple[str, ...]:
        """What the labeler relates: the colours, then the box where the data can hold it."""
        return self.colours + ((BOX,) if self.has_box else ())

    @property
    def box_keys(self) -> list[str]:
        """The keys of the box's arrays (none where the data cannot hold the box)."""
        return ["box_present", "box_position"] + [f"box_pixels_{c}" for c in self.cameras] if self.has_box else []

    def object_arrays(self, arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``present``, ``positions`` and ``pixels_<camera>`` of loaded ``arrays`` over
        :attr:`objects`: with the box as a fifth object where the data has it, as they are
        otherwise (load :attr:`box_keys` with them). Keys that ``arrays`` lacks are left out."""
        box_keys = {"present": "box_present", "positions": "box_position",
                    **{f"pixels_{c}": f"box_pixels_{c}" for c in self.cameras}}
        return {key: with_box(arrays[key], arrays[box]) if self.has_box else arrays[key]
                for key, box in box_keys.items() if key in arrays}

    @property
    def shards(self) -> list[str]:
        """Names of the finished shards, in order."""
        return sorted(self.manifest["shards"])

    @property
    def complete(self) -> bool:
        return bool(self.manifest["complete"])

    def __len__(self) -> int:
        return sum(info["images"] for info in self.manifest["shards"].values())

    def shard(self, name: str, keys=None) -> dict[str, np.ndarray]:
        arrays = load_npz(self.folder / f"{name}.npz")
        return arrays if keys is None else {k: arrays[k] for k in keys}

    def load(self, keys=None) -> dict[str, np.ndarray]:
        """The finished shards' arrays, concatenated. Keys: ``images_<camera>`` (N, H, W, 3)
        uint8; evaluation only: ``positions`` (N, 4, 3) world xyz and ``pixels_<camera>``
        (N, 4, 2) true pixel (x, row), NaN for absent colours; ``present`` (N, 4) over
        :attr:`colours`; ``scene`` (N,) index into :attr:`scenes`; ``episode``, ``step``; where
        :attr:`has_box`, the box's arrays apart (see :meth:`object_arrays`)."""
        parts = [self.shard(name, keys) for name in self.shards]
        if not parts:
            raise ValueError(f"{self.folder} holds no finished shard yet")
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    def labels_folder(self, labels: str | Path = LABELS) -> Path:
        """A labels folder: a name inside the dataset folder, or an absolute path."""
        path = Path(labels)
        return path if path.is_absolute() else self.folder / path

    def captions(self, labels: str | Path = LABELS, oracle: str | None = None) -> list[list[str]]:
        """Captions of every image of the finished shards: Grad-CAM captions (for training), or
        with ``oracle="pixel"``/``"world"`` the true-coordinate captions (evaluation only)."""
        folder = self.labels_folder(labels)
        manifest = read_manifest(folder)
        out: list[list[str]] = []
        for name in self.shards:
            if name not in manifest["shards"]:
                raise ValueError(f"{folder} has not labelled {name} yet: run zsrm label")
            path = folder / f"{name}.json" if oracle is None else folder / ORACLE / f"{name}.json"
            captions = read_json(path, "a labels shard").get(oracle or "captions")
            if not isinstance(captions, list):
                raise ZsrmFileError(f"{path} is damaged: no {oracle or 'captions'!r} list in it")
            out += captions
        return out

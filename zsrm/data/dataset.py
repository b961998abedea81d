"""Reading a collected (and labelled) exploration dataset.

>>> data = ExplorationData("data/explore")                     # doctest: +SKIP
>>> images = data.load(["images_front"])["images_front"]      # doctest: +SKIP
>>> captions = data.captions()  # Grad-CAM captions, for training  # doctest: +SKIP
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from zsrm.data.shards import MANIFEST, load_npz, read_manifest
from zsrm.vlm.files import ZsrmFileError, read_json

LABELS = "labels"  # the default labels folder inside a dataset folder
ORACLE = "oracle"  # inside the labels folder: true-coordinate captions, for evaluation only


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
        :attr:`colours`; ``scene`` (N,) index into :attr:`scenes`; ``episode``, ``step``."""
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

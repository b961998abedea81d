"""Datasets on disk as numbered shards plus a ``manifest.json`` that lists the finished ones.

A shard's files are written to temporary names and renamed into place, and the manifest
names a shard only once all its files are there; so a stage killed at any moment resumes
by redoing the shards the manifest does not list. Each shard's content depends only on the
stage's options and the shard's index (its seed), so a resumed run writes the same data as
an uninterrupted one.

>>> import tempfile
>>> folder = tempfile.mkdtemp()
>>> shards = ShardFolder(folder, kind="example", config={"n": 2}, n_shards=2)
>>> shards.pending()
[0, 1]
>>> save_npz(shards.path(0, ".npz"), x=np.arange(3)); shards.finish(0, {"n": 3})
>>> ShardFolder(folder, kind="example", config={"n": 2}, n_shards=2).pending()
[1]
"""
from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from zsrm.common.files import ZsrmFileError, atomic_path, check_writable, json_type, read_json, write_json

FORMAT = "zsrm-shards-1"
MANIFEST = "manifest.json"


def save_npz(path: str | Path, **arrays) -> None:
    """np.savez_compressed, atomically (a kill or a full disk leaves the old file or none, never half)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)


def save_json(path: str | Path, obj: Any) -> None:
    """JSON, atomically."""
    write_json(path, obj, indent=1)


def load_npz(path: str | Path) -> dict[str, np.ndarray]:
    """The arrays of a shard (never unpickled); a damaged shard is one ZsrmFileError naming it."""
    try:
        with np.load(path, allow_pickle=False) as f:
            return {k: f[k] for k in f.files}
    except FileNotFoundError:
        raise
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as err:
        raise ZsrmFileError(f"{path} is not a readable shard ({str(err).splitlines()[0][:200] if str(err) else err}); "
                            "delete it and its folder's manifest entry, then rerun the stage that wrote it") from None


MANIFEST_FIELDS = {"kind": str, "config": dict, "n_shards": int, "complete": bool, "shards": dict}


def read_manifest(folder: str | Path) -> dict:
    path = Path(folder) / MANIFEST
    if not path.exists():
        raise FileNotFoundError(f"no {MANIFEST} in {folder}: not a zsrm dataset folder")
    manifest = read_json(path, "a zsrm shard manifest")
    if manifest.get("format") != FORMAT:
        raise ZsrmFileError(f"{path} is not a zsrm shard manifest (format {manifest.get('format')!r})")
    for key, kind in MANIFEST_FIELDS.items():
        if not isinstance(manifest.get(key), kind) or (kind is int and isinstance(manifest[key], bool)):
            raise ZsrmFileError(f"{path} is damaged: {key!r} must be a JSON {json_type(kind())}, "
                                f"got {manifest.get(key)!r}"[:300])
    return manifest


def shard_name(index: int) -> str:
    return f"shard_{index:05d}"


class ShardFolder:
    """The manifest of one stage's output folder: its options, and which shards are done.

    Opening a folder that holds a manifest written with other options raises ValueError:
    resuming must not mix data made two ways.
    """

    def __init__(self, folder: str | Path, kind: str, config: dict, n_shards: int, extra: dict | None = None):
        self.folder = check_writable(folder, folder=True)
        config = json.loads(json.dumps(config))  # tuples -> lists, as they read back
        if (self.folder / MANIFEST).exists():
            manifest = read_manifest(self.folder)
            if manifest.get("kind") != kind:
                raise ValueError(f"{self.folder} holds a {manifest.get('kind')} folder, not a {kind} one")
            if manifest["config"] != config:
                diff = sorted(k for k in set(config) | set(manifest["config"])
                              if config.get(k) != manifest["config"].get(k))
                raise ValueError(
                    f"{self.folder} was made with other options ({', '.join(diff)} differ); "
                    "rerun with the same options to resume, or write to another folder")
            self.manifest = manifest
            missing = {k: v for k, v in (extra or {}).items() if k not in manifest}
            if missing:  # folders from before a field existed (e.g. camera calibration) gain it
                manifest.update(missing)
                save_json(self.folder / MANIFEST, manifest)
        else:
            self.manifest = {"format": FORMAT, "kind": kind, "config": config, "n_shards": n_shards,
                             "complete": False, "shards": {}, **(extra or {})}
            save_json(self.folder / MANIFEST, self.manifest)

    def path(self, index: int, suffix: str, sub: str | None = None) -> Path:
        folder = self.folder / sub if sub else self.folder
        folder.mkdir(parents=True, exist_ok=True)
        return folder / f"{shard_name(index)}{suffix}"

    def done(self, index: int) -> bool:
        return shard_name(index) in self.manifest["shards"]

    def pending(self) -> list[int]:
        return [i for i in range(self.manifest["n_shards"]) if not self.done(i)]

    def finish(self, index: int, info: dict) -> None:
        """Record a shard whose files are all written."""
        self.manifest["shards"][shard_name(index)] = info
        self.manifest["complete"] = not self.pending()
        save_json(self.folder / MANIFEST, self.manifest)

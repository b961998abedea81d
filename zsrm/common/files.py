"""Files in and out, the same way everywhere: one clear line for a bad file or path, atomic writes.

* :class:`ZsrmFileError` (a ValueError, so the CLI prints it as one line with exit status 2):
  a file zsrm was handed is unusable, or a path it must write cannot be written. The message
  names the file and what is wrong with it.
* :func:`read_json`: a JSON file whose top level must be an object, or that error.
* :func:`check_writable`: called by every command that writes, before its work starts.
* :func:`atomic_path` (and :func:`write_text`, :func:`write_json` on top of it): a file is
  written under a temporary name beside its place and renamed into place only when complete,
  so a kill or a full disk leaves the previous file (or none), never half of one; a full disk
  or a refused write becomes a :class:`ZsrmFileError`.

>>> import tempfile
>>> path = Path(tempfile.mkdtemp()) / "out" / "a.json"
>>> _ = write_json(path, {"a": 1})
>>> read_json(path)
{'a': 1}
>>> read_json(write_text(path, "[1, 2]"))  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
zsrm.common.files.ZsrmFileError: ... holds a JSON list, not an object; expected a JSON object
"""
from __future__ import annotations

import errno
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

FULL_DISK = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


class ZsrmFileError(ValueError):
    """A file or folder zsrm reads or writes is unusable: one line naming it and what is wrong."""


def json_type(value) -> str:
    """How JSON calls the type of ``value`` (for messages)."""
    for kind, name in ((bool, "boolean"), ((int, float), "number"), (str, "string"), (dict, "object"),
                       ((list, tuple), "list"), (type(None), "null")):
        if isinstance(value, kind):
            return name
    return type(value).__name__


def read_json(path: str | Path, what: str = "a JSON object") -> dict:
    """The JSON object in ``path``; a ZsrmFileError naming the file if it is unreadable, not
    JSON, or not an object."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise
    except (OSError, UnicodeDecodeError) as err:
        raise ZsrmFileError(f"cannot read {path}: {getattr(err, 'strerror', None) or err}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as err:
        raise ZsrmFileError(f"{path} is not valid JSON ({err}); expected {what}") from None
    if not isinstance(data, dict):
        raise ZsrmFileError(f"{path} holds a JSON {json_type(data)}, not an object; expected {what}")
    return data


def output_error(path: str | Path, err: OSError) -> ZsrmFileError:
    """The one line for a write to ``path`` that failed with ``err``."""
    if err.errno in FULL_DISK:
        return ZsrmFileError(f"no space left on the device to write {path}; files finished before it are intact: "
                             "free some space and rerun to resume")
    return ZsrmFileError(f"cannot write {path}: {err.strerror or err}")


def _replace(src: Path, dst: Path) -> None:
    os.replace(src, dst)  # one place, so tests can make the disk full


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` (same suffix, so writers that go by it still work) to
    write to; renamed onto ``path`` when the block ends, removed if it fails. Parent folders
    are made. A failed write (full disk, read-only place) raises :class:`ZsrmFileError`."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        yield tmp
        _replace(tmp, path)
    except OSError as err:
        _discard(tmp)
        raise output_error(path, err) from None
    except BaseException:
        _discard(tmp)
        raise


def _discard(tmp: Path) -> None:
    try:
        tmp.unlink(missing_ok=True)
    except OSError:
        pass


def write_text(path: str | Path, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)


def write_json(path: str | Path, obj, **dump) -> Path:
    """``obj`` as JSON (``indent=2`` unless ``dump`` says otherwise), atomically."""
    return write_text(path, json.dumps(obj, **{"indent": 2, **dump}) + "\n")


def check_writable(path: str | Path, folder: bool = False) -> Path:
    """Fail now, with one line, when ``path`` (a file, or with ``folder`` a folder) cannot be
    created and written: called by each command before its work starts. Makes the folder."""
    path = Path(path)
    where = path if folder else path.parent
    if path.is_dir() and not folder:
        raise ZsrmFileError(f"cannot write {path}: it is a folder, not a file")
    try:
        where.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=where, prefix=".zsrm-write-check-"):
            pass
    except FileExistsError:
        raise ZsrmFileError(f"cannot write {path}: {where} exists and is not a folder") from None
    except OSError as err:
        raise ZsrmFileError(f"cannot write {path}: {err.strerror or err}"
                            + (f" ({err.filename})" if err.filename else "")) from None
    return path

"""Saved models: one folder format, one registry of model kinds, one way to read and write them.

A saved model is a folder holding ``config.json``, whose ``"backend"`` field (or ``"kind"``)
names the model's *kind*, and its weights as safetensors (never pickle, so loading runs no code from a file).
Each kind registers the function that loads it (:func:`register_kind`); :func:`load_folder`
reads the kind and calls it. Models that ship with zsrm are registered by name
(:func:`register_shipped`: ``"scene"``, and ``"student"`` once :mod:`zsrm.fullmodel` is
imported), so a spec string can name them.

Every loader reads its folder through :func:`read_config` and :func:`load_weights`, and every
``save`` writes through :func:`save_folder`. Both validate before anything is built or loaded:
:func:`read_config` with ``schema`` checks the config's shape, keys and types against the
kind's config dataclass (:func:`parse_fields`); :func:`load_weights` reads the safetensors
header itself (:func:`read_header`: readable, not truncated) and checks its tensor names,
shapes and dtypes against the module the config describes. Every failure is one
:class:`~zsrm.common.files.ZsrmFileError` naming the file and what is wrong.

>>> import tempfile, torch
>>> folder = tempfile.mkdtemp()
>>> save_folder(folder, {"backend": "example", "width": 2}, {WEIGHTS_FILE: torch.nn.Linear(2, 1)})
>>> read_config(folder, kind="example")["width"]
2
"""
from __future__ import annotations

import dataclasses
import json
import math
import types
import typing
from pathlib import Path
from typing import Any, Callable

from zsrm.common.files import ZsrmFileError, atomic_path, json_type, read_json, write_json

CONFIG_FILE = "config.json"
WEIGHTS_FILE = "model.safetensors"

# kind -> loader(folder, device) -> VisionLanguageModel
KINDS: dict[str, Callable] = {}
# name -> folder of a model shipped with zsrm
SHIPPED: dict[str, Path] = {}


def register_kind(kind: str, loader: Callable) -> None:
    """Let :func:`load_folder` load folders whose config names ``kind`` with ``loader(folder, device)``."""
    KINDS[kind] = loader


def register_shipped(name: str, folder: Path) -> None:
    """A model shipped with zsrm, loadable by ``name`` (see :func:`zsrm.vlm.load_vlm`)."""
    SHIPPED[name] = Path(folder)


def read_config(folder: str | Path, kind: str | None = None, schema: type | dict | None = None):
    """A saved model folder's config.json; with ``kind``, checks the folder holds that kind; with
    ``schema`` (the kind's folder-config dataclass, or a ``key -> type`` dict of one), returns
    it parsed by :func:`parse_fields`."""
    path = Path(folder) / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"no {CONFIG_FILE} in {folder}: not a saved zsrm model folder")
    config = read_json(path, f"the config of a saved {kind!r} model" if kind else
                       "a saved zsrm model's config (an object naming its kind)")
    if kind is not None and kind_of(config) != kind:
        raise ZsrmFileError(f"{path}: the folder holds a {kind_of(config)!r} model, not a {kind!r} model")
    return config if schema is None else parse_fields(schema, config, str(path))


def kind_of(config: dict) -> str | None:
    """The kind a saved model's config names."""
    return config.get("kind", config.get("backend")) if isinstance(config, dict) else None


def folder_kind(spec) -> str | None:
    """The kind a saved model folder names, or None if ``spec`` is not such a folder."""
    try:
        return kind_of(read_config(Path(str(spec)).expanduser()))
    except (FileNotFoundError, ValueError, OSError):
        return None


# --- configs: JSON checked against a dataclass ---------------------------------------------------
def parse_fields(cls: type | dict, data: Any, where: str):
    """The dataclass ``cls`` from JSON ``data``: an object with only ``cls``'s fields, every
    required one present, each value of its field's type (nested dataclasses, ``int``,
    ``float``, ``str``, ``bool``, ``dict``, ``tuple``/``list``, ``Literal``, ``X | None``), then
    ``cls``'s own checks. Anything else: a ZsrmFileError naming ``where`` and the key. ``cls``
    may be a ``key -> type`` dict, for a dataclass of those (required) fields.

    >>> @dataclasses.dataclass
    ... class Size:
    ...     width: int = 2
    ...     scale: tuple[float, float] = (1.0, 1.0)
    >>> parse_fields(Size, {"width": 3, "scale": [1, 2]}, "config.json")
    Size(width=3, scale=(1.0, 2.0))
    >>> parse_fields(Size, {"width": "3"}, "config.json")
    Traceback (most recent call last):
    ...
    zsrm.common.files.ZsrmFileError: config.json: width must be an integer, got the string '3'
    """
    if isinstance(cls, dict):
        cls = dataclasses.make_dataclass("Fields", list(cls.items()))
    if not isinstance(data, dict):
        raise ZsrmFileError(f"{where} must be an object, got a {json_type(data)}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ZsrmFileError(f"{where}: unknown key{'s' * (len(unknown) > 1)} {', '.join(map(repr, unknown))} "
                            f"(known: {', '.join(fields)})")
    missing = [n for n, f in fields.items() if n not in data
               and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]
    if missing:
        raise ZsrmFileError(f"{where}: missing key{'s' * (len(missing) > 1)} {', '.join(map(repr, missing))}")
    hints = typing.get_type_hints(cls)
    values = {k: _check_value(hints[k], v, where, k) for k, v in data.items()}
    # a file written before a field existed means the value the class names for it, if any
    values = {**getattr(cls, "LEGACY_DEFAULTS", {}), **values}
    try:
        return cls(**values)
    except (ValueError, TypeError) as err:
        raise ZsrmFileError(f"{where}: {str(err).splitlines()[0] if str(err) else type(err).__name__}") from None


def _check_value(kind, value, where: str, key: str):
    """``value`` checked against the annotation ``kind`` (lists become tuples where it says so)."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if kind is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        options = [a for a in args if a is not type(None)]
        if len(options) == 1:
            return _check_value(options[0], value, where, key)
        if any(_fits(a, value) for a in options):
            return value
        raise _wrong(where, key, " or ".join(map(_describe, options)), value)
    if origin is typing.Literal:
        if value not in args:
            raise ZsrmFileError(f"{where}: {key} must be one of {', '.join(map(repr, args))}, got {value!r}")
        return value
    if dataclasses.is_dataclass(kind):
        return parse_fields(kind, value, f"{where}: {key}")
    if origin in (tuple, list) or kind in (tuple, list):
        return _check_sequence(kind, value, where, key)
    if not _fits(kind, value):
        raise _wrong(where, key, _describe(kind), value)
    return float(value) if kind is float else value


def _check_sequence(kind, value, where: str, key: str):
    origin, args = typing.get_origin(kind) or kind, typing.get_args(kind)
    if not isinstance(value, list):
        raise _wrong(where, key, "a list", value)
    if origin is tuple and args and args[-1] is not Ellipsis:
        if len(value) != len(args):
            raise ZsrmFileError(f"{where}: {key} must be a list of {len(args)} values, got {len(value)}")
        kinds = args
    else:
        kinds = [args[0] if args else Any] * len(value)
    items = [_check_value(k, v, where, f"{key}[{i}]") for i, (k, v) in enumerate(zip(kinds, value))]
    return tuple(items) if origin is tuple else items


def _fits(kind, value) -> bool:
    if kind is bool:
        return isinstance(value, bool)
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if kind is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    return isinstance(value, typing.get_origin(kind) or kind)


def _describe(kind) -> str:
    names = {bool: "true or false", int: "an integer", float: "a finite number", str: "a string", dict: "an object"}
    return names.get(typing.get_origin(kind) or kind, getattr(kind, "__name__", str(kind)))


def _wrong(where: str, key: str, expected: str, value) -> ZsrmFileError:
    return ZsrmFileError(f"{where}: {key} must be {expected}, got the {json_type(value)} {value!r}"[:400])


def build_model(folder: str | Path, make: Callable):
    """``make()``: the model a checked config describes; a config whose values cannot build one
    (e.g. GroupNorm groups that do not divide a width) is a ZsrmFileError naming it."""
    try:
        return make()
    except (ValueError, TypeError, RuntimeError) as err:
        if isinstance(err, ZsrmFileError):
            raise
        raise ZsrmFileError(f"{Path(folder) / CONFIG_FILE} describes a model that cannot be built: "
                            f"{str(err).splitlines()[0][:300] if str(err) else type(err).__name__}") from None


# --- weights: the safetensors header checked against the module -----------------------------------
DTYPES = {"F64": 8, "F32": 4, "F16": 2, "BF16": 2, "I64": 8, "I32": 4, "I16": 2, "I8": 1, "U8": 1, "BOOL": 1,
          "U16": 2, "U32": 4, "U64": 8, "F8_E4M3": 1, "F8_E5M2": 1}
MAX_HEADER = 100_000_000  # bytes; safetensors' own limit


def read_header(path: str | Path) -> dict[str, dict]:
    """``name -> {"dtype", "shape"}`` of a safetensors file, read and checked without loading a
    tensor: the file must be complete (every tensor's bytes inside it, nothing cut off)."""
    path = Path(path)
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            n = int.from_bytes(f.read(8), "little")
            raw = f.read(n) if 8 <= size and n <= min(size - 8, MAX_HEADER) else b""
    except OSError as err:
        raise ZsrmFileError(f"cannot read {path}: {err.strerror or err}") from None
    if size == 0:
        raise ZsrmFileError(f"{path} is empty: not a safetensors file (written by a run that was cut short?)")
    if size < 8 or n > min(size - 8, MAX_HEADER):
        raise ZsrmFileError(f"{path} is not a safetensors file, or is cut inside its header "
                            f"({size} bytes; the first 8 announce a {n}-byte header)")
    try:
        header = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise ZsrmFileError(f"{path} is not a safetensors file: its header is not JSON") from None
    if not isinstance(header, dict):
        raise ZsrmFileError(f"{path} is not a safetensors file: its header is a {json_type(header)}")
    header.pop("__metadata__", None)
    return _check_entries(path, header, size - 8 - n)


def _check_entries(path: Path, header: dict, data_bytes: int) -> dict[str, dict]:
    out, end = {}, 0
    for name, entry in header.items():
        ok = (isinstance(entry, dict) and entry.get("dtype") in DTYPES and isinstance(entry.get("shape"), list)
              and all(isinstance(d, int) and d >= 0 for d in entry["shape"])
              and isinstance(entry.get("data_offsets"), list) and len(entry["data_offsets"]) == 2
              and all(isinstance(o, int) for o in entry["data_offsets"]))
        if not ok:
            raise ZsrmFileError(f"{path} is not a safetensors file: the header entry of {name!r} is malformed")
        start, stop = entry["data_offsets"]
        if not 0 <= start <= stop or stop - start != math.prod(entry["shape"]) * DTYPES[entry["dtype"]]:
            raise ZsrmFileError(f"{path} is damaged: tensor {name!r} has the wrong number of bytes")
        out[name], end = {"dtype": entry["dtype"], "shape": entry["shape"]}, max(end, stop)
    if end > data_bytes:
        raise ZsrmFileError(f"{path} is truncated: its header describes {end} bytes of tensors, "
                            f"the file holds {data_bytes}")
    return out


def check_weights(module, path: str | Path) -> None:
    """The weights file's tensors are exactly ``module``'s (tied tensors may be stored once),
    with the same shapes and dtypes; else a ZsrmFileError naming the file and the difference."""
    import torch

    header, state = read_header(path), module.state_dict()
    storage = {k: (v.untyped_storage().data_ptr(), v.storage_offset(), tuple(v.shape)) for k, v in state.items()}
    stored = {storage[k] for k in state if k in header}
    missing = [k for k in state if k not in header and storage[k] not in stored]
    unexpected = [k for k in header if k not in state]
    if missing or unexpected:
        parts = ([f"lacks {len(missing)} tensor(s) the model has (e.g. {', '.join(missing[:3])})"] if missing else []) \
            + ([f"holds {len(unexpected)} the model has not (e.g. {', '.join(unexpected[:3])})"] if unexpected else [])
        raise ZsrmFileError(f"{path} does not hold the model its config describes: {'; '.join(parts)}")
    for k, entry in header.items():
        want, dtype = list(state[k].shape), _dtype_name(state[k].dtype, torch)
        if entry["shape"] != want:
            raise ZsrmFileError(f"{path} does not match its config: {k} is {entry['shape']} in the file, "
                                f"{want} in the model the config describes")
        if entry["dtype"] != dtype:
            raise ZsrmFileError(f"{path}: {k} is stored as {entry['dtype']}, the model needs {dtype}")


def _dtype_name(dtype, torch) -> str:
    names = {torch.float64: "F64", torch.float32: "F32", torch.float16: "F16", torch.bfloat16: "BF16",
             torch.int64: "I64", torch.int32: "I32", torch.int16: "I16", torch.int8: "I8", torch.uint8: "U8",
             torch.bool: "BOOL"}
    return names.get(dtype, str(dtype))


def load_weights(module, folder: str | Path, file: str = WEIGHTS_FILE, device="cpu") -> None:
    """Load ``folder/file`` (safetensors) into ``module``, once :func:`check_weights` passed."""
    from safetensors.torch import load_model

    path = Path(folder) / file
    if not path.is_file():
        raise FileNotFoundError(f"no {file} in {folder}")
    check_weights(module, path)
    try:
        load_model(module, str(path), strict=True, device=str(device))
    except Exception as err:  # safetensors' own error types: a damaged file the header check missed
        raise ZsrmFileError(f"{path} cannot be loaded: {str(err).splitlines()[0][:300] if str(err) else err}") from None


def save_weights(module, folder: str | Path, file: str = WEIGHTS_FILE) -> None:
    """Write ``module``'s weights to ``folder/file`` as safetensors, atomically."""
    from safetensors.torch import save_model

    with atomic_path(Path(folder) / file) as tmp:
        save_model(module, str(tmp))


def save_tensors(tensors: dict, path: str | Path) -> None:
    """A flat ``name -> tensor`` dict as a safetensors file (e.g. an optimiser's state), atomically."""
    from safetensors.torch import save_file

    with atomic_path(path) as tmp:
        save_file({k: v.detach().contiguous() for k, v in tensors.items()}, str(tmp))


def load_tensors(path: str | Path) -> dict:
    """The tensors of a safetensors file, its header checked first (:func:`read_header`)."""
    from safetensors.torch import load_file

    if not Path(path).is_file():
        raise FileNotFoundError(f"no {Path(path).name} in {Path(path).parent}")
    read_header(path)
    try:
        return load_file(str(path))
    except Exception as err:
        raise ZsrmFileError(f"{path} cannot be loaded: {str(err).splitlines()[0][:300] if str(err) else err}") from None


def save_folder(folder: str | Path, config: dict, weights: dict) -> None:
    """Write each ``file -> module`` of ``weights`` as safetensors and ``config`` as config.json
    (last, so a folder with a config has its weights), each file atomically."""
    for file, module in weights.items():
        save_weights(module, folder, file)
    write_json(Path(folder) / CONFIG_FILE, config)


def load_folder(folder: str | Path, device="cpu"):
    """The model saved in ``folder``, by the loader its kind registered."""
    kind = kind_of(read_config(folder))
    if kind not in KINDS:
        raise ZsrmFileError(f"{Path(folder) / CONFIG_FILE} names an unknown model kind {kind!r}; known: "
                         f"{', '.join(KINDS)} (zsrm.fullmodel registers its kinds when imported)")
    return KINDS[kind](Path(folder), device)

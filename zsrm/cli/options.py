"""Command-line options from a dataclass: one field, one option, its default written once.

A field ``shard_size: int = 250  # scenes per shard`` becomes ``--shard-size SHARD_SIZE`` with
that default and the comment as its help (a string right below the field works too, as an
attribute docstring). Types: ``str``, ``int``, ``float``, ``bool`` (a flag), ``Literal[...]``
(choices), ``X | None`` and ``tuple[X, ...]`` (one or more values, each also split at commas,
unless the field's metadata says ``{"split": False}``). Field metadata ``{"positional": True}``
makes a positional argument; ``{"cli": False}`` leaves a field out. The class docstring's
first line is the command's help, the whole docstring its description.

>>> from dataclasses import dataclass
>>> @dataclass
... class Example:
...     '''Say hello.'''
...     name: str = "world"  # whom to greet
...     times: int = 1
>>> parser = argparse.ArgumentParser()
>>> add_options(parser, Example)
>>> from_namespace(Example, parser.parse_args(["--name", "you", "--times", "2"]))
Example(name='you', times=2)
"""
from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import io
import textwrap
import tokenize
import types
import typing


def field_docs(cls) -> dict[str, str]:
    """Each field's help: the comment on its line, or the string just below it (through the MRO)."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        try:
            source = textwrap.dedent(inspect.getsource(klass))
        except (OSError, TypeError):
            continue
        comments = {tok.start[0]: tok.string.lstrip("#").strip()
                    for tok in tokenize.generate_tokens(io.StringIO(source).readline) if tok.type == tokenize.COMMENT}
        node = ast.parse(source).body[0]
        body = getattr(node, "body", [])
        for i, stmt in enumerate(body):
            if not (isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name)):
                continue
            doc = comments.get(stmt.end_lineno) or comments.get(stmt.lineno)
            after = body[i + 1] if i + 1 < len(body) else None
            if isinstance(after, ast.Expr) and isinstance(getattr(after, "value", None), ast.Constant) \
                    and isinstance(after.value.value, str):
                doc = inspect.cleandoc(after.value.value)
            if doc:
                docs[stmt.target.id] = doc
    return docs


def _unwrap_optional(kind):
    """``X | None`` -> X; anything else unchanged."""
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(kind) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return kind


def _argument(f: dataclasses.Field, kind, doc: str) -> tuple[list[str], dict]:
    """The names and keywords of ``parser.add_argument`` for one field."""
    kind = _unwrap_optional(kind)
    origin = typing.get_origin(kind)
    has_default = f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING
    default = f.default if f.default is not dataclasses.MISSING else (
        f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
    kw: dict = {"help": doc}
    if kind is bool:  # a flag; --no-NAME turns off one that is on (or, when None, set) by default
        kw["action"] = argparse.BooleanOptionalAction if default in (True, None) else "store_true"
    elif origin is typing.Literal:
        kw["choices"] = typing.get_args(kind)
        kw["type"] = type(kw["choices"][0])
    elif origin in (tuple, list):
        kw["type"] = typing.get_args(kind)[0]
        kw["nargs"] = "+"
    else:
        kw["type"] = kind
    if default not in (None, False, "", ()):
        shown = ",".join(map(str, default)) if isinstance(default, (tuple, list)) else default
        kw["help"] = f"{doc} (default: {shown})" if doc else f"default: {shown}"
    if has_default:  # left out when not given: the dataclass's own default applies
        kw["default"] = argparse.SUPPRESS
    if f.metadata.get("positional"):
        if has_default and "nargs" not in kw:
            kw["nargs"] = "?"
        return [f.name], {**kw, "metavar": f.metadata.get("metavar", f.name.upper())}
    if "metavar" in f.metadata:
        kw["metavar"] = f.metadata["metavar"]
    if not has_default:
        kw["required"] = True
    return ["--" + f.name.replace("_", "-")], {**kw, "dest": f.name}


def cli_fields(cls) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(cls) if f.init and f.metadata.get("cli", True)]


def add_options(parser: argparse.ArgumentParser, cls) -> None:
    """An argument per field of dataclass ``cls`` (see the module docstring)."""
    hints, docs = typing.get_type_hints(cls, include_extras=False), field_docs(cls)
    for f in cli_fields(cls):
        names, kw = _argument(f, hints[f.name], docs.get(f.name, ""))
        parser.add_argument(*names, **kw)


def from_namespace(cls, namespace: argparse.Namespace):
    """The dataclass ``cls`` from parsed arguments; defaults stay the dataclass's own."""
    values = {}
    for f in cli_fields(cls):
        if not hasattr(namespace, f.name):
            continue
        value = getattr(namespace, f.name)
        if isinstance(value, list):
            if f.metadata.get("split", True):
                value = [part.strip() for v in value for part in str(v).split(",") if part.strip()]
            value = tuple(value)
        values[f.name] = value
    return cls(**values)


def add_command(subparsers, name: str, cls) -> argparse.ArgumentParser:
    """A subcommand ``name`` whose options are the fields of ``cls`` (its docstring: help, description)."""
    doc = inspect.cleandoc(cls.__doc__ or "")
    parser = subparsers.add_parser(name, help=doc.splitlines()[0] if doc else None, description=doc or None)
    add_options(parser, cls)
    parser.set_defaults(options_class=cls)
    return parser

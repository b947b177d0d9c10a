"""batch.json: the machine-readable record of a batch folder, what ``gndreplay batch --merge`` reads back.

It holds the format version, the shard (index, count; null for a whole batch), the number of inputs of the
whole batch and the global index of each input this folder ran (``shard.shard_indices``), the digest of
what defines the batch, the thresholds file (absolute path and sha256) and every ``InputResult`` field by
field (a field added to ``InputResult`` is written and read back without change here); floats are finite
or null (read back as nan), run directories relative to the batch folder (``a`` or ``variant/a``).

The digest is the sha256 of the batch's definition: the gndreplay version, every task in order (input
path, kind, seed, scenario, limits, the resolved stack configuration, the run, read and scenario options,
the run directory relative to the batch folder), the content of the scenarios' ``--config`` file, the
thresholds file's sha256 and the per-input timeout. Two folders are shards of one batch when their
digests are equal. A path inside the current folder enters the digest relative to it (shards run from
checkouts at different places agree), any other path absolute.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path, PurePath, PurePosixPath
from typing import Any

from .. import __version__
from ..errors import ConfigError
from ..io.userfile import brief, read_bytes, read_text
from .shard import Shard, shard_indices
from .sweep import SweepPoint
from .thresholds import MAX_THRESHOLDS_BYTES, Thresholds
from .worker import InputResult, Task

__all__ = [
    "BATCH_FILE",
    "FORMAT",
    "VERSION",
    "BatchRecord",
    "RecordError",
    "batch_digest",
    "plain",
    "read_record",
    "record_json",
    "relative_runs",
    "thresholds_digest",
    "thresholds_ref",
]

#: The record's file in a batch folder.
BATCH_FILE = "batch.json"
#: ``format`` of the record (how a batch folder is recognised).
FORMAT = "gndreplay batch"
#: Version of the record's layout.
VERSION = 1
#: Largest batch.json read back (a batch of 100,000 inputs with tracebacks stays far below).
MAX_RECORD_BYTES = 1 << 30


class RecordError(ConfigError):
    """A folder is not a gndreplay batch folder, or its batch.json is malformed (the message names it)."""


@dataclass(frozen=True, slots=True)
class BatchRecord:
    """What batch.json says.

    Attributes:
        digest: sha256 (hex) of what defines the batch (``batch_digest``).
        total: inputs of the whole batch, before sharding.
        shard: the shard this folder ran, or None (the whole batch).
        indices: the global index of each result (``shard_indices(total, shard)``).
        thresholds_path: the thresholds file (absolute), or None (the defaults or limits given in code).
        thresholds_sha256: ``thresholds_digest`` of the thresholds the batch ran with.
        results: one per index; run directories relative to the batch folder.
        points: the sweep's combinations (one unnamed point when nothing is swept).
    """

    digest: str
    total: int
    shard: Shard | None
    indices: tuple[int, ...]
    thresholds_path: str | None
    thresholds_sha256: str
    results: tuple[InputResult, ...] = ()
    points: tuple[SweepPoint, ...] = (SweepPoint("", (), ()),)


def plain(x: Any, path_text: Callable[[PurePath], str] = PurePath.as_posix) -> Any:
    """JSON-ready data of ``x``: a dataclass field by field, mappings (string keys), sequences as lists,
    paths through ``path_text`` (default: as POSIX strings), non-finite floats as None."""
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {f.name: plain(getattr(x, f.name), path_text) for f in dataclasses.fields(x)}
    if isinstance(x, Mapping):
        return {str(k): plain(v, path_text) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [plain(v, path_text) for v in x]
    if isinstance(x, PurePath):
        return path_text(x)
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _canonical(x: Any, path_text: Callable[[PurePath], str] = PurePath.as_posix) -> bytes:
    return json.dumps(plain(x, path_text), sort_keys=True, separators=(",", ":"), default=repr).encode()


def _portable(base: Path) -> Callable[[PurePath], str]:
    """A path as the digest takes it: relative to ``base`` (the current folder) when inside it, so shards
    run from checkouts at different places agree; else absolute."""

    def text(p: PurePath) -> str:
        return p.relative_to(base).as_posix() if p.is_absolute() and p.is_relative_to(base) else p.as_posix()

    return text


def thresholds_digest(thresholds: Thresholds) -> str:
    """sha256 of the thresholds file's bytes, or, for thresholds without a file, of their limits and rules.

    Raises:
        ConfigError: the file cannot be read.
    """
    if thresholds.source is not None:
        return _sha256(read_bytes(thresholds.source, "thresholds file", MAX_THRESHOLDS_BYTES))
    return _sha256(_canonical(replace(thresholds, source=None)))


def _file_digest(path: Path | None) -> str | None:
    """sha256 of a scenario configuration file (None: no file, or one that cannot be read: its runs say
    why)."""
    if path is None:
        return None
    from ..config import MAX_CONFIG_BYTES

    try:
        return _sha256(read_bytes(path, "config file", MAX_CONFIG_BYTES))
    except ConfigError:
        return None


def batch_digest(
    tasks: Sequence[Task], out_dir: Path, *, thresholds_sha256: str, timeout_s: float | None
) -> str:
    """sha256 (hex) of what defines a batch (see the module docstring): equal for its shards, whatever the
    batch folder each writes."""
    path_text = _portable(Path.cwd())
    defined = {
        "gndreplay": __version__,
        "tasks": [replace(t, run_dir=t.run_dir.relative_to(out_dir)) for t in tasks],
        "config_files": sorted({path_text(t.sim.config): _file_digest(t.sim.config)
                                for t in tasks if t.sim is not None and t.sim.config is not None}.items()),
        "thresholds": thresholds_sha256,
        "timeout_s": timeout_s,
    }
    return _sha256(_canonical(defined, path_text))


def _relative(r: InputResult, folder: Path) -> InputResult:
    """``r`` with its run directory relative to ``folder`` (one outside it as it is)."""
    if r.run_dir is None or not Path(r.run_dir).is_absolute() or not Path(r.run_dir).is_relative_to(folder):
        return r
    return replace(r, run_dir=Path(r.run_dir).relative_to(folder))


def relative_runs(results: Sequence[InputResult], folder: Path) -> tuple[InputResult, ...]:
    """``results`` with their run directories relative to the batch folder ``folder``."""
    return tuple(_relative(r, folder) for r in results)


def record_json(record: BatchRecord) -> str:
    """batch.json's text."""
    doc = {
        "format": FORMAT,
        "version": VERSION,
        "gndreplay": __version__,
        "digest": record.digest,
        "shard": None if record.shard is None else {"index": record.shard.index, "count": record.shard.count},
        "tasks": record.total,
        "indices": list(record.indices),
        "thresholds": {"path": record.thresholds_path, "sha256": record.thresholds_sha256},
        "sweep": [{"name": p.name, "values": [list(kv) for kv in p.values]} for p in record.points if p.name],
        "results": [plain(r) for r in record.results],
    }
    return json.dumps(doc, indent=2, ensure_ascii=False, allow_nan=False) + "\n"


# ---- reading back ------------------------------------------------------------------------------------------


def _bad(where: str, what: str, value: Any) -> RecordError:
    return RecordError(f"{where}: expected {what}, got {brief(value)}")


def _run_dir(value: Any, where: str) -> Path:
    """A run directory relative to the batch folder, inside it (no ``..``, not absolute, not hidden)."""
    if not isinstance(value, str):
        raise _bad(where, "a relative path", value)
    p = PurePosixPath(value)
    if p.is_absolute() or not p.parts or any(part in (".", "..") or part.startswith(".") for part in p.parts):
        raise _bad(where, "a path inside the batch folder", value)
    return Path(*p.parts)


def _typed(tp: Any, value: Any, where: str) -> Any:
    """``value`` read back as the type ``tp`` of an ``InputResult`` field (a float: null is nan, an integer
    stays one, as it was written); a type not known here passes the value as it is."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        return _typed(next(a for a in args if a is not type(None)), value, where)
    if origin is typing.Literal:
        if value not in args:
            raise _bad(where, " or ".join(repr(a) for a in args), value)
        return value
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        if not isinstance(value, list):
            raise _bad(where, "a list", value)
        return tuple(_typed(args[0], v, f"{where}[{k}]") for k, v in enumerate(value))
    if origin in (dict, Mapping) or tp in (dict, Mapping):
        if not isinstance(value, dict):
            raise _bad(where, "an object", value)
        item = args[1] if len(args) == 2 else Any
        return {k: _typed(item, v, f"{where}.{k}") for k, v in value.items()}
    if tp is float:
        if value is None:
            return math.nan
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise _bad(where, "a number or null", value)
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise _bad(where, "an integer", value)
        return value
    if tp in (str, bool) and not isinstance(value, tp):
        raise _bad(where, "a string" if tp is str else "true or false", value)
    return value


def _result(doc: Any, where: str) -> InputResult:
    """An ``InputResult`` from its fields (a missing one takes its default; an unknown one is refused: the
    record is of a newer gndreplay)."""
    if not isinstance(doc, dict):
        raise _bad(where, "an object", doc)
    hints = typing.get_type_hints(InputResult)
    unknown = sorted(set(doc) - set(hints))
    if unknown:
        raise RecordError(f"{where}: unknown field {unknown[0]!r} (written by another gndreplay version?)")
    fields: dict[str, Any] = {}
    for name, value in doc.items():
        at = f"{where}.{name}"
        fields[name] = (None if value is None else _run_dir(value, at)) if name == "run_dir" else (
            _typed(hints[name], value, at))
    try:
        return InputResult(**fields)
    except TypeError as err:  # a required field missing
        raise RecordError(f"{where}: {err}") from None


def _int(value: Any, where: str, lo: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise _bad(where, f"an integer >= {lo}", value)
    return value


def _shard(value: Any, where: str) -> Shard | None:
    if value is None:
        return None
    if not isinstance(value, dict) or set(value) != {"index", "count"}:
        raise _bad(where, "null or an object of index and count", value)
    try:
        return Shard(_int(value["index"], f"{where}.index"), _int(value["count"], f"{where}.count", 1))
    except ConfigError as err:
        raise RecordError(f"{where}: {err}") from None


def _points(value: Any, where: str) -> tuple[SweepPoint, ...]:
    """The sweep's combinations (``[]``: none swept) as ``SweepPoint``s (their ``--set`` pairs are not
    recorded: the digest stands for them)."""
    if not isinstance(value, list):
        raise _bad(where, "a list", value)
    points = []
    for k, p in enumerate(value):
        at = f"{where}[{k}]"
        if not (isinstance(p, dict) and set(p) == {"name", "values"} and isinstance(p["name"], str)
                and p["name"] and isinstance(p["values"], list)
                and all(isinstance(kv, list) and len(kv) == 2 and all(isinstance(x, str) for x in kv)
                        for kv in p["values"])):
            raise _bad(at, "an object of name and values ([key, value] pairs)", p)
        points.append(SweepPoint(p["name"], tuple((kv[0], kv[1]) for kv in p["values"]), ()))
    return tuple(points) or (SweepPoint("", (), ()),)


def read_record(folder: Path) -> BatchRecord:
    """The batch.json of the batch folder ``folder`` (results with run directories relative to it).

    Raises:
        RecordError: ``folder`` is not a folder or has no batch.json (not a gndreplay batch folder), or its
            batch.json is malformed, of another format version, or inconsistent (indices not the shard's).
    """
    folder = Path(folder)
    path = folder / BATCH_FILE
    if not folder.is_dir():
        raise RecordError(f"{folder}: not a folder (expected a gndreplay batch folder)")
    if not path.exists():
        raise RecordError(f"{folder}: no {BATCH_FILE} in it: not a gndreplay batch folder")
    try:
        doc = json.loads(read_text(path, "batch record", MAX_RECORD_BYTES))
    except RecursionError:
        raise RecordError(f"{path}: nested too deep") from None
    except ValueError as err:
        raise RecordError(f"{path}: not valid JSON: {err}") from None
    except ConfigError as err:
        raise RecordError(str(err)) from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise RecordError(f"{path}: not a gndreplay batch record (no \"format\": {FORMAT!r})")
    if doc.get("version") != VERSION:
        raise RecordError(f"{path}: format version {brief(doc.get('version'))}; this gndreplay reads "
                          f"version {VERSION}")
    digest, th = doc.get("digest"), doc.get("thresholds")
    if not isinstance(digest, str) or not digest:
        raise _bad(f"{path}: digest", "a string", digest)
    if not (isinstance(th, dict) and isinstance(th.get("sha256"), str)
            and (th.get("path") is None or isinstance(th.get("path"), str))):
        raise _bad(f"{path}: thresholds", "an object of path and sha256", th)
    total = _int(doc.get("tasks"), f"{path}: tasks")
    shard = _shard(doc.get("shard"), f"{path}: shard")
    indices, results = doc.get("indices"), doc.get("results")
    if not isinstance(indices, list) or indices != shard_indices(total, shard):
        raise _bad(f"{path}: indices", f"the indices of shard {shard or 'whole'} of {total} inputs", indices)
    if not isinstance(results, list) or len(results) != len(indices):
        raise _bad(f"{path}: results", f"a list of {len(indices)} results", results)
    return BatchRecord(
        points=_points(doc.get("sweep", []), f"{path}: sweep"),
        digest=digest,
        total=total,
        shard=shard,
        indices=tuple(indices),
        thresholds_path=th["path"],
        thresholds_sha256=th["sha256"],
        results=tuple(_result(r, f"{path}: results[{k}]") for k, r in enumerate(results)),
    )


def thresholds_ref(thresholds: Thresholds) -> tuple[str | None, str]:
    """(absolute path of the thresholds file or None, ``thresholds_digest``) as batch.json records them."""
    path = None if thresholds.source is None else os.path.abspath(thresholds.source)
    return path, thresholds_digest(thresholds)

"""``gndreplay batch --merge``: the shard folders of one batch (``--shard I/N``) joined into one batch
folder, the same files an unsharded batch writes.

The shards' batch.json records are checked to be of one batch (equal digests, the same number of shards,
each shard once, none missing); the results are put back in global order; each run directory is recreated
in the new folder with a hard link per file (a copy where a link cannot be made, e.g. across file
systems); the per-scenario aggregates over seeds are computed again over all seeds, with the thresholds
the shards ran with, and the files are written by ``run.write_outputs``, as a batch writes them. The shard
folders are only read.
"""

from __future__ import annotations

import os
import shutil
import stat
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from .. import fsutil
from ..errors import ConfigError
from .record import BatchRecord, RecordError, read_record, thresholds_ref
from .run import Baseline, BatchResult, _mkdirs_marked, build_batch
from .shard import Shard
from .thresholds import Thresholds, load_thresholds
from .worker import InputResult

__all__ = ["merge_batches", "merge_order", "merge_thresholds"]


def _shard(record: BatchRecord) -> Shard:
    return record.shard if record.shard is not None else Shard(0, 1)


def merge_order(records: Sequence[tuple[Path, BatchRecord]]) -> list[tuple[Path, InputResult]]:
    """Every result of the shard folders ``records`` (folder, its record) in the batch's global order,
    each with the folder it is in.

    Raises:
        RecordError: no folder; a folder of another batch (its digest differs from the first's), or split
            into another number of shards; a shard given twice; a shard missing.
    """
    if not records:
        raise RecordError("--merge: give the shard folders of a batch")
    first, head = records[0]
    count = _shard(head).count
    seen: dict[int, Path] = {}
    for folder, record in records:
        shard = _shard(record)
        if record.digest != head.digest:
            raise RecordError(
                f"{folder}: a shard of another batch than {first} (the inputs, options, configuration or "
                "thresholds differ: batch.json digests differ)"
            )
        if shard.count != count:
            raise RecordError(f"{folder}: shard {shard}, but {first} is one of {count} shards")
        if shard.index in seen:
            raise RecordError(f"{seen[shard.index]} and {folder} are both shard {shard}; give each once")
        seen[shard.index] = folder
    missing = [i for i in range(count) if i not in seen]
    if missing:
        shown = ", ".join(f"{i}/{count}" for i in missing[:5]) + (", ..." if len(missing) > 5 else "")
        raise RecordError(f"shard {shown} missing: give every shard folder of the batch ({count} shards)")
    placed: dict[int, tuple[Path, InputResult]] = {}
    for folder, record in records:
        for index, result in zip(record.indices, record.results, strict=True):
            placed[index] = (folder, result)
    return [placed[i] for i in range(head.total)]


def merge_thresholds(record: BatchRecord, given: Thresholds | None) -> Thresholds:
    """The thresholds the shards ran with: ``given`` (e.g. ``--thresholds F``), else the file the record
    names, else the defaults; checked against the record's sha256.

    Raises:
        ConfigError: the file is gone, unreadable or changed since the shards ran, or ``given`` differs.
    """
    if given is None and record.thresholds_path is not None:
        path = Path(record.thresholds_path)
        if not path.exists():
            raise ConfigError(
                f"{path}: the thresholds file the shards ran with is not there; give it with --thresholds"
            )
        given = load_thresholds(path)
    thresholds = given if given is not None else Thresholds()
    _, sha = thresholds_ref(thresholds)
    if sha != record.thresholds_sha256:
        what = thresholds.source if thresholds.source is not None else "the default thresholds"
        raise ConfigError(
            f"{what}: not the thresholds the shards ran with (sha256 {sha[:12]}... differs from "
            f"{record.thresholds_sha256[:12]}...); give the file they ran with (--thresholds)"
        )
    return thresholds


def _link_tree(src: Path, dst: Path) -> None:
    """Recreate the run directory ``src`` at ``dst``: its folders, and a hard link to each of its files (a
    copy where the link cannot be made). ``src`` is only read.

    Raises:
        RecordError: ``src`` is missing, or holds a symbolic link or a special file (gndreplay writes
            neither).
    """
    if not src.is_dir() or src.is_symlink():
        raise RecordError(f"{src}: the run directory its batch.json names is missing (or not a folder)")
    def unreadable(err: OSError) -> None:
        raise RecordError(f"{err.filename}: cannot read it ({err.strerror or err})")

    for root, dirs, files in os.walk(src, onerror=unreadable):
        here = Path(root)
        (dst / here.relative_to(src)).mkdir(exist_ok=True)
        for name in (*dirs, *files):
            entry = here / name
            mode = entry.lstat().st_mode
            if stat.S_ISDIR(mode):
                continue
            if not stat.S_ISREG(mode):
                raise RecordError(f"{entry}: not a regular file (gndreplay writes none in a run directory)")
            target = dst / entry.relative_to(src)
            try:
                os.link(entry, target, follow_symlinks=False)
            except OSError:  # another file system, a link limit, a file system without hard links
                shutil.copy2(entry, target, follow_symlinks=False)


def merge_batches(
    folders: Sequence[Path],
    *,
    out_dir: Path = Path("out/batch"),
    junit: Path | None = None,
    thresholds: Thresholds | None = None,
    overwrite: bool = False,
    baseline: Baseline | None = None,
) -> BatchResult:
    """Join the shard folders of one batch into the batch folder ``out_dir``: the files and exit code an
    unsharded batch of the same inputs gives (summary.csv, summary.md, scenarios.csv, ``junit``,
    batch.json, and each input's run directory, hard-linked). ``out_dir`` is protected as any batch
    folder (``run_batch``); the shard folders are never modified.

    Args:
        thresholds: the thresholds to check the aggregates over seeds with (None: the file the shards ran
            with, which must not have changed); they must be the ones the shards ran with.
        baseline: compare every run with this baseline batch folder, as ``run_batch`` does.

    Raises:
        RecordError: a folder is not a gndreplay batch folder, is of another batch, or a shard is missing
            or given twice (see ``merge_order``); a run directory is missing.
        ConfigError: the thresholds are not the ones the shards ran with.
        OutputError: ``out_dir`` (or ``junit``) is unsafe to write.
    """
    t0 = time.perf_counter()
    records = [(Path(f), read_record(Path(f))) for f in folders]
    placed = merge_order(records)
    head = records[0][1]
    limits = merge_thresholds(head, thresholds)
    whole = replace(head, shard=None, indices=tuple(range(head.total)), results=())

    def produce(tmp: Path, final: Path) -> tuple[InputResult, ...]:
        results = []
        for folder, r in placed:
            if r.run_dir is not None:
                rel = Path(r.run_dir)
                _mkdirs_marked(tmp, rel.parent)
                _link_tree(folder / rel, tmp / rel)
                fsutil.add_to_marker(tmp / rel.parent, [rel.name])
                r = replace(r, run_dir=final / rel)
            results.append(r)
        return tuple(results)

    return build_batch(
        out_dir, inputs=[f for f, _ in records], junit=junit, overwrite=overwrite, thresholds=limits,
        record=whole, produce=produce, t0=t0, baseline=baseline,
    )

"""Safe file output: gndreplay never deletes or overwrites anything it did not write.

- Files are written atomically (a temporary sibling, then a rename), so no reader and no failed run ever
  sees half a file; final files get the usual permissions (0666 / 0777 less the umask), not mkstemp's 0600.
- Output directories (a run directory, a batch folder) are built in a staging directory beside the target
  and renamed into place only when complete. Each carries ``RUN_MARKER``, a file listing what gndreplay
  wrote there; only such a directory may be replaced (and only when every entry in it is listed).
- Staging directories are named ``.gndreplay-tmp-<host>-<pid>-<random>``: they are removed on every exit
  Python sees (exceptions, Ctrl-C, SIGTERM) and, when a run was killed, by the next run in the same folder
  (the owning process is gone).
- Timestamps are printed from integer nanoseconds by one function, ``format_stamp``, in every file.
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
import signal
import socket
import tempfile
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import FrameType

from .errors import OutputError

__all__ = [
    "RUN_MARKER",
    "TMP_PREFIX",
    "add_to_marker",
    "atomic_path",
    "atomic_write_text",
    "check_may_write",
    "check_output_dir",
    "format_stamp",
    "is_output_dir",
    "publish_dir",
    "remove_stale_staging",
    "resolve_output_dir",
    "safe_name",
    "staging_dir",
    "terminate_raises",
    "umask_mode",
    "write_marker",
]

RUN_MARKER = ".gndreplay"
TMP_PREFIX = ".gndreplay-tmp-"
_MARKER_HEAD = "# gndreplay output directory: the entries below were written by gndreplay\n"
_NS_PER_S = 1_000_000_000


def format_stamp(t_ns: int) -> str:
    """The one text form of a timestamp in every output file: exact decimal seconds with 9 digits from
    integer nanoseconds (no float rounding), e.g. ``1103939430.181894000``."""
    t = int(t_ns)
    sign = "-" if t < 0 else ""
    a = abs(t)
    return f"{sign}{a // _NS_PER_S}.{a % _NS_PER_S:09d}"


def umask_mode(base: int) -> int:
    """``base`` (0o666 for files, 0o777 for folders) less the process umask."""
    mask = os.umask(0)
    os.umask(mask)
    return base & ~mask


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path``, on error it is removed."""
    path = Path(path)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.chmod(tmp, umask_mode(0o666))
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8, newlines as given) to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8", newline="")


# ---- names ---------------------------------------------------------------------------------------------

_UNSAFE = re.compile(r"[\x00-\x1f/\\:]+")


def safe_name(name: str, default: str = "run") -> str:
    """A file-name component derived from ``name`` that is never empty, ``.``, ``..`` or hidden: path
    separators and control characters become ``_``, leading dots and surrounding blanks are dropped."""
    s = _UNSAFE.sub("_", name).strip().lstrip(".").strip()
    return s if s and s not in (".", "..") else default


# ---- the marker ----------------------------------------------------------------------------------------


def is_output_dir(path: Path) -> bool:
    """``path`` is a directory gndreplay created (it carries ``RUN_MARKER``)."""
    return (Path(path) / RUN_MARKER).is_file()


def _owned(directory: Path) -> set[str]:
    try:
        text = (directory / RUN_MARKER).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return set()
    return {line for line in text.splitlines() if line and not line.startswith("#")} | {RUN_MARKER}


def write_marker(directory: Path, names: Sequence[str] | None = None) -> None:
    """Write ``RUN_MARKER`` into ``directory`` listing ``names`` (default: every entry there now) as
    written by gndreplay; call it again when more entries are added (a batch folder)."""
    directory = Path(directory)
    listed = sorted(names if names is not None else (p.name for p in directory.iterdir()))
    body = "".join(f"{n}\n" for n in listed if n != RUN_MARKER)
    (directory / RUN_MARKER).write_text(_MARKER_HEAD + body, encoding="utf-8")
    os.chmod(directory / RUN_MARKER, umask_mode(0o666))


def add_to_marker(directory: Path, names: Sequence[str]) -> None:
    """List ``names`` (entries gndreplay just wrote) in the marker of ``directory``, if it has one (e.g.
    figures redrawn into a run directory written with --no-figures, or a run added to a batch folder)."""
    directory = Path(directory)
    if is_output_dir(directory):
        write_marker(directory, sorted((_owned(directory) - {RUN_MARKER}) | set(names)))


def _foreign(directory: Path, prefix: str = "") -> list[str]:
    """Entries of a marked directory that gndreplay did not write (sorted, relative to ``directory``): those
    its marker does not list, and, recursively, inside each listed folder, everything when that folder has
    no marker of its own and the entries its marker does not list otherwise (a user's file in a run folder
    of a batch is foreign too: replacing the batch folder would delete it)."""
    directory = Path(directory)
    owned = _owned(directory)
    out: list[str] = []
    try:
        entries = sorted(directory.iterdir())
    except OSError:
        return [prefix or str(directory)]
    for p in entries:
        rel = f"{prefix}{p.name}"
        if p.name not in owned:
            out.append(rel)
        elif p.is_dir() and not p.is_symlink():
            out += _foreign(p, f"{rel}/") if is_output_dir(p) else [f"{rel}/"]
    return out


def check_may_write(directory: Path, names: Sequence[str]) -> None:
    """Refuse to write ``names`` into ``directory`` over a file gndreplay did not write: an existing entry
    must be listed in the directory's ``RUN_MARKER`` (no marker: no existing entry may be replaced).

    Raises:
        OutputError: naming the first such entry.
    """
    directory = Path(directory)
    marked = is_output_dir(directory)
    owned = _owned(directory) if marked else set()
    why = f"not listed in {directory / RUN_MARKER}" if marked else f"{directory} has no {RUN_MARKER} marker"
    for name in names:
        p = directory / name
        if (p.exists() or p.is_symlink()) and name not in owned:
            raise OutputError(f"{p}: exists and was not written by gndreplay ({why}); not overwriting it")


# ---- checks before any work ------------------------------------------------------------------------------


def _abs(path: Path) -> Path:
    return Path(os.path.abspath(Path(path).expanduser()))


def _norm(path: Path) -> Path:
    """``path`` without ``.``/``..`` components, resolved by name like ``_abs`` (relative stays relative)."""
    return Path(os.path.normpath(Path(path).expanduser()))


def _check_creatable(out: Path, o: Path, anc: Path) -> None:
    """Refuse ``out`` when its staging folder could not be created (a read-only parent, /proc, /sys): try
    to make, then remove, an empty staging-named folder in the nearest existing folder on the way."""
    where = o.parent if anc == o else anc
    probe = _staging_name(where)
    try:
        probe.mkdir(mode=0o700)
        probe.rmdir()
    except OSError as err:
        raise OutputError(f"{out}: cannot create it in {where} ({err.strerror or err})") from err


def _real(path: Path) -> Path:
    return Path(os.path.realpath(path))


def _within(child: Path, parent: Path) -> bool:
    return child == parent or child.is_relative_to(parent)


def check_output_dir(out: Path, *, inputs: Sequence[Path] = (), overwrite: bool = False) -> None:
    """Refuse an output directory that could cost the user a file, before any work is done.

    Refused (``OutputError``, one line naming ``out``): ``out`` is a file or lies inside one; ``out`` is
    a symbolic link; ``out`` cannot be created (its staging folder beside it cannot); ``out`` is
    the current directory or one of its ancestors; ``out`` contains an input (or lies inside an input
    folder); ``out`` exists, is not empty and has no ``RUN_MARKER``; with ``overwrite``, ``out`` holds
    entries its marker does not list, at any depth (files the user added). An existing marked directory is
    accepted: the caller replaces it (``overwrite``) or writes beside it (``resolve_output_dir``).
    """
    o = _abs(out)
    if o.is_symlink():
        raise OutputError(f"{out}: is a symbolic link; give the folder it points to ({_real(o)}) instead")
    anc = o
    for anc in (o, *o.parents):
        if anc.exists() or anc.is_symlink():
            if not anc.is_dir():
                where = "is a file" if anc == o else f"is inside {anc}, which is a file"
                raise OutputError(f"{out}: {where}; --out must be a directory")
            break
    real = _real(o)
    if _within(_real(Path.cwd()), real):
        raise OutputError(f"{out}: is the current directory or one of its parents; choose a new folder")
    for p in inputs:
        ip = _real(_abs(Path(p)))
        if _within(ip, real):
            raise OutputError(f"{out}: contains the input {p}; choose a folder that holds no input")
        if ip.is_dir() and _within(real, ip):
            raise OutputError(f"{out}: is inside the input folder {p}; choose a folder outside it")
    _check_creatable(out, o, anc)
    if not o.is_dir():
        return
    if not is_output_dir(o):
        if any(o.iterdir()):
            raise OutputError(
                f"{out}: exists, is not empty and was not written by gndreplay (no {RUN_MARKER} marker); "
                "choose a new folder"
            )
        return
    if overwrite:
        foreign = _foreign(o)
        if foreign:
            shown = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
            raise OutputError(f"{out}: holds files gndreplay did not write ({shown}); not replacing it")


def resolve_output_dir(out: Path, *, overwrite: bool = False) -> Path:
    """Where to write: ``out`` when it is free, empty or (with ``overwrite``) a gndreplay output directory;
    otherwise the first free ``out-2``, ``out-3``, ... beside it (an earlier run is never replaced
    silently). Call after ``check_output_dir``. ``..`` components are resolved by name (as the check does)."""
    out = _norm(out)
    if not out.exists() or (out.is_dir() and (overwrite or not any(out.iterdir()))):
        return out
    k = 2
    while True:
        cand = out.with_name(f"{out.name}-{k}")
        if not cand.exists() and not cand.is_symlink():
            return cand
        k += 1


# ---- staging ----------------------------------------------------------------------------------------------


def _host() -> str:
    return safe_name(socket.gethostname().split(".")[0], "host").replace("-", "_")


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_staging(parent: Path) -> list[Path]:
    """Remove staging directories in ``parent`` left by killed gndreplay processes of this host: named
    ``TMP_PREFIX<host>-<pid>-<random>``, carrying ``RUN_MARKER``, and their process gone. Returns them."""
    parent = Path(parent)
    removed: list[Path] = []
    if not parent.is_dir():
        return removed
    host = _host()
    for entry in parent.glob(f"{TMP_PREFIX}{host}-*"):
        parts = entry.name[len(TMP_PREFIX) + len(host) + 1:].split("-")
        if len(parts) != 2 or not parts[0].isdigit():
            continue
        pid = int(parts[0])
        if pid == os.getpid() or _pid_alive(pid):
            continue
        if entry.is_dir() and not entry.is_symlink() and is_output_dir(entry):
            shutil.rmtree(entry, ignore_errors=True)
            removed.append(entry)
    return removed


def _staging_name(parent: Path) -> Path:
    return parent / f"{TMP_PREFIX}{_host()}-{os.getpid()}-{secrets.token_hex(4)}"


def _new_staging(parent: Path) -> Path:
    """A fresh marked staging folder in ``parent`` (created if missing).

    Raises:
        OutputError: it cannot be created (read-only or special file system), naming the folder.
    """
    try:
        parent.mkdir(parents=True, exist_ok=True)
        while True:
            tmp = _staging_name(parent)
            try:
                tmp.mkdir(mode=0o700)
            except FileExistsError:
                continue
            write_marker(tmp, [])
            return tmp
    except OSError as err:
        raise OutputError(f"{parent}: cannot create the output folder there ({err.strerror or err})") from err


def publish_dir(tmp: Path, out: Path, *, overwrite: bool = False) -> None:
    """Move the complete staging directory ``tmp`` to ``out``: list its entries in ``RUN_MARKER``, give it
    the usual permissions, and rename it into place. An existing ``out`` must be empty, or a gndreplay
    output directory holding only listed entries and ``overwrite`` given; it is then swapped out (renamed
    to a staging name, so a crash in between leaves nothing a later run would not clean) and removed.

    Raises:
        OutputError: ``out`` appeared meanwhile and may not be replaced.
    """
    tmp, out = Path(tmp), _abs(out)
    try:
        _publish(tmp, out, overwrite=overwrite)
    except OSError as err:
        raise OutputError(f"{out}: cannot move the finished output there ({err.strerror or err})") from err


def _publish(tmp: Path, out: Path, *, overwrite: bool) -> None:
    write_marker(tmp)
    os.chmod(tmp, umask_mode(0o777))
    if out.is_dir() and not out.is_symlink() and not any(out.iterdir()):
        os.rename(tmp, out)  # replaces an empty directory
        return
    if out.exists() or out.is_symlink():
        check_output_dir(out, overwrite=True)
        if not (overwrite and is_output_dir(out)):
            raise OutputError(f"{out}: exists (a previous run); pass --overwrite to replace it")
        trash = _staging_name(out.parent)
        os.rename(out, trash)  # the old run keeps its marker: a stale trash dir is recognised too
        os.rename(tmp, out)
        shutil.rmtree(trash, ignore_errors=True)
        return
    os.rename(tmp, out)


class _Terminated(SystemExit):
    """SIGTERM turned into an exception, so ``finally`` blocks and staging clean-up run."""


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    raise _Terminated(128 + signum)


@contextmanager
def terminate_raises() -> Iterator[None]:
    """While active (main thread only), SIGTERM raises ``SystemExit(143)`` instead of killing the process
    outright, so the clean-up of staging directories runs. The previous handler is restored after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGTERM)
    if previous not in (signal.SIG_DFL, None):  # someone else handles SIGTERM: leave theirs in place
        yield
        return
    signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


@contextmanager
def staging_dir(out: Path, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a fresh staging directory beside ``out``; when the block completes it is published as ``out``
    (``publish_dir``), on any exception (Ctrl-C and SIGTERM included) it is removed. Stale staging
    directories of killed runs in the same folder are removed first.

    Write everything (figures and report included) inside the block: ``out`` appears only when complete.
    """
    out = _abs(out)
    parent = out.parent
    remove_stale_staging(parent)
    with terminate_raises():
        tmp = _new_staging(parent)
        try:
            yield tmp
            publish_dir(tmp, out, overwrite=overwrite)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise

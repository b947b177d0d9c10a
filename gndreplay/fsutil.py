"""Safe file output: gndreplay never deletes or overwrites anything it did not write.

- Files are written atomically (a temporary sibling, then a rename), so no reader and no failed run ever
  sees half a file; final files get the usual permissions (0666 / 0777 less the umask), not mkstemp's 0600.
- Output directories (a run directory, a batch folder) are built in a staging directory beside the target
  and renamed into place only when complete, under the first name still free at that moment (a rename
  onto a taken name fails, so two runs started at once never meet). Each carries ``RUN_MARKER``, a regular
  file listing what gndreplay wrote there, itself replaced atomically (never written through a link); only
  such a directory may be replaced (and only when every entry in it is listed).
- Staging directories are named ``.gndreplay-tmp-<host>-<pid>-<random>`` and hold ``STAGING_PROOF``, which
  repeats that name: they are removed on every exit Python sees (exceptions, Ctrl-C, SIGTERM) and, when a
  run was killed, by the next run in the same folder (the owning process is gone and the proof matches; a
  folder that merely looks like one is never touched).
- A full disk, an exceeded quota or a read-only file system is one ``OutputError`` naming what could not
  be written (``write_errors``); the staging directory is removed, an earlier output stays as it was.
- Timestamps are printed from integer nanoseconds by one function, ``format_stamp``, in every file.
"""

from __future__ import annotations

import errno
import os
import re
import secrets
import shutil
import signal
import socket
import stat
import tempfile
import threading
from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager, suppress
from pathlib import Path
from types import FrameType, TracebackType

from .errors import OutputError, find_cause

__all__ = [
    "RUN_MARKER",
    "STAGING_PROOF",
    "TMP_PREFIX",
    "Staging",
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
    "write_errors",
    "write_marker",
]

RUN_MARKER = ".gndreplay"
TMP_PREFIX = ".gndreplay-tmp-"
STAGING_PROOF = ".gndreplay-staging"
_MARKER_HEAD = "# gndreplay output directory: the entries below were written by gndreplay\n"
_NS_PER_S = 1_000_000_000
#: Errors of the disk rather than of the run: no space, quota exceeded, read-only file system.
_NO_ROOM = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS})
#: A rename onto a name that is taken (a non-empty folder, a file) fails with one of these.
_TAKEN = frozenset({errno.EEXIST, errno.ENOTEMPTY, errno.ENOTDIR, errno.EISDIR})
_CLAIM_TRIES = 100


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


def _no_room(err: BaseException) -> bool:
    """``err`` is a full-disk, quota or read-only ``OSError``."""
    return isinstance(err, OSError) and err.errno in _NO_ROOM


@contextmanager
def write_errors(where: Path, note: str = "") -> Iterator[None]:
    """Turn a full disk, an exceeded quota or a read-only file system met inside the block into one
    ``OutputError`` naming ``where`` and the reason (plus ``note``); other errors pass unchanged. Nested,
    the outermost names the error: the output the user asked for, not a temporary inside it."""
    try:
        yield
    except Exception as err:
        cause = find_cause(err, _no_room)  # itself, or wrapped by a library
        if not isinstance(cause, OSError):
            raise
        raise OutputError(f"{where}: cannot write ({cause.strerror or cause}){note}") from err


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` (a link there is replaced,
    never followed), on error it is removed.

    Raises:
        OutputError: the disk is full, the quota exceeded or the file system read-only (``write_errors``).
    """
    path = Path(path)
    with write_errors(path):
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


def _marker(directory: Path) -> Path | None:
    """The ``RUN_MARKER`` file of ``directory``, None when there is none.

    Raises:
        OutputError: it is a symbolic link or not a regular file (gndreplay writes neither, and reading or
            writing through one would reach a file elsewhere).
    """
    path = Path(directory) / RUN_MARKER
    try:
        mode = path.lstat().st_mode
    except OSError:
        return None
    if stat.S_ISREG(mode):
        return path
    what = "is a symbolic link" if stat.S_ISLNK(mode) else "is not a regular file"
    raise OutputError(f"{path}: {what}, not a marker gndreplay wrote; not using this folder")


def _read_regular(path: Path) -> str | None:
    """The text of the regular file ``path``, read without following a link (None: missing, a link, not
    a regular file, unreadable)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        return f.read().decode("utf-8", errors="replace")


def is_output_dir(path: Path) -> bool:
    """``path`` is a directory gndreplay created (it carries ``RUN_MARKER``).

    Raises:
        OutputError: its marker is a symbolic link or not a regular file.
    """
    return _marker(Path(path)) is not None


def _owned(directory: Path) -> set[str]:
    text = _read_regular(Path(directory) / RUN_MARKER)
    if text is None:
        return set()
    return {line for line in text.splitlines() if line and not line.startswith("#")} | {RUN_MARKER}


def write_marker(directory: Path, names: Sequence[str] | None = None) -> None:
    """Write ``RUN_MARKER`` into ``directory`` listing ``names`` (default: every entry there now) as
    written by gndreplay; call it again when more entries are added (a batch folder). The marker is
    replaced atomically, so a link or another name of the old file is never written through.

    Raises:
        OutputError: the marker there is a symbolic link or not a regular file; the disk is full.
    """
    directory = Path(directory)
    _marker(directory)
    listed = sorted(names if names is not None else (p.name for p in directory.iterdir()))
    body = "".join(f"{n}\n" for n in listed if n != RUN_MARKER)
    atomic_write_text(directory / RUN_MARKER, _MARKER_HEAD + body)


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


def _proof_text(name: str) -> str:
    """What ``STAGING_PROOF`` holds in the staging folder called ``name``."""
    return f"gndreplay staging folder {name}\n"


def _staged_by_gndreplay(entry: Path) -> bool:
    """``entry`` is a staging folder gndreplay made: a folder (not a link) whose ``STAGING_PROOF`` is a
    regular file repeating the folder's name."""
    try:
        if not stat.S_ISDIR(entry.lstat().st_mode):
            return False
    except OSError:
        return False
    return _read_regular(entry / STAGING_PROOF) == _proof_text(entry.name)


def _staging_pid(name: str, host: str) -> int | None:
    """The process id in the name of a staging folder of ``host``, None when the name is not one."""
    parts = name[len(TMP_PREFIX) + len(host) + 1:].split("-")
    return int(parts[0]) if len(parts) == 2 and parts[0].isdigit() else None


def remove_stale_staging(parent: Path) -> list[Path]:
    """Remove staging directories in ``parent`` left by killed gndreplay processes of this host: named
    ``TMP_PREFIX<host>-<pid>-<random>``, their process gone, and holding the ``STAGING_PROOF`` of that name
    (a folder that merely looks like one is left alone). Returns them."""
    parent = Path(parent)
    removed: list[Path] = []
    if not parent.is_dir():
        return removed
    host = _host()
    for entry in parent.glob(f"{TMP_PREFIX}{host}-*"):
        pid = _staging_pid(entry.name, host)
        if pid is None or pid == os.getpid() or _pid_alive(pid) or not _staged_by_gndreplay(entry):
            continue
        shutil.rmtree(entry, ignore_errors=True)
        removed.append(entry)
    return removed


def _staging_name(parent: Path) -> Path:
    return parent / f"{TMP_PREFIX}{_host()}-{os.getpid()}-{secrets.token_hex(4)}"


def _new_staging(parent: Path) -> Path:
    """A fresh staging folder in ``parent`` (created if missing) holding its ``STAGING_PROOF`` and an empty
    ``RUN_MARKER``; nothing is left behind when that fails.

    Raises:
        OutputError: it cannot be created (read-only or special file system, full disk), naming the folder.
    """
    tmp: Path | None = None
    try:
        parent.mkdir(parents=True, exist_ok=True)
        while tmp is None:
            cand = _staging_name(parent)
            with suppress(FileExistsError):
                cand.mkdir(mode=0o700)
                tmp = cand
        (tmp / STAGING_PROOF).write_text(_proof_text(tmp.name), encoding="utf-8")
        (tmp / RUN_MARKER).write_text(_MARKER_HEAD, encoding="utf-8")  # a new folder: no link to follow
        return tmp
    except BaseException as err:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(err, OSError):
            why = err.strerror or err
            raise OutputError(f"{parent}: cannot create the output folder there ({why})") from err
        raise


class _NameTaken(OutputError):
    """The name to publish at is taken (a concurrent run may have published there meanwhile)."""


def publish_dir(tmp: Path, out: Path, *, overwrite: bool = False) -> None:
    """Move the complete staging directory ``tmp`` to ``out``: list its entries in ``RUN_MARKER``, give it
    the usual permissions, and rename it into place. The rename claims the name atomically: it replaces an
    empty folder and fails, moving nothing, when ``out`` is (or has just become) anything else. With
    ``overwrite``, a gndreplay output directory at ``out`` holding only listed entries is swapped out
    instead (``_swap``).

    Raises:
        OutputError: ``out`` is taken and may not be replaced (a ``_NameTaken`` when another name would do).
    """
    tmp, out = Path(tmp), _abs(out)
    try:
        _publish(tmp, out, overwrite=overwrite)
    except OSError as err:
        if err.errno in _TAKEN:
            raise _NameTaken(f"{out}: was taken meanwhile (by another run?); nothing moved there") from err
        raise OutputError(f"{out}: cannot move the finished output there ({err.strerror or err})") from err


def _occupied(path: Path) -> bool:
    """Something other than an empty folder is at ``path``."""
    if path.is_symlink() or (path.exists() and not path.is_dir()):
        return True
    return path.is_dir() and any(path.iterdir())


def _publish(tmp: Path, out: Path, *, overwrite: bool) -> None:
    write_marker(tmp)
    os.chmod(tmp, umask_mode(0o777))
    if not _occupied(out):
        os.rename(tmp, out)
    elif overwrite:
        _swap(tmp, out)
    else:
        raise _NameTaken(f"{out}: exists (a previous run); pass --overwrite to replace it")


def _swap(tmp: Path, out: Path) -> None:
    """Replace the gndreplay output directory ``out`` (checked: every entry listed) by ``tmp``. The old one
    is first moved into a fresh staging folder, so a crash in between leaves nothing a later run would not
    clean; it is put back when ``tmp`` cannot take its place, and removed otherwise."""
    check_output_dir(out, overwrite=True)
    trash = _new_staging(out.parent)
    try:
        os.rename(out, trash / "old")
        try:
            os.rename(tmp, out)
        except OSError:
            with suppress(OSError):
                os.rename(trash / "old", out)
            raise
    finally:
        shutil.rmtree(trash, ignore_errors=True)


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


class Staging:
    """A staging directory beside ``out``, the value of ``with``: published when the block completes
    (``publish_dir``), removed on any exception (Ctrl-C and SIGTERM included). Stale staging directories of
    killed runs in the same folder are removed first. Write everything (figures and report included) inside
    the block: the output appears only when complete.

    After the block, ``out`` is where it was published: the name asked for or, when a concurrent run took
    that one meanwhile, the next free name beside ``base`` (``resolve_output_dir``), as a run started after
    the other would get. A full disk, quota or read-only file system is one ``OutputError`` naming ``out``.
    """

    def __init__(self, out: Path, *, overwrite: bool = False, base: Path | None = None) -> None:
        self.out = Path(out)
        self.base = Path(base) if base is not None else self.out
        self.overwrite = overwrite
        self._active: AbstractContextManager[Path] | None = None

    def __enter__(self) -> Path:
        self._active = self._staged()
        return self._active.__enter__()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> bool | None:
        active, self._active = self._active, None
        return None if active is None else active.__exit__(exc_type, exc, tb)

    @contextmanager
    def _staged(self) -> Iterator[Path]:
        parent = _abs(self.out).parent
        remove_stale_staging(parent)
        with terminate_raises():
            tmp = _new_staging(parent)
            with write_errors(self.out, "; nothing was written"):
                try:
                    yield tmp
                    self._publish(tmp)
                except BaseException:
                    shutil.rmtree(tmp, ignore_errors=True)
                    raise

    def _publish(self, tmp: Path) -> None:
        """Publish ``tmp`` (without its ``STAGING_PROOF``) at ``out``, or at the next free name while
        concurrent runs take them first."""
        (tmp / STAGING_PROOF).unlink(missing_ok=True)
        for _ in range(_CLAIM_TRIES):
            try:
                publish_dir(tmp, self.out, overwrite=self.overwrite)
                return
            except _NameTaken:
                self.out = resolve_output_dir(self.base, overwrite=self.overwrite)
        raise OutputError(f"{self.base}: every free name beside it was taken meanwhile; nothing was written")


def staging_dir(out: Path, *, overwrite: bool = False, base: Path | None = None) -> Staging:
    """``with staging_dir(out) as tmp:`` writes into ``tmp`` what appears as ``out`` when the block completes
    (a ``Staging``: its ``out`` says where it went when a concurrent run took the name; ``base`` is the
    name the next free ``base-2``, ``base-3``, ... derive from, default ``out``)."""
    return Staging(out, overwrite=overwrite, base=base)

"""Batch inputs: what one batch row runs (a :class:`Job`) and how command-line paths expand into jobs.

A path names a log (CARMEN ``.clf``/``.log``/``.carmen``, plain or ``.gz``/``.bz2``; ROS1 ``.bag``; ``.mcap``;
a ROS2 bag folder, i.e. a folder holding ``metadata.yaml``), a closed-loop scenario file (``.yaml``/``.yml``),
or a folder searched recursively for logs (only logs: scenario files are named one by one, or shipped
scenarios by name). A scenario runs once per seed: one job ``<scenario>-s<seed>`` each, all of one
``group`` (the scenario) so the report can aggregate over seeds.
"""

from __future__ import annotations

import difflib
import re
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

from .. import fsutil
from ..errors import ConfigError
from ..io import LOG_SUFFIXES, log_stem, log_suffix
from ..io.base import special_file_kind

__all__ = [
    "MAX_SEEDS",
    "RESERVED_NAMES",
    "SCENARIO_SUFFIXES",
    "Job",
    "JobKind",
    "expand_inputs",
    "find_logs",
    "input_stem",
    "is_log",
    "is_scenario_file",
    "parse_seeds",
    "safe_name",
    "shipped_names",
    "special_file_kind",
    "special_files",
    "unique_names",
]

JobKind = Literal["log", "scenario"]

#: Suffixes of scenario files (closed-loop runs, ``gndreplay.sim.scenario_file``).
SCENARIO_SUFFIXES: tuple[str, ...] = (".yaml", ".yml")
_UNSAFE = re.compile(r"[^A-Za-z0-9._+-]+")
#: Names of the batch folder's own files, never given to an input's run directory.
RESERVED_NAMES: tuple[str, ...] = ("summary.csv", "summary.md", "scenarios.csv", "junit.xml", "batch.json")
#: Most seeds one ``--seeds`` may expand to (a typo like ``1-100000`` is refused, not queued).
MAX_SEEDS = 10_000
_SEED_RANGE = re.compile(r"([0-9]{1,18})(?:-([0-9]{1,18}))?")


@dataclass(frozen=True, slots=True)
class Job:
    """One batch input.

    Attributes:
        name: unique in the batch; names the run directory, the summary row and the JUnit test case.
        path: the log file or ROS2 bag folder; for a scenario its file (a shipped one's packaged file).
        kind: "log" (replayed with ``run_log``) or "scenario" (run in closed loop with ``simulate_scenario``).
        relations: SLAM-benchmark relations file to score the corrected trajectory against, or None (logs).
        goal_xy: fixed goal [m] in the corrected odometry frame instead of the run options' goal (logs).
        seed: a scenario's seed (laser noise, odometry errors).
        group: a scenario's name in the batch (its rows are aggregated over seeds under it); "" for a log.
        scenario: a shipped scenario's name ("" for a scenario file: ``path`` is read).
    """

    name: str
    path: Path
    kind: JobKind = "log"
    relations: Path | None = None
    goal_xy: tuple[float, float] | None = None
    seed: int = 0
    group: str = ""
    scenario: str = ""


def is_scenario_file(path: Path) -> bool:
    """True for a path with a scenario suffix (``.yaml``/``.yml``) that is not a folder (a ROS2 bag folder's
    metadata.yaml is only ever found inside a bag folder, which is taken as a whole)."""
    return path.suffix.lower() in SCENARIO_SUFFIXES and not path.is_dir()


def _is_ros2_bag(path: Path) -> bool:
    return path.is_dir() and (path / "metadata.yaml").is_file()


def is_log(path: Path) -> bool:
    """True for a file with a log suffix (``gndreplay.io.LOG_SUFFIXES``) or a ROS2 bag folder (what a folder
    search picks up)."""
    return _is_ros2_bag(path) or (path.is_file() and log_suffix(path) is not None)


def find_logs(folder: Path) -> list[Path]:
    """Logs inside ``folder``, recursively, in sorted path order.

    Hidden entries (``.name``) and gndreplay's own output folders (run directories, batch folders: their
    results.mcap is not a log) are skipped; a ROS2 bag folder is one log (its files are not searched).
    """
    found: list[Path] = []
    for entry in sorted(folder.iterdir()):
        if entry.name.startswith(".") or fsutil.is_output_dir(entry):
            continue
        if is_log(entry):
            found.append(entry)
        elif entry.is_dir():
            found.extend(find_logs(entry))
    return found


def safe_name(name: str) -> str:
    """``name`` usable as a run-directory name: characters outside ``[A-Za-z0-9._+-]`` become ``_``, then
    ``fsutil.safe_name`` (never hidden, ``.`` or ``..``); ``"input"`` if nothing is left."""
    return fsutil.safe_name(_UNSAFE.sub("_", name), "input")


def input_stem(path: Path) -> str:
    """A log or scenario file name without its suffix (``mit-csail.clf.bz2`` -> ``mit-csail``,
    ``u_trap.yaml`` -> ``u_trap``; a bag folder: its name), made safe for a folder name
    (``.hidden.clf`` -> ``hidden``)."""
    name = path.name if path.is_dir() else (path.stem if is_scenario_file(path) else log_stem(path.name))
    return safe_name(name)


def unique_names(paths: Sequence[Path]) -> list[str]:
    """One name per path, unique in the list: the stem, qualified by the parent folder where stems collide,
    then numbered (``-2``, ``-3``) if still equal."""
    stems = [input_stem(p) for p in paths]
    counts = Counter(stems)
    wanted = [
        safe_name(f"{p.parent.name}-{s}") if counts[s] > 1 and p.parent.name else s
        for p, s in zip(paths, stems, strict=True)
    ]
    return numbered(wanted, RESERVED_NAMES)


def numbered(names: Sequence[str], reserved: Iterable[str] = ()) -> list[str]:
    """``names`` made unique, and distinct from ``reserved``, by numbering repeats (``-2``, ``-3``)."""
    used: set[str] = set(reserved)
    out: list[str] = []
    for name in names:
        candidate, k = name, 1
        while candidate in used:
            k += 1
            candidate = f"{name}-{k}"
        used.add(candidate)
        out.append(candidate)
    return out


def special_files(path: Path) -> list[str]:
    """``"<path> (a FIFO)"`` for ``path`` if it is a FIFO, device or socket, or for each such file
    directly inside it when it is a folder (a ROS2 bag folder's storage files); never opens any of them."""
    kind = special_file_kind(path)
    if kind is not None:
        return [f"{path} ({kind})"]
    if not path.is_dir():
        return []
    try:
        entries = sorted(path.iterdir())
    except OSError:
        return []
    return [f"{e} ({k})" for e in entries if (k := special_file_kind(e)) is not None]


def parse_seeds(text: str) -> tuple[int, ...]:
    """Seeds from ``"1-20"``, ``"1,3,5"`` or a mix (``"0-4,10"``), in the order given.

    Raises:
        ConfigError: not non-negative integers and ascending ranges, a seed given twice, or more than
            ``MAX_SEEDS`` seeds.
    """
    seeds: list[int] = []
    for part in text.split(","):
        m = _SEED_RANGE.fullmatch(part.strip())
        if m is None:
            raise ConfigError(
                f"seeds: {part.strip()!r} in {text!r} is not a seed or a range "
                "(expected non-negative integers like 1-20, 1,3,5 or 0-4,10)"
            )
        lo = int(m.group(1))
        hi = lo if m.group(2) is None else int(m.group(2))
        if hi < lo:
            raise ConfigError(f"seeds: range {part.strip()!r} in {text!r} goes down (write {hi}-{lo})")
        if len(seeds) + hi - lo + 1 > MAX_SEEDS:
            raise ConfigError(f"seeds: {text!r} gives more than {MAX_SEEDS} seeds")
        seeds.extend(range(lo, hi + 1))
    repeated = sorted(s for s, n in Counter(seeds).items() if n > 1)
    if repeated:
        raise ConfigError(f"seeds: {text!r} gives seed {repeated[0]} more than once")
    return tuple(seeds)


def shipped_names(requested: Iterable[str]) -> dict[str, Path]:
    """Shipped scenario name -> its packaged file for names given as ``"all"``, ``"a,b"`` or one each
    (in the order given, each once).

    Raises:
        ConfigError: an unknown name (the shipped ones are listed) or nothing requested.
    """
    from importlib import resources

    from ..sim.scenario_file import shipped_scenarios

    known = list(shipped_scenarios())
    wanted: list[str] = []
    for item in requested:
        for name in (n.strip() for n in item.split(",")):
            if not name:
                continue
            if name == "all":
                wanted.extend(known)
            elif name in known:
                wanted.append(name)
            else:
                close = difflib.get_close_matches(name, known, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise ConfigError(
                    f"scenarios: no shipped scenario {name!r}{hint}; shipped: all, {', '.join(known)} "
                    "(give a scenario file as an input)"
                )
    if not wanted:
        raise ConfigError("scenarios: no scenario named (give all or names, e.g. u_trap,enclosed)")
    folder = resources.files("gndreplay.sim").joinpath("scenarios")
    return {n: Path(str(folder.joinpath(f"{n}.yaml"))) for n in dict.fromkeys(wanted)}


def _expand_one(path: Path) -> list[Path]:
    if path.is_dir() and not _is_ros2_bag(path):
        logs = find_logs(path)
        if not logs:
            raise ConfigError(
                f"{path}: no logs in this folder (looked for {', '.join(LOG_SUFFIXES)}, "
                "compressed .gz/.bz2 text logs and ROS2 bag folders; scenario files are given one by one)"
            )
        return logs
    return [path]  # a file, a bag folder, or a missing path (reported as that input's error)


def expand_inputs(
    inputs: Iterable[str | Path],
    *,
    scenarios: Sequence[str] = (),
    seeds: Sequence[int] | None = None,
) -> list[Job]:
    """Jobs for command-line inputs, in the order given (folders expanded in sorted order), then the
    shipped ``scenarios`` (names or ``"all"``, see ``shipped_names``).

    A file is taken as given whatever its suffix (a file that cannot be read becomes that input's error);
    a ``.yaml``/``.yml`` file is a scenario. Each scenario becomes one job per seed (``seeds``; default 0)
    named ``<scenario>-s<seed>``; a scenario file that does not parse becomes one job named ``<scenario>``
    whose run reports the error (naming the file and the key). A path given twice (also through a folder)
    runs once. Names are safe folder names (see ``safe_name``), unique in the batch. Only scenario files
    are read here (FIFOs, devices and sockets are never opened: ``make_tasks`` refuses them).

    Raises:
        ConfigError: no inputs, a folder without any log in it, an unknown shipped scenario, or seeds
            given without any scenario.
    """
    paths: list[Path] = []
    shipped: dict[Path, str] = {}
    seen: set[Path] = set()

    def add(path: Path) -> None:
        key = path.resolve()
        if key not in seen:
            seen.add(key)
            paths.append(path)

    for raw in inputs:
        for path in _expand_one(Path(raw)):
            add(path)
    if scenarios:
        for name, path in shipped_names(scenarios).items():
            shipped.setdefault(path.resolve(), name)
            add(path)
    if not paths:
        raise ConfigError("no inputs: give log files, folders of logs, scenario files or shipped scenarios")
    is_scenario = [is_scenario_file(p) for p in paths]
    if seeds is not None and not any(is_scenario):
        raise ConfigError("seeds apply to scenarios, and no scenario file or shipped scenario was given")
    seeds = (0,) if seeds is None else tuple(seeds)
    if not seeds:
        raise ConfigError("seeds: none given")
    jobs: list[Job] = []
    for name, path, scenario in zip(unique_names(paths), paths, is_scenario, strict=True):
        if not scenario:
            jobs.append(Job(name=name, path=path))
        elif path.resolve() not in shipped and not _readable_scenario(path):
            # one run, named after the scenario, reports the file's error (not one per seed)
            jobs.append(Job(name=name, path=path, kind="scenario", seed=seeds[0], group=name))
        else:
            jobs += [
                Job(name=f"{name}-s{seed}", path=path, kind="scenario", seed=seed, group=name,
                    scenario=shipped.get(path.resolve(), ""))
                for seed in seeds
            ]
    return _distinct(jobs)


def _readable_scenario(path: Path) -> bool:
    """False for a missing scenario file or a regular one that does not parse (its runs would all fail
    alike); True otherwise, also for a FIFO or device, which is never opened here (``make_tasks`` names
    it)."""
    from ..sim.scenario_file import load_scenario

    if not path.exists():
        return False
    if not path.is_file() or special_file_kind(path) is not None:
        return True
    try:
        load_scenario(path)
    except ConfigError:
        return False
    return True


def _distinct(jobs: list[Job]) -> list[Job]:
    """``jobs`` with names made unique by numbering (``-2``, ...) where a log's name equals a scenario
    run's (``u_trap-s1.clf`` beside ``u_trap.yaml``); groups are kept."""
    used: set[str] = set(RESERVED_NAMES)
    out: list[Job] = []
    for job in jobs:
        candidate, k = job.name, 1
        while candidate in used:
            k += 1
            candidate = f"{job.name}-{k}"
        used.add(candidate)
        out.append(job if candidate == job.name else replace(job, name=candidate))
    return out

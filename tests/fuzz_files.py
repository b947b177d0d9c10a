"""Seeded mutations of the user's other files: scenario YAML, config TOML, thresholds TOML and run folders.

Shared by ``tests/test_fuzz.py`` and ``benchmarks/fuzz.py`` beside the log mutators of ``fuzzing.py`` (same
``Seed`` / ``Outcome`` and the same classification, time bound and memory measurement). An input is a valid
file with 1-3 mutations: a value replaced by a hostile one (a 401-digit integer, 1e300, nan, a string, an
alias bomb, brackets nested 5,000 deep), a key removed or duplicated, bytes flipped or cut, invalid UTF-8,
and the file itself replaced by a FIFO, a link to /dev/zero, a folder or a file past its size bound. A run
folder gets the same per file, and links planted where ``gndreplay report`` writes (its marker, a figure,
report.md) that point into a *decoy tree* outside it: the caller hashes that tree before and after.

What each kind is put through, as the CLI does: a scenario is parsed, its closed loop built and stepped a few
ticks; a config or thresholds file is loaded; a run folder is loaded as ``report`` loads it, and redrawn
(``build_report``) when the mutation plants a link or touches the marker, and for one input in ten.
"""

from __future__ import annotations

import dataclasses
import hashlib
import random
import re
from collections.abc import Callable
from importlib import resources
from pathlib import Path

from fuzzing import Seed, _bytes_mutation

__all__ = ["FILE_FORMATS", "FileSeeds", "decoy_digest", "make_decoy", "make_file_input", "read_file_input"]

FILE_FORMATS = ("scenario", "config", "thresholds", "rundir")
RUN = "fuzzrun"  # the run folder's name: the one-line error must name it
DECOY = "@DECOY@"  # a link target under the decoy tree (``fuzzing.run_input`` substitutes the path)

HOSTILE = (
    "9" * 401, "-" + "9" * 401, "1e300", "-1e300", "nan", "inf", "-inf", "-1", "0", "'text'", "true", "[]",
    "{}", "4294967296", "1e-320", "null",
)  # fmt: skip
TOML_HOSTILE = (*HOSTILE[:7], '"text"', "true", "[]", "{}", "[" * 5000 + "]" * 5000, "-1", "0",
                "1979-05-27T07:32:00Z", '"' + "x" * 100_000 + '"')


def _alias_bomb(depth: int = 9) -> str:
    """A YAML flow value whose aliases expand to 10^depth elements ("billion laughs")."""
    parts = ["&a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    parts += [f"&a{i} [{', '.join([f'*a{i - 1}'] * 10)}]" for i in range(1, depth)]
    return "[" + ", ".join(parts) + "]"


YAML_HOSTILE = (*HOSTILE, "[" * 5000 + "]" * 5000, _alias_bomb(), "*undefined", "!!python/object:os.system x",
                "&x [*x]", "!!binary AAAA", "~")


@dataclasses.dataclass(frozen=True)
class FileSeeds:
    """Valid files of every kind: the shipped scenarios, the presets' configs, a thresholds file, and a
    run folder written by a short replay of the sample log."""

    scenarios: tuple[bytes, ...]
    configs: tuple[bytes, ...]
    thresholds: tuple[bytes, ...]
    run: dict[str, bytes]

    @staticmethod
    def make(work: Path) -> FileSeeds:
        from gndreplay.config import PRESETS, config_to_toml
        from gndreplay.replay import RunOptions, run_log
        from gndreplay.report import MapSink

        scenarios = tuple(f.read_bytes() for f in sorted(resources.files("gndreplay.sim").joinpath(
            "scenarios").iterdir(), key=lambda p: p.name) if f.name.endswith(".yaml"))
        configs = tuple(config_to_toml(cfg).encode() for cfg in PRESETS.values())
        configs += (b'preset = "wheelchair"\n[robot]\nvmax_mps = 0.25\n[planner]\nkind = "tunnel"\n',)
        thresholds = (
            b'[thresholds]\nreactor_p99_ms = 50.0\nemergency_stops = 0\nstack_max_ms = false\n'
            b'min_ticks = 10\n'
            b'[inputs."u_trap"]\nmin_success = false\ncollisions = 0\nmin_clearance_m = 0.05\n'
            b'min_success_rate = 0.8\n[inputs."mit*"]\ngoal = [12.0, -3.5]\nmatch_trans_err_mean_m = 0.15\n',
        )
        sample = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"
        out = run_log(sample, PRESETS["wheelchair"], work / RUN, options=RunOptions(until_s=6.0),
                      sinks=[MapSink()]).out_dir
        run = {f"{RUN}/{f.name}": f.read_bytes() for f in sorted(out.iterdir()) if f.is_file()}
        return FileSeeds(scenarios, configs, thresholds, run)


def _value_mutation(text: bytes, rng: random.Random, values: tuple[str, ...]) -> bytes:
    """A ``key: value`` / ``key = value`` line's value replaced, a key line removed or duplicated."""
    lines = text.split(b"\n")
    keyed = [i for i, ln in enumerate(lines) if re.match(rb"^\s*-?\s*[A-Za-z_][\w.\"-]*\s*[:=]", ln)]
    if not keyed:
        return _bytes_mutation(text, rng)
    i = rng.choice(keyed)
    op = rng.randrange(6)
    if op <= 3:
        sep = b"=" if b"=" in lines[i].split(b":")[0] else b":"
        key = lines[i].split(sep, 1)[0]
        lines[i] = key + sep + b" " + rng.choice(values).encode()
    elif op == 4:
        del lines[i]
    else:
        lines.insert(i, lines[i])
    return b"\n".join(lines)


def _text_mutation(text: bytes, rng: random.Random, values: tuple[str, ...]) -> bytes:
    r = rng.random()
    if r < 0.65:
        return _value_mutation(text, rng, values)
    if r < 0.75:  # invalid UTF-8
        pos = rng.randrange(len(text) + 1)
        return text[:pos] + rng.choice((b"\xff", b"\xc3\x28", b"\xed\xa0\x80")) + text[pos:]
    if r < 0.8:  # a file past any sensible size bound (comments: valid in both formats)
        return text + b"\n#" + b"x" * rng.choice((3 << 20, 9 << 20)) + b"\n"
    return _bytes_mutation(text, rng)


def _special(rng: random.Random) -> bytes | tuple[str, str]:
    """A FIFO, a link to /dev/zero or to a decoy file, or a folder, in place of a file."""
    return rng.choice((("fifo", ""), ("symlink", "/dev/zero"), ("symlink", f"{DECOY}/precious.txt"),
                       ("dir", "")))


def make_file_input(seeds: FileSeeds, fmt: str, index: int, master_seed: int = 12) -> Seed:
    """Input ``index`` of kind ``fmt`` (a pure function of the arguments)."""
    rng = random.Random(f"{master_seed}:{fmt}:{index}")
    if fmt == "rundir":
        return _run_input(seeds, rng)
    name, pool, values = {
        "scenario": ("scenario.yaml", seeds.scenarios, YAML_HOSTILE),
        "config": ("config.toml", seeds.configs, TOML_HOSTILE),
        "thresholds": ("thresholds.toml", seeds.thresholds, TOML_HOSTILE),
    }[fmt]
    if rng.random() < 0.05:
        return Seed({name: _special(rng)}, name)  # type: ignore[dict-item]
    text = rng.choice(pool)
    for _ in range(rng.randint(1, 3)):
        text = _text_mutation(text, rng, values)
    return Seed({name: text}, name)


def _run_input(seeds: FileSeeds, rng: random.Random) -> Seed:
    files: dict[str, bytes | tuple[str, str]] = dict(seeds.run)
    names = sorted(seeds.run)
    marker = f"{RUN}/.gndreplay"
    for _ in range(rng.randint(1, 3)):
        op = rng.randrange(10)
        target = rng.choice(names)
        if op <= 3:  # a file's bytes
            data = files[target]
            files[target] = _bytes_mutation(data, rng) if isinstance(data, bytes) else data
        elif op == 4:  # summary.json nested deep, or a huge integer in it
            files[f"{RUN}/summary.json"] = rng.choice((b"[" * 200_000 + b"]" * 200_000,
                                                      b'{"ticks": ' + b"9" * 5000 + b"}"))
        elif op == 5:  # a maps.npz member declaring a huge array
            files[f"{RUN}/maps.npz"] = _huge_npz(rng)
        elif op == 6:  # the marker: a link out of the folder, a folder, gone, or listing paths outside
            files[marker] = rng.choice((("symlink", f"{DECOY}/precious.txt"), ("dir", ""), None,
                                        b"../decoy/precious.txt\n/etc/passwd\n"))  # type: ignore[assignment]
        elif op == 7:  # a link where report writes
            out = rng.choice(("fig_model.png", "fig_commands.png", "report.md", "fig_modes.png"))
            files[f"{RUN}/{out}"] = ("symlink", f"{DECOY}/{rng.choice(('precious.txt', 'sub'))}")
        else:  # a file replaced by a FIFO, a link to /dev/zero or to the decoy, or a folder
            files[target] = _special(rng)
    return Seed({k: v for k, v in files.items() if v is not None}, RUN)  # type: ignore[misc]


def _huge_npz(rng: random.Random) -> bytes:
    """A small .npz whose one member's header declares a 60000 x 60000 (or negative, or odd) shape."""
    import io
    import zipfile

    shape = rng.choice(("(60000, 60000)", "(-1, 4)", "(3,)", "60000", "(2**40,)"))
    header = "{'descr': '<u2', 'fortran_order': False, 'shape': " + shape + ", }"
    header = header.ljust(118) + "\n"
    npy = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode() + b"\0" * 64
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr(rng.choice(("hits_corrected.npy", "grid.npy", "format.npy")), npy)
    return buf.getvalue()


def read_file_input(fmt: str, path: Path, redraw: bool) -> None:
    """Put one input through what the CLI does with a file of kind ``fmt`` (see the module docstring)."""
    readers: dict[str, Callable[[Path], None]] = {
        "scenario": _simulate_briefly, "config": _load_config, "thresholds": _load_thresholds,
    }
    if fmt == "rundir":
        from gndreplay.report import build_report, load_run

        load_run(path)
        if redraw:
            build_report(path)
        return
    readers[fmt](path)


def _simulate_briefly(path: Path) -> None:
    """Parse the scenario, build its closed loop and run 0.6 s of it through the stack."""
    from gndreplay.config import preset
    from gndreplay.replay import RunOptions, run_replay
    from gndreplay.sim.closedloop import ClosedLoop
    from gndreplay.sim.scenario_file import resolve_scenario

    spec = resolve_scenario(path)
    loop = ClosedLoop(spec, preset(spec.preset), seed=0)
    options = RunOptions(goal_xy=spec.goal, subgoals=spec.subgoals, until_s=0.6)
    run_replay(loop.ticks(), loop.cfg, path.parent / "sim", log=path, options=options, on_tick=loop.on_tick)
    loop.result()


def _load_config(path: Path) -> None:
    from gndreplay.config import load_config

    load_config(path)


def _load_thresholds(path: Path) -> None:
    from gndreplay.batch.thresholds import load_thresholds

    load_thresholds(path)


def make_decoy(folder: Path) -> Path:
    """A tree of files no input may change: the target of every planted link."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "precious.txt").write_text("the user's own file\n")
    (folder / "sub").mkdir(exist_ok=True)
    (folder / "sub" / "notes.md").write_text("# not gndreplay's\n")
    return folder


def decoy_digest(folder: Path) -> str:
    """A hash of every path, kind and content below ``folder``."""
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        h.update(str(p.relative_to(folder)).encode())
        h.update(b"d" if p.is_dir() else p.read_bytes())
    return h.hexdigest()

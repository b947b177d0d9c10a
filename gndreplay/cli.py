"""The ``gndreplay`` command line: parses options, calls one library function per command, prints.

Every command goes through :func:`cli_errors`, the single error boundary: a :class:`GndReplayError` becomes
one line ``gndreplay: error: <message>`` on stderr and exit code 2; Ctrl-C exits with 130. Anything else is a
bug and keeps its traceback. A bad command line (an unknown option, a value typer or a callback refuses) is
reported the same way by the command group (:class:`_Commands`). Every number an option gives is checked
against its physical range (``userfile.check_number``; the seed by ``sim.scenario.check_seed``), and a value
misspelt among fixed choices (matcher, preset, planner, mode) gets a "did you mean". Heavy imports happen
inside the commands so ``--help`` stays fast.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import inspect
import logging
import math
import re
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, NoReturn, ParamSpec, TextIO, TypeVar, cast

import typer
from rich.markup import escape
from typer.core import TyperCommand, TyperGroup

from . import __version__
from .errors import ConfigError, GndReplayError, find_cause, one_line

if TYPE_CHECKING:  # the CLI imports its heavy modules lazily, inside the commands, to start fast
    from rich.console import Console
    from rich.progress import Progress, TaskID

    from .config import CliOverrides, Config
    from .io import ReadOptions
    from .scanmatch import MatcherReport
    from .scanmatch.run import Method
    from .sim.runner import SimOutcome
    from .types import Subgoal

__all__ = ["app", "cli_errors", "main"]

P = ParamSpec("P")
R = TypeVar("R")

EXIT_ERROR = 2
EXIT_INTERRUPTED = 130
#: Suffixes of the files the commands read besides logs (``gndreplay.io.LOG_SUFFIXES``): an argument starting
#: with "-" and ending so is a file's name.
_OTHER_FILE_SUFFIXES = (".db3", ".yaml", ".yml", ".toml", ".txt", ".relations")
#: Longest command-line error message printed (click quotes the value given, which may be any length).
_MAX_MESSAGE = 400
#: The exceptions of the click typer parses with (its own copy in recent versions, not the click package).
_click = importlib.import_module(typer.BadParameter.__module__)
_NoArgsIsHelp = getattr(_click, "NoArgsIsHelpError", ())  # click >= 8.2: help for a bare command


class _Commands(TyperGroup):
    """The command group: a command line click or typer refuses (an unknown option, a missing argument, a
    bad value) or an option callback's :class:`GndReplayError` becomes one line on stderr and exit 2, as
    :func:`cli_errors` reports the commands' own errors."""

    def make_context(self, info_name: str | None, args: list[str], parent: Any = None, **extra: Any) -> Any:
        try:
            return super().make_context(info_name, args, parent=parent, **extra)
        except _NoArgsIsHelp:
            raise
        except (_click.ClickException, GndReplayError) as err:
            _command_line_error(err, args)

    def get_params(self, ctx: Any) -> list[Any]:
        return _untyped_flags(super().get_params(ctx))

    def invoke(self, ctx: Any) -> Any:
        # the command and its arguments, before it parses them (click's private field, as TyperGroup reads)
        args = [*getattr(ctx, "_protected_args", ()), *ctx.args]
        try:
            return super().invoke(ctx)
        except _NoArgsIsHelp:
            raise
        except (_click.ClickException, GndReplayError) as err:
            _command_line_error(err, args)


#: The rich markup a help text uses on purpose (``[bold]Examples[/]``); every other "[" is text.
_MARKUP = re.compile(r"\[(?:/?(?:bold|italic|dim)|/)\]")


def help_markup(text: str) -> str:
    """``text`` as rich markup that renders every character of it: each "[" not opening a tag of
    ``_MARKUP`` is escaped (rich would read ``[dask]`` as a style), and the lines of each paragraph that is
    not indented (prose, not an example) are joined for the terminal to wrap (typer keeps a docstring's line
    breaks)."""
    paragraphs = []
    for para in inspect.cleandoc(text).split("\n\n"):
        lines = para.split("\n")
        paragraphs.append(para if any(line.startswith(" ") for line in lines) else " ".join(lines))
    joined = "\n\n".join(paragraphs)
    tags = _MARKUP.findall(joined)
    texts = [escape(t) for t in _MARKUP.split(joined)]
    return "".join(t + tag for t, tag in zip(texts, [*tags, ""], strict=True))


class _Command(TyperCommand):
    """A command whose help shows every character of its docstring and option help texts
    (:func:`help_markup`), and a flag without a ``<bool>`` type."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.help = help_markup(self.help) if self.help else self.help
        for param in self.params:
            if isinstance(help_text := getattr(param, "help", None), str):
                param.help = help_markup(help_text)  # type: ignore[attr-defined]

    def get_params(self, ctx: Any) -> list[Any]:
        return _untyped_flags(super().get_params(ctx))


def _untyped_flags(params: list[Any]) -> list[Any]:
    """``params`` with no type shown for a flag (it takes no value: no "<bool>" in the help)."""
    for param in params:
        if getattr(param, "is_flag", False):
            param.metavar = ""
    return params


def _command_line_error(err: Exception, args: Sequence[str]) -> NoReturn:
    """Print a refused command line as one ``gndreplay: error:`` line and exit 2."""
    typer.echo(f"gndreplay: error: {_command_line_message(err, args)}", err=True)
    raise typer.Exit(EXIT_ERROR)


def _command_line_message(err: Exception, args: Sequence[str]) -> str:
    """The message of a refused command line in one line of at most ``_MAX_MESSAGE`` characters; an
    unknown option that is a file's name starting with "-" says how to give it."""
    if isinstance(err, _click.NoSuchOption) and (name := _dash_file(err.option_name, args)) is not None:
        return (
            f"{name}: a name starting with '-' reads as an option; write ./{name} to give that file "
            f"(or put -- before it)"
        )
    text = one_line(err.format_message() if isinstance(err, _click.ClickException) else err)
    ctx = getattr(err, "ctx", None)
    if isinstance(err, _click.UsageError) and not isinstance(err, _click.BadParameter) and ctx is not None:
        command = " ".join(["gndreplay", *ctx.command_path.split()[1:]])  # not a value: the usage is wrong
        text = f"{text.rstrip('.')} (see {command} --help)"
    return one_line(text, _MAX_MESSAGE)


def _dash_file(option: str, args: Sequence[str]) -> str | None:
    """The argument an unknown ``option`` was read from when it names a file: it starts with "-", holds the
    option's letters and exists or ends like the files gndreplay reads (``-dash.clf``)."""
    from .io import COMPRESSED_SUFFIXES, LOG_SUFFIXES

    suffixes = (*LOG_SUFFIXES, *COMPRESSED_SUFFIXES, *_OTHER_FILE_SUFFIXES)
    for a in args:
        if not (a.startswith("-") and option.lstrip("-") in a):
            continue
        if Path(a).suffix.lower() in suffixes or _exists(a):
            return a
    return None


def _exists(name: str) -> bool:
    try:
        return Path(name).exists()
    except (OSError, ValueError):  # a name too long for the system, a NUL byte
        return False


def _bounded(option: str, lo: float, hi: float) -> Callable[[Any], Any]:
    """A typer callback passing an option's number through ``userfile.check_number`` within [lo, hi] (None,
    the option not given, passes)."""

    def check(value: Any) -> Any:
        if value is not None:
            from .io.userfile import check_number

            check_number(value, option, lo, hi)
        return value

    return check


def _seed(value: int) -> int:
    """``--seed``: an integer numpy's SeedSequence takes (``sim.scenario.check_seed``)."""
    from .sim.scenario import check_seed

    return check_seed(value, "--seed")


#: Bounds of the options' numbers, equal to the library's (not imported: the modules holding them are slow
#: to import, and --help stays fast): |x|, |y| of --goal and --goal-ahead [m] (io.subgoals.MAX_ABS_SUBGOAL_M,
#: the readers' bound on positions); --until, --timeout [s] (io.base.MAX_ABS_TIME_NS, the readers' bound on
#: time stamps); --time-limit [s] (sim.scenario_file.MAX_TIME_S); --every; --jobs.
_MAX_POSITION_M = 1e6
_MAX_SECONDS = 4.5e9
_MAX_SCENARIO_TIME_S = 1e6
_MAX_EVERY = 1_000_000
_MAX_JOBS = 4096
_MAX_SNAPSHOTS = 100_000
#: ``--progress`` values, and the seconds between two plain progress lines while the total is unknown.
_PROGRESS_STYLES = ("auto", "plain", "none")
#: ``--mcap-grid`` values: results.mcap's robot-centred grid on every tick, or when it changed.
_MCAP_GRID = ("every", "change")
_PLAIN_EVERY_S = 10.0

app = typer.Typer(
    cls=_Commands,
    add_completion=False,
    rich_markup_mode="rich",
    no_args_is_help=True,
    help="Replay real robot logs (2D laser + odometry) through a GND / ND+ navigation stack.",
)

_LOG_PANEL = "Log reading"
_CONFIG_PANEL = "Configuration"
_MODE_PANEL = "Navigation mode (multi-loop)"
_RUN_PANEL = "Run"
_SIM_PANEL = "Scenarios"
_BASELINE_PANEL = "Baseline and sweeps"
_SNAPSHOT_PANEL = "Snapshots"


def cli_errors(fn: Callable[P, R]) -> Callable[P, R]:
    """Decorator for commands: project errors -> one stderr line + exit 2; Ctrl-C -> exit 130.

    While the command runs, library warnings (``logging``, logger "gndreplay") go to stderr as
    ``gndreplay: warning: ...``.
    """

    @functools.wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        logger = logging.getLogger("gndreplay")
        handler = _StderrHandler(level=logging.WARNING)
        logger.addHandler(handler)
        shown = warnings.showwarning
        warnings.showwarning = _show_warning
        try:
            return fn(*args, **kwargs)
        except GndReplayError as err:
            message = one_line(err) or type(err).__name__
            typer.echo(f"gndreplay: error: {message}", err=True)
            raise typer.Exit(EXIT_ERROR) from None
        except KeyboardInterrupt:
            typer.echo("gndreplay: interrupted", err=True)
            raise typer.Exit(EXIT_INTERRUPTED) from None
        except SystemError as err:
            cause = _interruption(err)
            if isinstance(cause, KeyboardInterrupt):
                typer.echo("gndreplay: interrupted", err=True)
                raise typer.Exit(EXIT_INTERRUPTED) from None
            if isinstance(cause, SystemExit):
                raise typer.Exit(cause.code if isinstance(cause.code, int) else 1) from None
            raise
        finally:
            logger.removeHandler(handler)
            warnings.showwarning = shown

    return wrapper


def _interruption(err: BaseException) -> BaseException | None:
    """The KeyboardInterrupt or SystemExit (SIGTERM, see ``fsutil.terminate_raises``) behind ``err``, if any.

    Ctrl-C or SIGTERM arriving inside a numba kernel call surfaces as a SystemError "returned a result with an
    exception set", often several deep (a kernel called from a kernel's dispatch): follow the chain."""
    return find_cause(err, lambda e: isinstance(e, KeyboardInterrupt | SystemExit))


def _show_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: TextIO | None = None,
    line: str | None = None,
) -> None:
    """A Python warning (e.g. numpy's RuntimeWarning) as one line, without the source line it came from."""
    where = f"{Path(filename).name}:{lineno}"
    typer.echo(f"gndreplay: warning: {category.__name__}: {message} ({where})", err=True)


class _StderrHandler(logging.Handler):
    """Library warnings -> ``gndreplay: warning: ...`` on the current stderr."""

    def emit(self, record: logging.LogRecord) -> None:
        typer.echo(f"gndreplay: {record.levelname.lower()}: {record.getMessage()}", err=True)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"gndreplay {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Show the version and exit.")
    ] = False,
) -> None:
    """Replay real robot logs (2D laser + odometry) through a GND / ND+ navigation stack."""


# --------------------------------------------------------------------------------------------------
# Options: each declared once, shared by the commands that take it

FormatOpt = Annotated[
    str | None,
    typer.Option(
        "--format",
        help="Log format instead of guessing from the path: carmen, rosbag1, rosbag2, mcap, rosbag.",
        rich_help_panel=_LOG_PANEL,
        show_default=False,
    ),
]
ScanTopicOpt = Annotated[
    str | None,
    typer.Option(
        "--scan-topic",
        help="LaserScan topic (ROS) or laser message (CARMEN: FLASER, RLASER, ROBOTLASER1, ...).",
        rich_help_panel=_LOG_PANEL,
        show_default=False,
    ),
]
OdomTopicOpt = Annotated[
    str | None,
    typer.Option(
        "--odom-topic",
        help="Odometry topic, [bold]/tf[/] for odom->base transforms (ROS), or ODOM / FLASER (CARMEN).",
        rich_help_panel=_LOG_PANEL,
        show_default=False,
    ),
]
CmdTopicOpt = Annotated[
    str | None,
    typer.Option(
        "--cmd-topic",
        help="Recorded velocity commands (Twist / TwistStamped topic).",
        rich_help_panel=_LOG_PANEL,
        show_default=False,
    ),
]
TruthTopicOpt = Annotated[
    str | None,
    typer.Option(
        "--truth-topic",
        help="Ground-truth pose topic (ROS) or TRUEPOS (CARMEN).",
        rich_help_panel=_LOG_PANEL,
        show_default=False,
    ),
]
StrictOpt = Annotated[
    bool,
    typer.Option(
        "--strict",
        help="A malformed line or message is an error (instead of skipped and counted).",
        rich_help_panel=_LOG_PANEL,
    ),
]
PresetOpt = Annotated[
    str | None,
    typer.Option(
        "--preset",
        help="Robot and stack preset: wheelchair (default), xr4000 or compact; a scenario has its own.",
        rich_help_panel=_CONFIG_PANEL,
        show_default=False,
    ),
]
ConfigOpt = Annotated[
    Path | None,
    typer.Option(
        "--config",
        help="TOML file overriding any key of the preset.",
        rich_help_panel=_CONFIG_PANEL,
        show_default=False,
    ),
]
SetOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--set",
        help="Override one configuration key, section.key=value (repeatable; applied last), e.g. "
        "--set reactor.security_m=0.4.",
        rich_help_panel=_CONFIG_PANEL,
        show_default=False,
    ),
]
ToleranceOpt = Annotated[
    Path | None,
    typer.Option(
        "--tolerance",
        help="TOML [tolerance] table of absolute tolerances (default: exact).",
        show_default=False,
    ),
]
PlannerOpt = Annotated[
    str | None,
    typer.Option(
        "--planner",
        help="Global planner: nf1 (GND) or tunnel (the wheelchair paper); default: the config's, nf1.",
        rich_help_panel=_CONFIG_PANEL,
        show_default=False,
    ),
]
ModeOpt = Annotated[
    str | None,
    typer.Option(
        "--mode",
        help="Desired navigation mode: gnd (GND to the goal), teleop (the recorded velocity commands), "
        "follow (path following of --subgoals) or local (local navigation alone). Default: the config's "
        "[navigation] mode, gnd.",
        rich_help_panel=_MODE_PANEL,
        show_default=False,
    ),
]
LocalOpt = Annotated[
    str | None,
    typer.Option(
        "--local",
        help="Local navigation strategy: nd (ND+, the default), free-space, wall-left, wall-right, contour.",
        rich_help_panel=_MODE_PANEL,
        show_default=False,
    ),
]
SubgoalsOpt = Annotated[
    Path | None,
    typer.Option(
        "--subgoals",
        help="Subgoals for --mode follow: one 'x y theta [stop|forward|reverse]' per line, in the "
        "corrected odometry frame.",
        rich_help_panel=_MODE_PANEL,
        show_default=False,
    ),
]
NoSelectorOpt = Annotated[
    bool,
    typer.Option(
        "--no-selector",
        help="Disable the mode selector: the desired mode's command goes out unchanged (no takeover, no "
        "reflexive override).",
        rich_help_panel=_MODE_PANEL,
    ),
]
GoalAheadOpt = Annotated[
    float | None,
    typer.Option(
        "--goal-ahead",
        callback=_bounded("--goal-ahead", 0.1, _MAX_POSITION_M),
        help="Goal = the pose this many metres further along the log's corrected trajectory (default 5).",
        rich_help_panel=_RUN_PANEL,
        show_default=False,
    ),
]
UntilOpt = Annotated[
    float | None,
    typer.Option(
        "--until",
        callback=_bounded("--until", 0.0, _MAX_SECONDS),
        help="Replay only the first T seconds of log time.",
        rich_help_panel=_RUN_PANEL,
        show_default=False,
    ),
]
EveryOpt = Annotated[
    int,
    typer.Option(
        "--every",
        callback=_bounded("--every", 1, _MAX_EVERY),
        help="Run the stack on every N-th scan.",
        rich_help_panel=_RUN_PANEL,
    ),
]
FiguresOpt = Annotated[
    bool,
    typer.Option(
        "--figures/--no-figures", help="Draw the figures (and report.md).", rich_help_panel=_RUN_PANEL
    ),
]
OverwriteOpt = Annotated[
    bool,
    typer.Option(
        "--overwrite",
        help="Replace an earlier gndreplay output at --out (never a folder gndreplay did not write).",
        rich_help_panel=_RUN_PANEL,
    ),
]
MatchAheadOpt = Annotated[
    bool | None,
    typer.Option(
        "--match-ahead/--no-match-ahead",
        help="Scan matching in a second process, ahead of the stack: the same results, sooner "
        "(default: when two CPUs are available).",
        rich_help_panel=_RUN_PANEL,
        show_default=False,
    ),
]
QuietOpt = Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar or table.")]
ProgressOpt = Annotated[
    str,
    typer.Option(
        "--progress",
        help="Progress on stderr: auto (a bar on a terminal, else a line every 10 %), plain or none.",
        rich_help_panel=_RUN_PANEL,
    ),
]
JsonOpt = Annotated[
    bool, typer.Option("--json", help="Print the result as JSON on stdout instead of tables.")
]
FromOpt = Annotated[
    float | None,
    typer.Option(
        "--from",
        callback=_bounded("--from", 0.0, _MAX_SECONDS),
        help="Draw the time-series figures from T seconds into the run (log time since its first tick).",
        rich_help_panel=_RUN_PANEL,
        show_default=False,
    ),
]
ToOpt = Annotated[
    float | None,
    typer.Option(
        "--to",
        callback=_bounded("--to", 0.0, _MAX_SECONDS),
        help="Draw the time-series figures up to T seconds into the run.",
        rich_help_panel=_RUN_PANEL,
        show_default=False,
    ),
]
SnapshotsOpt = Annotated[
    bool | None,
    typer.Option(
        "--snapshots/--no-snapshots",
        help="Draw a figure of each key event into snapshots/ (default: with the figures).",
        rich_help_panel=_SNAPSHOT_PANEL,
        show_default=False,
    ),
]
SnapshotEveryOpt = Annotated[
    float,
    typer.Option(
        "--snapshot-every",
        callback=_bounded("--snapshot-every", 0.0, _MAX_SECONDS),
        help="At most one snapshot of each kind of event per this many seconds of log time.",
        rich_help_panel=_SNAPSHOT_PANEL,
    ),
]
SnapshotMaxOpt = Annotated[
    int,
    typer.Option(
        "--snapshot-max",
        callback=_bounded("--snapshot-max", 0, _MAX_SNAPSHOTS),
        help="At most this many snapshots per run.",
        rich_help_panel=_SNAPSHOT_PANEL,
    ),
]
McapOpt = Annotated[
    bool,
    typer.Option(
        "--mcap",
        help="Also write results.mcap (ROS 2: scan, odometry, grids, the decision; opens in Foxglove with "
        "results.foxglove.json).",
        rich_help_panel=_RUN_PANEL,
    ),
]
McapGridOpt = Annotated[
    str,
    typer.Option(
        "--mcap-grid",
        help="results.mcap's robot-centred grid: on every tick, or when it changed.",
        rich_help_panel=_RUN_PANEL,
    ),
]
LatencyOpt = Annotated[
    str,
    typer.Option(
        "--latency",
        help="Seconds from a scan to its command taking effect (default 0), or 'measured' (not "
        "deterministic).",
        rich_help_panel=_SIM_PANEL,
        show_default=False,
    ),
]
PerfectOdometryOpt = Annotated[
    bool,
    typer.Option(
        "--perfect-odometry",
        help="No odometry drift (scan matching still runs).",
        rich_help_panel=_SIM_PANEL,
    ),
]
IdealDynamicsOpt = Annotated[
    bool,
    typer.Option(
        "--ideal-dynamics",
        help="The exact motion model: no drive lag, no slip.",
        rich_help_panel=_SIM_PANEL,
    ),
]
TimeLimitOpt = Annotated[
    float | None,
    typer.Option(
        "--time-limit",
        callback=_bounded("--time-limit", 0.1, _MAX_SCENARIO_TIME_S),
        help="Override each scenario's time limit (s, 0.1 to 1e6).",
        rich_help_panel=_SIM_PANEL,
        show_default=False,
    ),
]
AgainstOpt = Annotated[
    Path | None,
    typer.Option(
        "--against",
        help="Another container of the same recording (e.g. the bag converted from a CARMEN log): list what "
        "a replay reads differently in it. Read with its format and topics detected (the log options apply "
        "to LOG; --strict to both).",
        show_default=False,
    ),
]
LogArg = Annotated[
    Path,
    typer.Argument(
        help="CARMEN log (.clf/.log, plain/.gz/.bz2), ROS1 .bag, ROS2 bag folder or .mcap file.",
        show_default=False,
    ),
]


@dataclass(frozen=True, slots=True)
class Setup:
    """The configuration a command line asks for: the preset, the ``--config`` file, the overrides (named
    options and ``--set``) and the subgoals file's content."""

    path: Path | None
    preset: str | None
    overrides: CliOverrides
    subgoals: tuple[Subgoal, ...] = ()

    def config(self, **more: Any) -> Config:
        """The resolved configuration, with ``more`` overrides (``CliOverrides`` fields) on top."""
        from .config import configure

        return configure(
            self.path, preset_name=self.preset, overrides=dataclasses.replace(self.overrides, **more)
        )


def _read_options(**given: Any) -> ReadOptions:
    """The log-reading options (``_LOG_OPTIONS``, named as ``io.ReadOptions``' fields) as one value."""
    from .io import ReadOptions

    return ReadOptions(**given)


def _setup(preset_name: str | None, config: Path | None, sets: list[str] | None, planner: str | None = None,
           mode: str | None = None, local: str | None = None, subgoals: Path | None = None,
           no_selector: bool = False) -> Setup:
    """The configuration options as one value; an unknown preset and a bad subgoals file are refused here,
    before any log is read."""
    from .config import PRESETS, CliOverrides, choose

    choose("--preset", preset_name, sorted(PRESETS))
    overrides = CliOverrides(
        planner=planner, mode=mode, local=local, no_selector=no_selector, sets=tuple(sets or ())
    )
    return Setup(config, preset_name, overrides, _load_subgoals(subgoals))


def _resolved(annotation: Any, namespace: dict[str, Any]) -> Any:
    """A parameter's annotation evaluated as typer needs it (the module's annotations are strings); a name
    imported for type checking only stays a string: it is the value of another option group, which that
    group's decorator removes from the signature."""
    if not isinstance(annotation, str):
        return annotation
    try:
        return eval(annotation, namespace)
    except NameError:
        return annotation


def _option_group(
    into: str, options: dict[str, tuple[Any, Any]], build: Callable[..., Any]
) -> Callable[[Callable[..., R]], Callable[..., R]]:
    """A decorator giving a command the ``options`` (name -> (annotated type, default)) as typer options and
    passing them to it as one keyword argument ``into`` = ``build(**options given)``: a group of options is
    declared once and each command receives it as one value."""

    def decorate(fn: Callable[..., R]) -> Callable[..., R]:
        own = [
            p.replace(annotation=_resolved(p.annotation, fn.__globals__))
            for p in inspect.signature(fn).parameters.values()
            if p.name != into
        ]
        added = [
            inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, annotation=tp, default=default)
            for name, (tp, default) in options.items()
        ]

        @functools.wraps(fn)
        def command(*args: Any, **kwargs: Any) -> R:
            group = {name: kwargs.pop(name) for name in options}
            return fn(*args, **kwargs, **{into: build(**group)})

        params = own + added
        command.__signature__ = inspect.Signature(params, return_annotation=None)  # type: ignore[attr-defined]
        command.__annotations__ = {p.name: p.annotation for p in params}
        return command

    return decorate


_LOG_OPTIONS = {
    "fmt": (FormatOpt, None),
    "scan_topic": (ScanTopicOpt, None),
    "odom_topic": (OdomTopicOpt, None),
    "cmd_topic": (CmdTopicOpt, None),
    "truth_topic": (TruthTopicOpt, None),
    "strict": (StrictOpt, False),
}
_CONFIG_OPTIONS = {"preset_name": (PresetOpt, None), "config": (ConfigOpt, None), "sets": (SetOpt, None)}
_NAV_OPTIONS = {
    "planner": (PlannerOpt, None),
    "mode": (ModeOpt, None),
    "local": (LocalOpt, None),
    "subgoals": (SubgoalsOpt, None),
    "no_selector": (NoSelectorOpt, False),
}
#: The log-reading options (``--format``, the topics, ``--strict``), given to a command as ``read``.
log_options = _option_group("read", _LOG_OPTIONS, _read_options)
#: The configuration options (``--preset``, ``--config``, ``--set``), given to a command as ``setup``.
config_options = _option_group("setup", _CONFIG_OPTIONS, _setup)
#: The configuration options and the navigation ones (``--planner``, ``--mode``, ``--local``, ``--subgoals``,
#: ``--no-selector``), given to a command as ``setup``.
navigation_options = _option_group("setup", _CONFIG_OPTIONS | _NAV_OPTIONS, _setup)


def _load_subgoals(path: Path | None) -> tuple[Subgoal, ...]:
    """The subgoals of --subgoals FILE (none without it)."""
    if path is None:
        return ()
    from .io.subgoals import load_subgoals

    return tuple(load_subgoals(path))


def _said_moved(asked: Path, written: Path, what: str = "run", *, silent: bool = False) -> None:
    """Tell the user the output went beside an earlier one (``asked``-2, ...) rather than over it."""
    if written != asked and not silent:
        typer.echo(
            f"gndreplay: {asked} holds an earlier {what}; wrote {written} (--overwrite replaces it)", err=True
        )


def _print_json(data: object) -> None:
    import json

    typer.echo(json.dumps(data, allow_nan=True))


# --------------------------------------------------------------------------------------------------
# Commands


@app.command(cls=_Command)
@cli_errors
@log_options
def info(log: LogArg, json_out: JsonOpt = False, against: AgainstOpt = None, *, read: ReadOptions) -> None:
    """Show what a log contains (streams, rates, beams, range limits, odometry, gaps, malformed records).

    Format, start/end and duration, per-topic or per-message-type counts and rates, beams per scan, field
    of view, range limits, fraction of invalid / no-return beams, odometry source, time reversals, gaps and
    skipped malformed records. MCAP files are summarised from their index without decoding every message.
    With --against OTHER (the same recording in another container, a conversion say): then each difference
    between the two in what a replay reads, and what it changes.

    [bold]Examples[/]

      gndreplay info mit-csail.clf.bz2
      gndreplay info run.bag --scan-topic /base_scan --json
      gndreplay info aces.clf.bz2 --against aces.bag
    """
    from .info import against_dict, against_lines, log_info

    result = log_info(log, options=read)
    other = None if against is None else log_info(against, options=_read_options(strict=read.strict))
    if json_out:
        import json

        data = result.to_dict()
        if other is not None:
            data["against"] = against_dict(result, other)
        typer.echo(json.dumps(data, allow_nan=False))
        return
    _print_info(result)
    if other is not None:
        typer.echo("\n".join(against_lines(result, other)))


def _print_info(result: object) -> None:
    from rich.console import Console
    from rich.table import Table

    from .info import LogInfo, stream_rows, summary_rows

    assert isinstance(result, LogInfo)
    console = Console(soft_wrap=False)
    summary = Table(show_header=False, box=None, pad_edge=False)
    summary.add_column(style="bold")
    summary.add_column(overflow="fold")
    for label, value in summary_rows(result):
        summary.add_row(label, value)
    console.print(summary)
    streams = Table(title="streams", title_justify="left")
    for col in ("stream", "type", "used as", "count", "rate", "average"):
        streams.add_column(col, justify="right" if col in ("count", "rate", "average") else "left")
    for row in stream_rows(result):
        streams.add_row(*row)
    console.print(streams)


def _parse_goal(value: str | None, goal_ahead: float | None) -> tuple[float, float] | None:
    """``--goal X,Y``: two numbers, each within the readers' bound on positions; not with --goal-ahead.

    Raises:
        ConfigError: not two numbers separated by a comma, one not finite or out of range, or both options.
    """
    if value is None:
        return None
    if goal_ahead is not None:
        raise ConfigError("--goal and --goal-ahead exclude each other: give one")
    from .io.userfile import brief, check_number

    parts = value.replace(" ", "").split(",")
    try:
        x, y = (float(p) for p in parts)
    except ValueError:
        raise ConfigError(f"--goal: expected X,Y in metres (e.g. 3.5,-1.0), got {brief(value)}") from None
    return (
        check_number(x, "--goal: X", -_MAX_POSITION_M, _MAX_POSITION_M),
        check_number(y, "--goal: Y", -_MAX_POSITION_M, _MAX_POSITION_M),
    )


def _window(t_from: float | None, t_to: float | None, *, figures: bool) -> bool:
    """Whether ``--from`` / ``--to`` ask for a window of the time-series figures, checked before any work
    (refused without the figures, or empty: the run's span is checked when it is drawn).

    Raises:
        ConfigError: a window with --no-figures, or one ``report.rundir.check_window`` refuses.
    """
    if t_from is None and t_to is None:
        return False
    if not figures:
        raise ConfigError("--from / --to choose the figures' window: not with --no-figures")
    from .report.rundir import check_window

    check_window(t_from, t_to, name="--from / --to")
    return True


def _grid_every(value: str) -> int | Literal["change"]:
    """``--mcap-grid``: the robot-centred grid in results.mcap on every tick (1) or when it changed."""
    from .config import choose

    return 1 if choose("--mcap-grid", value, _MCAP_GRID) == "every" else "change"


def _snapshot_options(snapshots: bool | None, *, figures: bool, every_s: float, most: int) -> Any:
    """The event snapshots ``default_sinks`` draws: on with the figures unless --no-snapshots (None: off), at
    most one per kind of event per ``every_s`` seconds of log time and ``most`` per run."""
    if not (figures if snapshots is None else snapshots):
        return None
    from .report.snapshots import SnapshotOptions

    return SnapshotOptions(min_interval_s=every_s, max_snapshots=most)


def _corrected_xy(run_dir: Path) -> Any:
    """The x, y of every pose of a run's corrected trajectory ((N, 2), from trajectory_corrected.tum)."""
    from .report.rundir import CORRECTED_TRAJECTORY_FILE, read_tum

    return read_tum(run_dir / CORRECTED_TRAJECTORY_FILE)[:, 1:3]


def _log_stem(log: Path) -> str:
    """The default output name of a log: its name less the log suffixes, never ``.``/``..``/empty/hidden."""
    from .fsutil import safe_name
    from .io import COMPRESSED_SUFFIXES, LOG_SUFFIXES

    name = log.name.rstrip("/")
    for suffix in (*COMPRESSED_SUFFIXES, *LOG_SUFFIXES):
        if name.endswith(suffix):
            name = name[: -len(suffix)]
    return safe_name(name)


@app.command(cls=_Command)
@cli_errors
@log_options
@navigation_options
def run(
    log: Annotated[
        Path | None,
        typer.Argument(
            help="The log to replay (any format `gndreplay info` reads). Default: the bundled sample log.",
            show_default=False,
        ),
    ] = None,
    goal: Annotated[
        str | None,
        typer.Option(
            "--goal",
            help="Fixed goal X,Y (m) in the corrected odometry frame (instead of --goal-ahead).",
            rich_help_panel=_RUN_PANEL,
            show_default=False,
        ),
    ] = None,
    goal_ahead: GoalAheadOpt = None,
    matcher: Annotated[
        str | None,
        typer.Option(
            "--matcher",
            help="Odometry correction before the model: idc, kiss-icp or odom (default: the config's, idc).",
            rich_help_panel=_CONFIG_PANEL,
            show_default=False,
        ),
    ] = None,
    enforce_budgets: Annotated[
        bool,
        typer.Option(
            "--enforce-budgets",
            help="Act on module time-outs as the papers do (planner over budget = planner failure).",
            rich_help_panel=_CONFIG_PANEL,
        ),
    ] = False,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            help="Run directory (default: out/<log-stem>). An earlier run there is kept: the new one is "
            "written beside it (out/<log-stem>-2, ...) unless --overwrite.",
            rich_help_panel=_RUN_PANEL,
            show_default=False,
        ),
    ] = None,
    overwrite: OverwriteOpt = False,
    until: UntilOpt = None,
    every: EveryOpt = 1,
    mcap: McapOpt = False,
    figures: FiguresOpt = True,
    snapshots: SnapshotsOpt = None,
    snapshot_every: SnapshotEveryOpt = 10.0,
    snapshot_max: SnapshotMaxOpt = 40,
    mcap_grid: McapGridOpt = "change",
    t_from: FromOpt = None,
    t_to: ToOpt = None,
    match_ahead: MatchAheadOpt = None,
    quiet: QuietOpt = False,
    progress: ProgressOpt = "auto",
    json_out: JsonOpt = False,
    *,
    read: ReadOptions,
    setup: Setup,
) -> None:
    """Replay a log through scan matching -> model -> planner -> ND+ reactor -> supervisor.

    Writes a run directory: commands.csv (one command per scan), timing.csv, the odometry and corrected
    trajectories (TUM), summary.json, the resolved config.toml, the figures and report.md.

    [bold]Examples[/]

      gndreplay run                               # the bundled sample log
      gndreplay run aces.clf.bz2 --goal-ahead 3 --out out/aces
      gndreplay run run.bag --preset xr4000 --config mine.toml --until 60 --mcap
      gndreplay run run.bag --mode teleop         # would the stack have taken over?
    """
    from .replay import RunOptions, far_goal_warning, run_log
    from .report.build import build_report
    from .report.sinks import default_sinks
    from .report.summary import command_gap_warning, matcher_warning
    from .scanmatch.ahead import worthwhile
    from .sim.scenario import sample_log

    goal_xy = _parse_goal(goal, goal_ahead)
    window = _window(t_from, t_to, figures=figures)
    grid_every = _grid_every(mcap_grid)
    cfg = setup.config(matcher=matcher, enforce_budgets=enforce_budgets)
    log_path = log if log is not None else sample_log()
    out_dir = out if out is not None else Path("out") / _log_stem(log_path)
    options = RunOptions(goal_xy=goal_xy, goal_ahead_m=5.0 if goal_ahead is None else goal_ahead,
                         until_s=until, every=every, subgoals=setup.subgoals,
                         match_ahead=worthwhile() if match_ahead is None else match_ahead)
    style = _progress_style(progress, quiet=quiet, json_out=json_out)
    with _Progress(style) as shown:
        watch = _LogProgress(shown, log_path.name, until_s=until)
        sinks = default_sinks(figures=figures, mcap=mcap, enforce_budgets=cfg.supervisor.enforce_budgets,
                              on_draw=watch.on_draw,
                              snapshots=_snapshot_options(snapshots, figures=figures, every_s=snapshot_every,
                                                          most=snapshot_max),
                              config=cfg, mcap_grid=grid_every)
        summary = run_log(log_path, cfg, out_dir, options=options, read=read, sinks=sinks,
                          overwrite=overwrite, **watch.callbacks())
        if window:
            watch.on_draw()
            build_report(summary.out_dir, require_marker=True, t_from=t_from, t_to=t_to)
    _said_moved(out_dir, summary.out_dir, silent=quiet or json_out)
    far = None if goal_xy is None else far_goal_warning(goal_xy, _corrected_xy(summary.out_dir), cfg.grid)
    if json_out:
        _print_json(summary.data)
    elif not quiet:
        _print_run(summary.data, summary.out_dir)
    for warning in (far, command_gap_warning(summary.data), matcher_warning(summary.data)):  # last: seen
        if warning is not None:
            typer.echo(f"gndreplay: warning: {warning}", err=True)


@app.command(cls=_Command)
@cli_errors
@log_options
@config_options
def scanmatch(
    log: LogArg,
    matcher: Annotated[
        str, typer.Option("--matcher", help="idc, kiss-icp, odom, or all (side by side in one run).")
    ] = "all",
    relations: Annotated[
        Path | None,
        typer.Option(
            "--relations",
            help="SLAM-benchmark relations (t1 t2 x y z roll pitch yaw) to score each trajectory against.",
            show_default=False,
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            help="Folder for one TUM trajectory per matcher (default: out/<log-stem>-scanmatch).",
            rich_help_panel=_RUN_PANEL,
            show_default=False,
        ),
    ] = None,
    overwrite: OverwriteOpt = False,
    parallel: Annotated[
        bool | None,
        typer.Option(
            "--parallel/--no-parallel",
            help="With several matchers, run them side by side in one pass over the log, one process each: "
            "the same trajectories, sooner (default: when two CPUs are available).",
            rich_help_panel=_RUN_PANEL,
            show_default=False,
        ),
    ] = None,
    progress: ProgressOpt = "auto",
    json_out: JsonOpt = False,
    *,
    read: ReadOptions,
    setup: Setup,
) -> None:
    """Correct the log's odometry with each matcher and compare them side by side from the same run.

    Writes one TUM trajectory per matcher (full-precision stamps, readable by evo) and prints ms per scan
    (median, p99), match failures and, with --relations, the relation errors: for each relation (t1, t2) the
    pose of scan t2 in the frame of scan t1 against the reference; mean +- std and max of the translational
    (m) and rotational (deg) errors, relations matched / unmatched. When the log has ground truth (CARMEN
    TRUEPOS, a truth topic): each trajectory's ATE (RMSE and max after its SE(2) alignment to the truth)
    and RPE over 1 s. Then each matcher's health: failed and refused matches, the longest stretch without
    one, its disagreement with the odometry per scan and over the worst 5 s; a warning line when it likely
    made things worse (measured against the truth when there is one). The matchers' settings come from the
    configuration's [scanmatch.idc] / [scanmatch.kiss] sections.

    [bold]Example[/]

      gndreplay scanmatch mit-csail.clf.bz2 --relations mit-csail.relations
    """
    from .config import choose
    from .evaluation import load_relations
    from .replay import mounting_for
    from .scanmatch import METHODS, run_scanmatch
    from .scanmatch.ahead import worthwhile
    from .scanmatch.run import log_ticks

    chosen = choose("--matcher", matcher, (*METHODS, "all"))
    methods: list[Method] = list(METHODS) if chosen == "all" else [cast("Method", chosen)]
    cfg = setup.config()
    refs = load_relations(relations) if relations is not None else None
    out_dir = out if out is not None else Path("out") / f"{_log_stem(log)}-scanmatch"
    said: list[str] = []

    with _Progress(_progress_style(progress, json_out=json_out)) as shown:
        watch = _LogProgress(shown, log.name, until_s=None)
        rows = run_scanmatch(
            log_ticks(log, mounting_for(read, cfg), on_open=watch.on_open, on_tick=watch.on_tick),
            methods, relations=refs, out_dir=out_dir, idc=cfg.scanmatch.idc, kiss=cfg.scanmatch.kiss,
            relations_name=str(relations), overwrite=overwrite, on_pass=watch.on_pass,
            inputs=[Path(log)] + ([relations] if relations is not None else []),
            on_warning=said.append, parallel=worthwhile() if parallel is None else parallel,
        )
    for line in said:  # after the progress display, which would overwrite it
        typer.echo(f"gndreplay: warning: {line}", err=True)
    _said_moved(out_dir, Path(rows[0].tum_path).parent if rows and rows[0].tum_path else out_dir)
    if json_out:
        _print_json([r.to_dict() for r in rows])
    else:
        _print_scanmatch(rows, relations is not None)
    for r in rows:  # last: the line a user must not miss
        if r.health is not None and r.health.warning:
            typer.echo(f"gndreplay: warning: {r.health.warning}", err=True)


_RELATION_COLUMNS = ("trans err (m)", "trans max", "rot err (deg)", "rot max", "relations", "<1 s m",
                     "1-10 s m", ">10 s m", "<1 s rot max")
_TRUTH_COLUMNS = ("ATE RMSE (m)", "ATE max", "RPE (m)", "RPE (deg)")


def _scanmatch_cells(r: MatcherReport, with_relations: bool, with_truth: bool) -> list[str]:
    """One row of the scanmatch table: timings and failures, then the relation and ground-truth errors."""
    d = r.to_dict()
    cells = [d["method"], f"{d['ms_median']:.2f}", f"{d['ms_p99']:.2f}", str(d["failures"])]
    rel = d["relations"]
    if with_relations and rel is not None:
        cells += [
            f"{rel['trans_mean_m']:.3f} ± {rel['trans_std_m']:.3f}",
            f"{rel['trans_max_m']:.3f}",
            f"{rel['rot_mean_deg']:.2f} ± {rel['rot_std_deg']:.2f}",
            f"{rel['rot_max_deg']:.2f}",
            f"{rel['matched']}/{rel['matched'] + rel['unmatched']}",
        ]
        spans = {sp["label"]: sp for sp in rel["by_span"]}
        cells += [_num(spans.get(k, {}).get("trans_mean_m"), "{:.3f}") for k in ("<1 s", "1-10 s", ">10 s")]
        cells.append(_num(spans.get("<1 s", {}).get("rot_max_deg"), "{:.2f}"))
    if with_truth:
        e = r.truth
        cells += (["-"] * 4 if e is None else
                  [_num(e.ate_rmse_m, "{:.3f}"), _num(e.ate_max_m, "{:.3f}"),
                   _num(e.rpe_trans_rmse_m, "{:.4f}"), _num(e.rpe_rot_rmse_deg, "{:.3f}")])
    return cells


def _print_scanmatch(rows: Sequence[MatcherReport], with_relations: bool) -> None:
    """The side-by-side table (with the errors against the relations and the ground truth when there are),
    the matchers' health and where the trajectories went."""
    from rich.table import Table

    with_truth = any(r.truth is not None for r in rows)
    table = Table(title="scan matching, side by side in one run", title_justify="left")
    cols = ["matcher", "ms median", "ms p99", "failures"]
    cols += [*(_RELATION_COLUMNS if with_relations else ()), *(_TRUTH_COLUMNS if with_truth else ())]
    for c in cols:
        table.add_column(c, justify="left" if c == "matcher" else "right")
    for r in rows:
        table.add_row(*_scanmatch_cells(r, with_relations, with_truth))
    console = _console()
    console.print(table)
    if with_truth:
        console.print("ATE: aligned to the ground truth (SE(2) least squares); RPE: RMSE of the motion over "
                      "1 s.", highlight=False)
    _print_health(console, rows)
    for r in rows:
        if r.tum_path:
            console.print(f"{r.method}: {r.scans} scans -> {r.tum_path}", highlight=False)


def _print_health(console: Console, rows: Sequence[MatcherReport]) -> None:
    """The matchers' health side by side (``evaluation.matcher_health``)."""
    from rich.table import Table

    healths = [r.health for r in rows if r.health is not None]
    if not healths:
        return
    table = Table(title="scan matcher health (every scan)", title_justify="left")
    for c in ("matcher", "failed", "refused", "longest without a match", "vs odometry per scan p95 / max",
              f"worst {healths[0].window_s:g} s window", "verdict"):
        table.add_column(c, justify="left" if c in ("matcher", "verdict") else "right")
    for h in healths:
        longest = f"{h.longest_s:.1f} s ({h.longest_scans} scans)" if h.longest_scans else "-"
        step = (f"{_num(h.step_trans_m[1], '{:.3f}')} / {_num(h.step_trans_m[2], '{:.3f}')} m, "
                f"{_num(h.step_rot_deg[1], '{:.2f}')} / {_num(h.step_rot_deg[2], '{:.2f}')} deg")
        window = f"{_num(h.window_sigmas, '{:.1f}')} sigma"
        verdict = ("warning" if h.warning else "ok") + (" (measured)" if h.measured else " (estimated)")
        table.add_row(h.matcher, f"{h.failed} ({100.0 * h.failed_share:.1f} %)" if h.scans else "0",
                      str(h.refused), longest, step, window, verdict)
    console.print(table)


def _console() -> Console:
    """The terminal's console; when stdout is not a terminal, wide enough that tables do not fold."""
    from rich.console import Console

    console = Console(soft_wrap=False)
    if not console.is_terminal:
        console = Console(soft_wrap=False, width=160)
    return console


@app.command(cls=_Command)
@cli_errors
def report(
    run_dir: Annotated[
        Path, typer.Argument(help="A run directory written by `gndreplay run`.", show_default=False)
    ],
    t_from: FromOpt = None,
    t_to: ToOpt = None,
    animate: Annotated[
        bool,
        typer.Option(
            "--animate",
            help="Write an animation of the robot-centred view (GIF; MP4 when an encoder is installed) "
            "instead of redrawing the figures.",
        ),
    ] = False,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out", help="The animation's file (default: animation.gif in the run directory).",
            show_default=False,
        ),
    ] = None,
    progress: ProgressOpt = "auto",
) -> None:
    """Redraw the figures and report.md of a finished run from its files alone (no log needed).

    The figures (fig_model, fig_raw, fig_commands, fig_timing, fig_modes; fig_error with ground truth) come
    from commands.csv, timing.csv, the trajectories, summary.json and maps.npz; --from / --to draw the time
    series of a window. --animate writes an animation of the robot-centred view instead.

    [bold]Examples[/]

      gndreplay report out/aces
      gndreplay report out/aces --from 600 --to 660
      gndreplay report out/aces --animate --from 600 --to 620 --out aces.gif
    """
    from .report.build import build_report

    if animate:
        from .report.animate import animate_run

        with _Progress(_progress_style(progress)) as shown:
            path = animate_run(run_dir, out if out is not None else run_dir / "animation.gif", t_from=t_from,
                               t_to=t_to, on_progress=_frame_counter(shown, f"{run_dir.name}: animation"))
        typer.echo(str(path))
        return
    if out is not None:
        raise ConfigError("report: --out names the animation's file: give --animate too")
    for path in build_report(run_dir, require_marker=True, t_from=t_from, t_to=t_to):
        typer.echo(str(path))


@app.command(cls=_Command)
@cli_errors
def compare(
    run_a: Annotated[Path, typer.Argument(help="The reference run directory (A).", show_default=False)],
    run_b: Annotated[
        Path, typer.Argument(help="The run directory compared with it (B).", show_default=False)
    ],
    tolerance: ToleranceOpt = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out", help="Write compare.json, fig_compare.png and fig_compare_snapshot.png into this new "
            "folder.", show_default=False
        ),
    ] = None,
    snapshot: Annotated[
        bool | None,
        typer.Option(
            "--snapshot/--no-snapshot",
            help="Draw both runs' decisions at the first divergent tick (fig_compare_snapshot.png), "
            "re-running each run's input up to it (default: with --out).",
            show_default=False,
        ),
    ] = None,
    overwrite: OverwriteOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Compare two run directories (of run, simulate or batch): the first tick whose command differs, the
    first stage that differed at or before it, ticks differing per field, latency per module and the
    outcome of closed-loop runs.

    The command (commands.csv) is compared tick by tick on the ticks' stamps; the stages (stages.csv) are
    the corrected pose, the grid, the planner's result, ND+'s situation, region, direction and proposal, and
    the supervisor's mode, flags and command. Module times are wall clock: they are reported, never a
    difference. Exit 0: the same within tolerance; 1: different; 2: a run directory or the tolerance file
    cannot be read.

    [bold]Examples[/]

      gndreplay compare out/aces out/aces-2
      gndreplay compare out/aces out/aces-2 --tolerance tol.toml --out out/aces-compare
    """
    from .report.compare import comparison_lines, comparison_to_dict
    from .rerun import compare_dirs

    result, written = compare_dirs(run_a, run_b, tolerance=tolerance, out=out, overwrite=overwrite,
                                   snapshot=snapshot)
    if json_out:
        import json

        typer.echo(json.dumps(comparison_to_dict(result), indent=2, allow_nan=False))
    else:
        for line in comparison_lines(result):
            typer.echo(line)
        if written is not None:
            typer.echo(f"written: {written}")
    if not result.same:
        raise typer.Exit(1)


@app.command(cls=_Command)
@cli_errors
@navigation_options
def simulate(
    scenario: Annotated[
        str | None,
        typer.Argument(
            help="A scenario file (.yaml), a shipped scenario's name (see --list), or office (the scripted "
            "sample log).",
            show_default=False,
        ),
    ] = None,
    seed: Annotated[
        int,
        typer.Option(
            "--seed",
            callback=_seed,
            help="Seed of every random draw (the same seed gives the same bytes; 0 to 2^63 - 1).",
            rich_help_panel=_SIM_PANEL,
        ),
    ] = 0,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            help="Run directory (default out/sim/SCENARIO-PRESET-SEED); for office: the CARMEN log "
            "to write (.clf, .clf.gz, .clf.bz2; default office.clf.bz2).",
            rich_help_panel=_RUN_PANEL,
            show_default=False,
        ),
    ] = None,
    latency: LatencyOpt = "0",
    perfect_odometry: PerfectOdometryOpt = False,
    ideal_dynamics: IdealDynamicsOpt = False,
    time_limit: TimeLimitOpt = None,
    figures: FiguresOpt = True,
    snapshots: SnapshotsOpt = None,
    snapshot_every: SnapshotEveryOpt = 10.0,
    snapshot_max: SnapshotMaxOpt = 40,
    mcap: McapOpt = False,
    mcap_grid: McapGridOpt = "change",
    overwrite: OverwriteOpt = False,
    list_: Annotated[bool, typer.Option("--list", help="List the shipped scenarios and exit.")] = False,
    progress: ProgressOpt = "auto",
    json_out: JsonOpt = False,
    *,
    setup: Setup,
) -> None:
    """Drive the navigation stack in closed loop through a simulated world and score it.

    Writes a run directory like `gndreplay run` plus result.json (outcome, collision, time to goal, path,
    clearance, ...), log.mcap (scan, odometry, commands, ground truth; `gndreplay run` replays it) and
    fig_world.png. Exit 0 on success, 1 on a collision, a goal missed or a time-out, 2 on a bad scenario.

    `gndreplay simulate office --seed 0 --out sample_logs/office.clf.bz2` writes the bundled sample log.
    """
    from .sim.scenario import SCENARIOS

    if list_ or scenario is None:
        _list_scenarios(given=list_)
        return
    if scenario in SCENARIOS:
        from .sim.scenario import simulate as simulate_log

        log = simulate_log(scenario, seed=seed, out=out or Path(f"{scenario}.clf.bz2"), overwrite=overwrite)
        typer.echo(str(log))
        return
    from .fsutil import safe_name
    from .sim import resolve_scenario, simulate_scenario
    from .sim.closedloop import configure_scenario
    from .sim.runner import parse_latency

    latency_s = parse_latency(latency)
    spec, cfg = configure_scenario(resolve_scenario(scenario), config=setup.path, preset=setup.preset,
                                   overrides=setup.overrides, subgoals=setup.subgoals)
    run_name = safe_name(f"{spec.name}-{cfg.preset}-{seed}")  # a scenario's name never leaves out/sim
    out_dir = out if out is not None else Path("out") / "sim" / run_name
    with _Progress(_progress_style(progress, json_out=json_out)) as shown:
        watch = _LogProgress(shown, spec.name, until_s=time_limit or spec.time_limit_s)
        result = simulate_scenario(
            spec, out_dir=out_dir, cfg=cfg, seed=seed, latency_s=latency_s, perfect_odometry=perfect_odometry,
            time_limit_s=time_limit, figures=figures, overwrite=overwrite, on_tick=watch.on_tick,
            run_kwargs={"on_stage": watch.on_stage, "on_compile": watch.on_compile},
            snapshots=_snapshot_options(snapshots, figures=figures, every_s=snapshot_every,
                                        most=snapshot_max),
            mcap=mcap,
            mcap_grid=_grid_every(mcap_grid),
            ideal_dynamics=ideal_dynamics,
        )
    _said_moved(out_dir, result.out_dir, silent=json_out)
    _warn_matcher(result.out_dir)
    if json_out:
        _print_json(result.result)
    else:
        _print_simulation(result, f"{spec.name} ({cfg.preset}, seed {seed})")
    if not result.success:
        raise typer.Exit(1)


def _warn_matcher(run_dir: Path) -> None:
    """The scan matcher's warning of a finished run (its summary.json), on stderr, if it has one."""
    from .report.rundir import SUMMARY_FILE, read_summary
    from .report.summary import matcher_warning

    warning = matcher_warning(read_summary(run_dir / SUMMARY_FILE))
    if warning is not None:
        typer.echo(f"gndreplay: warning: {warning}", err=True)


def _print_simulation(result: SimOutcome, title: str) -> None:
    """One line: how the scenario run ended, its path (and the optimal one), clearance, the narrowest passage
    on the way, challenge metric, and where it was written; a warning when the robot does not fit that
    passage."""
    c = result.collision
    what = (f"collision with {c['object']} at {c['t_s']:.2f} s" if c else
            f"{result.outcome} at {result.end_time_s:.1f} s")
    typer.echo(
        f"{title}: {what}; path {result.path_length_m:.1f} m (optimal "
        f"{_num(result.optimal_path_m, '{:.1f}')} m), min clearance "
        f"{_num(result.min_clearance_m, '{:.3f}')} m, narrowest passage "
        f"{_num(result.narrowest_passage_m, '{:.2f}')} m, challenge metric "
        f"{_num(result.challenge_metric, '{:.3f}')} -> {result.out_dir}"
    )
    if result.passage_warning is not None:
        typer.echo(f"gndreplay: warning: {title}: {result.passage_warning}", err=True)


def _list_scenarios(*, given: bool) -> None:
    """``simulate --list``: the shipped scenarios, one per line (without it and a scenario: an error)."""
    if not given:
        raise ConfigError("simulate: give a scenario file or name (or --list)")
    from .sim.scenario_file import shipped_scenarios

    for name, text in shipped_scenarios().items():
        typer.echo(f"{name:24s} {text}")


@app.command(cls=_Command)
@cli_errors
@log_options
@navigation_options
def batch(
    ctx: typer.Context,
    inputs: Annotated[
        list[Path] | None,
        typer.Argument(
            help="Logs, folders searched for logs (CARMEN, ROS bags, MCAP), and scenario files (.yaml/.yml).",
            show_default=False,
        ),
    ] = None,
    scenarios: Annotated[
        list[str] | None,
        typer.Option(
            "--scenarios",
            help="Shipped scenarios to run too: all, or names (comma-separated or repeated; "
            "`simulate --list`).",
            rich_help_panel=_SIM_PANEL,
            show_default=False,
        ),
    ] = None,
    seeds: Annotated[
        str | None,
        typer.Option(
            "--seeds",
            help="Seeds of each scenario (default 0), e.g. 1-20, 1,3,5 or 0-4,10: a run each, named "
            "<scenario>-s<seed>.",
            rich_help_panel=_SIM_PANEL,
            show_default=False,
        ),
    ] = None,
    jobs: Annotated[
        int, typer.Option("--jobs", "-j", callback=_bounded("--jobs", 1, _MAX_JOBS), help="Worker processes.")
    ] = 1,
    thresholds: Annotated[
        Path | None,
        typer.Option(
            "--thresholds",
            help="TOML of pass/fail limits and per-input settings.",
            show_default=False,
        ),
    ] = None,
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            help="Batch folder (default out/batch; taken: beside it).",
            show_default=False,
            rich_help_panel=_RUN_PANEL,
        ),
    ] = Path("out/batch"),
    overwrite: OverwriteOpt = False,
    junit: Annotated[
        Path | None,
        typer.Option(
            "--junit",
            help="Also write JUnit XML (a test case per input and check).",
            rich_help_panel=_RUN_PANEL,
            show_default=False,
        ),
    ] = None,
    dask: Annotated[
        str | None,
        typer.Option(
            "--dask",
            help="Run on this dask scheduler (pip install 'gndreplay[dask]').",
            show_default=False,
        ),
    ] = None,
    shard: Annotated[
        str | None,
        typer.Option(
            "--shard",
            help="I/N: run only the inputs i % N == I. N: I from the job's index.",
            show_default=False,
        ),
    ] = None,
    merge: Annotated[
        bool,
        typer.Option(
            "--merge",
            help="INPUTS are shard folders of one batch: merge them into --out.",
        ),
    ] = False,
    goal_ahead: GoalAheadOpt = None,
    until: UntilOpt = None,
    every: EveryOpt = 1,
    latency: LatencyOpt = "0",
    perfect_odometry: PerfectOdometryOpt = False,
    ideal_dynamics: IdealDynamicsOpt = False,
    time_limit: TimeLimitOpt = None,
    figures: Annotated[
        bool | None,
        typer.Option(
            "--figures/--no-figures",
            help="Draw each run's figures (default: scenario runs only).",
            rich_help_panel=_RUN_PANEL,
        ),
    ] = None,
    timeout: Annotated[
        float,
        typer.Option(
            "--timeout",
            callback=_bounded("--timeout", 0.001, _MAX_SECONDS),
            help="Per-input time limit [s] (default 3600).",
            show_default=False,
        ),
    ] = 3600.0,
    baseline: Annotated[
        Path | None,
        typer.Option(
            "--baseline",
            help="Earlier batch folder: compare each run with its run there; a change fails.",
            show_default=False,
            rich_help_panel=_BASELINE_PANEL,
        ),
    ] = None,
    update_baseline: Annotated[
        bool,
        typer.Option(
            "--update-baseline",
            help="Make this batch the new --baseline: changes are not failures.",
            rich_help_panel=_BASELINE_PANEL,
        ),
    ] = False,
    tolerance: ToleranceOpt = None,
    latency_ratio: Annotated[
        float,
        typer.Option(
            "--latency-ratio",
            callback=_bounded("--latency-ratio", 0.0, 1e6),
            help="Fail when a module's median time is over this times the baseline's (0: off).",
            rich_help_panel=_BASELINE_PANEL,
        ),
    ] = 1.5,
    quiet: QuietOpt = False,
    progress: ProgressOpt = "auto",
    *,
    read: ReadOptions,
    setup: Setup,
) -> None:
    """Replay many logs and run closed-loop scenarios in parallel worker processes; check thresholds,
    compare with a baseline, sweep configuration keys; write summary.csv, summary.md and JUnit XML.

    A scenario runs once per seed and passes if the robot reaches the goal. --baseline compares each run
    with its run in an earlier batch (first divergent tick, stage, outcome, latency); a --set listing
    values sweeps their combinations; --shard and --merge split a batch across machines. Exit 0: all
    passed, 1: a threshold failed or a run changed, 2: an input could not be read.

    [bold]Examples[/]

      gndreplay batch ../shared/datasets/carmen --jobs 2 --junit out/junit.xml --thresholds ci.toml
      gndreplay batch logs/ --until 120 --baseline ci/baseline   # --update-baseline accepts changes
      gndreplay batch --scenarios u_trap --set reactor.security_m=0.3,0.5 --set robot.vmax_mps=1,2
    """
    import os

    from .batch import expand_inputs, load_thresholds, parse_seeds, run_batch
    from .batch.scenarios import SimOptions
    from .batch.shard import parse_shard, shard_indices
    from .batch.thresholds import Thresholds
    from .replay import RunOptions
    from .sim.runner import parse_latency

    against = _baseline(baseline, update=update_baseline, tolerance=tolerance, ratio=latency_ratio)
    if against is not None and against.update:
        if getattr(ctx.get_parameter_source("out"), "name", None) == "COMMANDLINE":
            raise ConfigError("--update-baseline writes the batch to the --baseline folder: not with --out")
        out, overwrite = against.folder, True
    if merge:
        _merge(ctx, inputs or [], out=out, junit=junit, thresholds=thresholds, overwrite=overwrite,
               baseline=against, quiet=quiet)
    part = None if shard is None else parse_shard(shard, os.environ)
    sim = SimOptions(latency_s=parse_latency(latency), perfect_odometry=perfect_odometry,
                     ideal_dynamics=ideal_dynamics, time_limit_s=time_limit, figures=figures is not False,
                     config=setup.path, preset=setup.preset, overrides=setup.overrides,
                     subgoals=setup.subgoals)
    settings = _sweep_settings(setup, sim)
    job_list = expand_inputs(
        inputs or [], scenarios=scenarios or [], seeds=None if seeds is None else parse_seeds(seeds)
    )
    limits = load_thresholds(thresholds) if thresholds is not None else Thresholds()
    options = RunOptions(goal_ahead_m=5.0 if goal_ahead is None else goal_ahead, until_s=until, every=every,
                         subgoals=setup.subgoals)
    total = len(shard_indices(len(job_list) * len(settings), part))
    with _Progress(_progress_style(progress, quiet=quiet)) as shown:
        shown.start("batch", total)
        advance = None if shown.style == "none" else _counter(shown, total, "inputs")
        result = run_batch(job_list, cfg=settings[0].cfg, options=options, thresholds=limits, out_dir=out,
                           workers=jobs, dask_address=dask, progress=advance, junit=junit, read=read,
                           timeout_s=timeout, overwrite=overwrite, sim=settings[0].sim,
                           figures=figures is True, shard=part,
                           sweep=settings if settings[0].point.name else (), baseline=against)
    _batch_done(out, result, quiet=quiet)


scenario_app = typer.Typer(
    cls=_Commands,
    no_args_is_help=True,
    rich_markup_mode="rich",
    help="Make scenario files.",
)
app.add_typer(scenario_app, name="scenario")


@scenario_app.command(cls=_Command)
@cli_errors
@config_options
def generate(
    out: Annotated[
        Path,
        typer.Argument(help="Folder to write the scenario files to (field_000.yaml, ...).",
                       show_default=False),
    ],
    count: Annotated[
        int,
        typer.Option("--count", "-n", callback=_bounded("--count", 1, 10_000), help="Fields to write."),
    ] = 10,
    seed: Annotated[
        int,
        typer.Option("--seed", callback=_seed,
                     help="Seed of the fields (the same seed gives the same files)."),
    ] = 0,
    overwrite: OverwriteOpt = False,
    *,
    setup: Setup,
) -> None:
    """Write random obstacle fields (a 4.5 m corridor of clustered cylinders, the goal 10 m ahead) as
    scenario files, each passable by the robot's inscribed circle.

    The robot's footprint comes from the configuration (--preset, --config, --set); the files name its
    preset. Run them with `gndreplay batch OUT/*.yaml` or `gndreplay simulate OUT/field_000.yaml`.
    """
    from .sim.fields import generate_fields

    cfg = setup.config()
    folder, files = generate_fields(out, count=count, seed=seed, robot=cfg.robot, preset_name=cfg.preset,
                                    overwrite=overwrite)
    _said_moved(out, folder, "set of fields")
    typer.echo(f"{len(files)} fields -> {folder}")


def _merge(ctx: typer.Context, folders: list[Path], *, out: Path, junit: Path | None, thresholds: Path | None,
           overwrite: bool, baseline: Any, quiet: bool) -> NoReturn:
    """``batch --merge``: join the shard folders into ``out`` (only the output and baseline options go with
    it), print the result and exit with its code."""
    from .batch import load_thresholds
    from .batch.merge import merge_batches

    _only_options(ctx, "--merge", ("inputs", "merge", "out", "junit", "thresholds", "overwrite", "quiet",
                                   "progress", "baseline", "update_baseline", "tolerance", "latency_ratio"))
    given = None if thresholds is None else load_thresholds(thresholds)
    merged = merge_batches(folders, out_dir=out, junit=junit, thresholds=given, overwrite=overwrite,
                           baseline=baseline)
    _batch_done(out, merged, quiet=quiet)


def _batch_done(out: Path, result: object, *, quiet: bool) -> NoReturn:
    """Say where the batch folder went if not at ``out``, print the result and exit with its code."""
    import os

    from .batch import BatchResult

    assert isinstance(result, BatchResult)
    _said_moved(Path(os.path.abspath(out)), result.out_dir, "batch")
    _print_batch(result, quiet=quiet)
    raise typer.Exit(result.exit_code)


def _baseline(folder: Path | None, *, update: bool, tolerance: Path | None, ratio: float) -> Any:
    """The ``batch.Baseline`` the baseline options ask for (None without --baseline).

    Raises:
        ConfigError: --update-baseline or --tolerance without --baseline; a bad tolerance file.
    """
    from .batch import Baseline
    from .report.compare import Tolerance, read_tolerance

    if folder is None:
        if update or tolerance is not None:
            raise ConfigError(f"{'--update-baseline' if update else '--tolerance'}: name the baseline folder "
                              "with --baseline DIR")
        return None
    return Baseline(folder, read_tolerance(tolerance) if tolerance is not None else Tolerance(), ratio,
                    update=update)


def _sweep_settings(setup: Setup, sim: Any) -> list[Any]:
    """One ``batch.Setting`` per combination of the --set sweep (one when nothing is swept), each
    configuration validated before anything runs."""
    from .batch import Setting, sweep_points

    return [Setting(p, setup.config(sets=p.sets),
                    dataclasses.replace(sim, overrides=dataclasses.replace(setup.overrides, sets=p.sets)))
            for p in sweep_points(setup.overrides.sets)]


def _only_options(ctx: typer.Context, flag: str, allowed: Sequence[str]) -> None:
    """Refuse an option given on the command line (or from the environment) besides ``allowed`` (parameter
    names) with ``flag``: one line naming it."""
    given = [
        p for p in ctx.command.params
        if p.name not in allowed and p.name is not None
        and getattr(ctx.get_parameter_source(p.name), "name", None) in ("COMMANDLINE", "ENVIRONMENT")
    ]
    if given:
        names = ", ".join(p.opts[0] for p in given)
        kept = ", ".join(p.opts[0] for p in ctx.command.params
                         if p.name in allowed and p.opts[0].startswith("-"))
        raise ConfigError(f"{flag}: not with {names} (it takes only {kept})")


def _print_batch(result: object, *, quiet: bool) -> None:
    """The errors and failures on stderr (failures only when ``quiet``: the table shows them), then the
    table of inputs unless ``quiet``."""
    from rich.table import Table

    from .batch import BatchResult

    assert isinstance(result, BatchResult)
    for r in result.results:
        if r.status == "error":
            typer.echo(f"gndreplay: error: {r.name}: {r.error}", err=True)
        elif r.status == "fail" and quiet:
            typer.echo(f"gndreplay: fail: {r.name}: {'; '.join(r.failures)}", err=True)
    for a in result.aggregates:
        if a.failures:
            typer.echo(
                f"gndreplay: fail: {a.label} over {a.runs} seeds: {'; '.join(a.failures)}", err=True
            )
    _print_check_lines(result)
    if quiet:
        return
    _print_baseline(result)
    _print_sweep(result)
    table = Table(title=f"batch: {len(result.results)} inputs in {result.wall_s:.1f} s", title_justify="left")
    for col in ("input", "status", "ticks", "stack p99 ms", "reactor p99 ms", "match failures", "why"):
        table.add_column(
            col, justify="right" if "ms" in col or col in ("ticks", "match failures") else "left"
        )
    style = {"pass": "green", "fail": "yellow", "error": "red"}
    for r in result.results:
        m = r.metrics
        why = r.error if r.status == "error" else "; ".join(r.failures)
        table.add_row(
            r.label,
            f"[{style[r.status]}]{r.status}[/]",
            str(r.ticks),
            _num(m.get("stack_p99_ms")),
            _num(m.get("reactor_p99_ms")),
            _num(m.get("match_failures"), "{:.0f}"),
            why or "",
        )
    _console().print(table)
    typer.echo(
        f"summary: {result.summary_csv}, {result.summary_md}" + (f", {result.junit}" if result.junit else "")
    )


def _print_check_lines(result: Any) -> None:
    """One line on stderr per failed (or, updating the baseline, accepted) baseline check."""
    verb = "accepted" if result.baseline_updated else "fail"
    for c in result.checks:
        for why in (c.behaviour_failure, c.latency_failure):
            if why:
                typer.echo(f"gndreplay: {verb}: {c.label}: {why}", err=True)
        if c.error:
            typer.echo(f"gndreplay: error: {c.label}: baseline: {c.error}", err=True)


def _print_baseline(result: Any) -> None:
    """The table of the runs against the baseline (input, verdict, first divergence, outcome change, latency
    ratio), when there is one."""
    from rich.markup import escape
    from rich.table import Table

    from .batch.baseline import ratio_text

    if not result.checks and not result.missing:
        return
    title = "against the baseline" + (" (written as the new baseline)" if result.baseline_updated else "")
    table = Table(title=title, title_justify="left")
    for col in ("input", "verdict", "first divergence", "outcome change", "latency ratio"):
        table.add_column(col, justify="right" if col == "latency ratio" else "left")
    style = {"same": "green", "new": "cyan", "error": "red"}
    for c in result.checks:
        table.add_row(escape(c.label), f"[{style.get(c.verdict, 'yellow')}]{c.verdict}[/]",
                      escape(c.error or c.divergence or "-"), escape(c.outcome_change or "-"),
                      ratio_text(c.latency_ratio) + (f" {c.slowest_module}" if c.slowest_module else ""))
    _console().print(table)
    if result.missing:
        typer.echo("not in this batch (in the baseline): " + ", ".join(result.missing))


def _print_sweep(result: Any) -> None:
    """The sweep table (one row per combination), when the batch swept configuration keys."""
    from rich.markup import escape
    from rich.table import Table

    from .batch.sweep import sweep_rows

    if not any(p.name for p in result.points):
        return
    header, rows = sweep_rows(result.points, result.results)
    keys = len(result.points[0].values)
    table = Table(title=f"sweep: {len(rows)} combinations", title_justify="left")
    for k, col in enumerate(header):
        table.add_column(escape(col), justify="left" if k < keys else "right")
    for row in rows:
        table.add_row(*(escape(str(v)) if k < keys + 4 else _num(v, "{:.3g}") for k, v in enumerate(row)))
    _console().print(table)


def _num(value: object, fmt: str = "{:.2f}") -> str:
    """A number for a table cell; "-" when there is none (missing, or NaN: nothing to average)."""
    return fmt.format(value) if isinstance(value, int | float) and math.isfinite(value) else "-"




class _Progress:
    """Progress on stderr in one of three styles (:func:`_progress_style`): "live", a transient rich bar
    (:func:`_progress_bar`); "plain", a line at each tenth of the total (none at the end: the result
    follows), or every ``_PLAIN_EVERY_S`` seconds while the total is unknown; "none".

    ``start`` begins a pass over ``total`` units (None: unknown), ``update`` says how far it is and
    ``describe`` names a stage of the pass.
    """

    def __init__(self, style: str) -> None:
        self.style = style
        self.description = ""
        self.total: float | None = None
        self._t0 = self._last = time.monotonic()
        self._tenths = 0
        self._bar: Progress | None = None
        self._task: TaskID | None = None

    def __enter__(self) -> _Progress:
        if self.style == "live":
            from rich.console import Console

            self._bar = _progress_bar(Console(stderr=True))
            self._bar.start()
            self._task = self._bar.add_task("", total=None, detail="")
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.stop()

    def start(self, description: str, total: float | None) -> None:
        """A pass over ``total`` units begins."""
        self.description, self.total = description, total
        self._t0 = self._last = time.monotonic()
        self._tenths = 0
        if self._bar is not None and self._task is not None:
            self._bar.reset(self._task, total=total, description=escape(description), detail="")

    def describe(self, description: str, detail: str | None = None, completed: float | None = None) -> None:
        """Name the stage the pass is in (the bar's text; plain lines only count)."""
        self.description = description
        fields: dict[str, Any] = {"description": escape(description)}
        fields |= ({} if detail is None else {"detail": detail}) | ({} if completed is None else
                                                                   {"completed": completed})
        if self._bar is not None and self._task is not None:
            self._bar.update(self._task, **fields)

    def update(self, completed: float, detail: str = "") -> None:
        """``completed`` of the pass's ``total`` units are done."""
        if self._bar is not None and self._task is not None:
            self._bar.update(self._task, completed=completed, detail=detail)
        elif self.style == "plain" and self._plain_due(completed):
            line = _plain_line(self.description, completed, self.total, detail, time.monotonic() - self._t0)
            typer.echo(line, err=True)

    def note(self, text: str) -> None:
        """A one-time notice a plain display prints (the bar shows it in its text instead)."""
        if self.style == "plain":
            typer.echo(f"gndreplay: {text}", err=True)

    def _plain_due(self, completed: float) -> bool:
        """Whether a plain line is due: a new tenth of the total reached (not the last), or, with no
        total, ``_PLAIN_EVERY_S`` seconds since the last line."""
        if self.total:
            tenths = int(10 * completed / self.total)
            if tenths <= self._tenths or tenths >= 10:
                return False
            self._tenths = tenths
            return True
        now = time.monotonic()
        if now - self._last < _PLAIN_EVERY_S:
            return False
        self._last = now
        return True


def _progress_style(choice: str, *, quiet: bool = False, json_out: bool = False) -> str:
    """The progress display ``--progress`` asks for: none with --quiet (and, unless asked, with --json);
    auto is a live bar when stderr is a terminal and plain lines when it is a file or a pipe."""
    from .config import choose

    style = choose("--progress", choice, _PROGRESS_STYLES)
    if quiet or style == "none" or (style == "auto" and json_out):
        return "none"
    return "live" if style == "auto" and sys.stderr.isatty() else "plain"


def _progress_bar(console: Console) -> Progress:
    """The live bar: spinner, description, bar, percentage, detail, elapsed time and ETA. The description
    and the detail are cut (with an ellipsis) before the times are, so the line fits 80 columns."""
    from rich.progress import (
        BarColumn,
        Progress,
        SpinnerColumn,
        TaskProgressColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )
    from rich.table import Column

    def fixed(width: int) -> Column:
        return Column(min_width=width, no_wrap=True)

    def cut(width: int) -> Column:
        return Column(max_width=width, no_wrap=True, overflow="ellipsis")

    return Progress(
        SpinnerColumn(),
        TextColumn("[bold]{task.description}", table_column=cut(22)),
        BarColumn(bar_width=None, table_column=Column(ratio=1, min_width=8)),
        TaskProgressColumn(table_column=fixed(4)),
        TextColumn("{task.fields[detail]}", table_column=cut(20)),
        TimeElapsedColumn(table_column=fixed(7)),
        TextColumn("ETA", table_column=fixed(3)),
        TimeRemainingColumn(table_column=fixed(7)),
        console=console,
        transient=True,
        expand=True,
    )


def _plain_line(description: str, done: float, total: float | None, detail: str, elapsed_s: float) -> str:
    """One plain progress line: ``gndreplay: aces.clf: 40 % (120 ticks, 96 s), 0:00:12 elapsed, ETA
    0:00:18`` (without a total: no share and no ETA)."""
    share = f" {math.floor(100.0 * done / total)} %" if total else ""
    what = f" ({detail})" if detail and share else f" {detail}" if detail else ""
    eta = f", ETA {_clock(elapsed_s * (total - done) / done)}" if total and done > 0 else ""
    return f"gndreplay: {description}:{share}{what}, {_clock(elapsed_s)} elapsed{eta}"


def _clock(seconds: float) -> str:
    """``h:mm:ss``, as the bar shows times."""
    s = max(round(seconds), 0)
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


def _counter(progress: _Progress, total: int, unit: str) -> Callable[[object], None]:
    """A callback advancing ``progress`` by one item (a batch input, named by its ``name``)."""
    done = 0

    def advance(item: object) -> None:
        nonlocal done
        done += 1
        progress.update(done, f"{done}/{total} {unit}, last {getattr(item, 'name', '')}")

    return advance


def _frame_counter(progress: _Progress, label: str) -> Callable[[int, int], None]:
    """A callback showing an animation's frames drawn (done, total) on ``progress``."""

    def on_frame(done: int, total: int) -> None:
        if progress.total != total:
            progress.start(label, total)
        progress.update(done, f"{done}/{total} frames")

    return on_frame


class _LogProgress:
    """What ``run``, ``scanmatch`` and ``simulate`` show while they work (through a :class:`_Progress`):
    the warm-up ("compiling (first run only)" with the count of kernels when numba's disk cache is cold),
    then each pass over the log's time with percentage and ETA (total: ``until_s``, else the log's
    duration or scan count when its format knows them, else the share of the file read), then writing and
    drawing the figures. ``scanmatch`` makes one pass per matcher (``on_pass``)."""

    def __init__(self, progress: _Progress, label: str, *, until_s: float | None) -> None:
        self.progress = progress
        self.label = label
        self.until_s = until_s
        self.total: float | None = until_s
        self.unit = "s"
        self.ticks = 0
        self.compiled = 0
        self._t0_ns: int | None = None
        self._fraction: Callable[[], float | None] | None = None
        self._pass: str | None = None
        progress.describe(f"{label}: opening")

    def callbacks(self) -> dict[str, Callable[..., None]]:
        """The callbacks ``replay.run_log`` takes: on_tick, on_open, on_stage, on_compile."""
        return {
            "on_tick": self.on_tick,
            "on_open": self.on_open,
            "on_stage": self.on_stage,
            "on_compile": self.on_compile,
        }

    def on_open(self, reader: object) -> None:
        """The log is open: its total (and, in a matcher's pass, the pass begins)."""
        self.total, self.unit, self._fraction = _log_total(reader, self.until_s)
        if self._pass is not None:
            self._begin(f"{self.label}: {self._pass}")

    def on_pass(self, method: str) -> None:
        """A matcher's pass over the log begins (the log is opened next)."""
        self._pass = method

    def on_stage(self, stage: str) -> None:
        """Switch the display to the replay's stage."""
        if stage == "warm-up":
            self.progress.describe(f"{self.label}: warming up")
        elif stage == "replay":
            self._begin(self.label)
        elif stage == "write":
            self.progress.describe(f"{self.label}: writing", completed=self.total or 0)

    def _begin(self, description: str) -> None:
        self.ticks, self._t0_ns = 0, None
        self.progress.start(description, self.total)

    def on_compile(self, kernel: str) -> None:
        """A kernel is being compiled (cold cache): say so, once, and count them."""
        self.compiled += 1
        if self.compiled == 1:
            self.progress.note("compiling (first run only)...")
        self.progress.describe(
            f"{self.label}: compiling (first run only)…", detail=f"{self.compiled} kernels ({kernel})"
        )

    def on_tick(self, result: object) -> None:
        """One tick (a stack decision, a matched scan): advance by its log time (or by one scan, or by the
        share of the file read)."""
        t_ns = int(getattr(result, "t_ns", 0))
        if self._t0_ns is None:
            self._t0_ns = t_ns
        self.ticks += 1
        log_s = (t_ns - self._t0_ns) / 1e9
        if self._fraction is not None:
            self.progress.update(100.0 * (self._fraction() or 0.0), f"{self.ticks} ticks, {log_s:.0f} s")
            return
        done = log_s if self.unit == "s" else float(self.ticks)
        self.progress.update(done, f"{self.ticks} ticks, {done:.0f} {self.unit}")

    def on_draw(self) -> None:
        """The figures are being drawn."""
        self.progress.describe(f"{self.label}: drawing figures")


def _log_total(
    reader: object, until_s: float | None
) -> tuple[float | None, str, Callable[[], float | None] | None]:
    """What a pass over an open log counts to, as (total, unit, share-of-file callback): the log's duration
    in seconds (at most ``until_s``) when its description knows it, else ``until_s``, else its scan count,
    else the share of the file read (CARMEN logs do not say their length) in %, else unknown."""
    desc = reader.describe() if hasattr(reader, "describe") else reader
    start, end = getattr(desc, "start_ns", None), getattr(desc, "end_ns", None)
    if start is not None and end is not None and end > start:
        duration = (end - start) / 1e9
        return (duration if until_s is None else min(until_s, duration)), "s", None
    if until_s is not None:
        return until_s, "s", None
    scan = getattr(desc, "scan_stream", None)
    counts = [s.count for s in getattr(desc, "streams", ()) if s.name == scan and s.count]
    if counts:
        return float(counts[0]), "scans", None
    if callable(fraction := getattr(reader, "fraction_read", None)):
        return 100.0, "%", fraction
    return None, "s", None


def _print_run(data: dict[str, object], out_dir: Path) -> None:
    from rich.table import Table

    console = _console()
    head = Table(show_header=False, box=None, pad_edge=False)
    head.add_column(style="bold")
    head.add_column()
    agreement = data.get("agreement") or {}
    assert isinstance(agreement, dict)
    head.add_row("run directory", str(out_dir))
    head.add_row("ticks", f"{data['ticks']} over {float(data['duration_s']):.1f} s")  # type: ignore[arg-type]
    head.add_row("modes", _counts(data["modes"]))
    head.add_row("situations", _counts(data["situations"]))
    flags = {k: v for k, v in data["flags"].items() if v}  # type: ignore[attr-defined]
    head.add_row("flags", _counts(flags) or "none")
    iv = data.get("interventions")
    if isinstance(iv, dict):
        takeovers, emergencies = iv.get("takeovers", []), iv.get("emergencies", [])
        head.add_row(
            "interventions",
            f"{len(takeovers)} takeovers ({iv.get('takeover_ticks', 0)} ticks), "
            f"{len(emergencies)} reflexive overrides ({iv.get('reflexive_ticks', 0)} ticks); "
            f"active modes {_counts(iv.get('active', {}))}",
        )
    if agreement.get("heading_ticks"):
        head.add_row(
            "agreement with the log",
            f"heading within 30 deg {100 * agreement['heading_within_30deg']:.0f} % "
            f"(median error {agreement['heading_err_median_deg']:.1f} deg), "
            f"speed MAE {agreement['speed_mae_mps']:.3f} m/s, "
            f"turn direction agrees {100 * agreement['turn_sign_agreement']:.0f} %",
        )
    if isinstance(health := data.get("matcher_health"), dict):
        head.add_row("scan matcher", _health_line(health))
    console.print(head)
    lat = Table(title="latency per tick (ms)", title_justify="left")
    for col in ("module", "median", "p90", "p99", "max"):
        lat.add_column(col, justify="left" if col == "module" else "right")
    for module, q in data["latency_ms"].items():  # type: ignore[attr-defined]
        if q:
            lat.add_row(module, *(f"{q[k]:.2f}" for k in ("median", "p90", "p99", "max")))
    console.print(lat)


def _health_line(h: dict[str, Any]) -> str:
    """summary.json's ``matcher_health`` in one line (the warning itself goes to stderr)."""
    n, failed = int(h.get("scans", 0)), int(h.get("failed", 0))
    share = _num(100.0 * failed / n if n else None, "{:.1f}")
    longest = _num((h.get("longest_without_match") or {}).get("duration_s"), "{:.1f}")
    window = h.get("worst_window") or {}
    span, sigmas = _num(window.get("window_s"), "{:g}"), _num(window.get("sigmas"), "{:.1f}")
    text = (f"{h.get('matcher')}: {failed} of {n} failed ({share} %), {longest} s at most without a match, "
            f"worst {span} s vs odometry {sigmas} sigma")
    if h.get("verdict") == "measured":
        ate, odom = _num(h.get("ate_matcher_m"), "{:.3f}"), _num(h.get("ate_odom_m"), "{:.3f}")
        text += f"; ATE {ate} m (odometry {odom})"
    return text + ("; warned" if h.get("warning") else "")


def _counts(counts: object) -> str:
    assert isinstance(counts, dict)
    return ", ".join(f"{k} {v}" for k, v in sorted(counts.items(), key=lambda kv: -kv[1]))


def main() -> None:
    """Console-script entry point."""
    try:
        app()
    except KeyboardInterrupt:  # outside a command (e.g. while importing)
        typer.echo("gndreplay: interrupted", err=True)
        sys.exit(EXIT_INTERRUPTED)

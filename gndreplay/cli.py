"""The ``gndreplay`` command line: parses options, calls one library function per command, prints.

Every command goes through :func:`cli_errors`, the single error boundary: a :class:`GndReplayError` becomes
one line ``gndreplay: error: <message>`` on stderr and exit code 2; Ctrl-C exits with 130. Anything else is a
bug and keeps its traceback. Heavy imports happen inside the commands so ``--help`` stays fast.
"""

from __future__ import annotations

import functools
import logging
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, ParamSpec, TypeVar

import typer

from . import __version__
from .errors import GndReplayError

__all__ = ["app", "cli_errors", "main"]

P = ParamSpec("P")
R = TypeVar("R")

EXIT_ERROR = 2
EXIT_INTERRUPTED = 130

app = typer.Typer(
    add_completion=False,
    rich_markup_mode="rich",
    no_args_is_help=True,
    help="Replay real robot logs (2D laser + odometry) through a GND / ND+ navigation stack.",
)

_LOG_PANEL = "Log reading"


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
        try:
            return fn(*args, **kwargs)
        except GndReplayError as err:
            message = " ".join(str(err).split()) or type(err).__name__
            typer.echo(f"gndreplay: error: {message}", err=True)
            raise typer.Exit(EXIT_ERROR) from None
        except KeyboardInterrupt:
            typer.echo("gndreplay: interrupted", err=True)
            raise typer.Exit(EXIT_INTERRUPTED) from None
        finally:
            logger.removeHandler(handler)

    return wrapper


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


# options shared by every command that reads a log
FormatOpt = Annotated[
    str | None,
    typer.Option(
        "--format",
        help="Log format instead of guessing from the path: carmen, rosbag1, rosbag2, mcap (or rosbag).",
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
        help="A malformed line or message is an error instead of being skipped and counted.",
        rich_help_panel=_LOG_PANEL,
    ),
]
LogArg = Annotated[
    Path,
    typer.Argument(
        help="CARMEN log (.clf/.log, plain/.gz/.bz2), ROS1 .bag, ROS2 bag folder or .mcap file.",
        show_default=False,
    ),
]


@app.command()
@cli_errors
def info(
    log: LogArg,
    fmt: FormatOpt = None,
    scan_topic: ScanTopicOpt = None,
    odom_topic: OdomTopicOpt = None,
    cmd_topic: CmdTopicOpt = None,
    truth_topic: TruthTopicOpt = None,
    strict: StrictOpt = False,
    json_out: Annotated[
        bool, typer.Option("--json", help="Print one JSON object instead of tables.")
    ] = False,
) -> None:
    """Show what a log contains (streams, rates, beams, range limits, odometry, gaps, malformed records).

    Format, start/end and duration, per-topic or per-message-type counts and rates, beams per scan, field
    of view, range limits, fraction of invalid / no-return beams, odometry source, time reversals, gaps and
    skipped malformed records. MCAP files are summarised from their index without decoding every message.

    [bold]Examples[/]

      gndreplay info mit-csail.clf.bz2

      gndreplay info run.bag --scan-topic /base_scan --json
    """
    from .info import log_info

    result = log_info(
        log,
        fmt=fmt,
        scan_topic=scan_topic,
        odom_topic=odom_topic,
        cmd_topic=cmd_topic,
        truth_topic=truth_topic,
        strict=strict,
    )
    if json_out:
        import json

        typer.echo(json.dumps(result.to_dict(), allow_nan=False))
        return
    _print_info(result)


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
    for col, justify in (
        ("stream", "left"),
        ("type", "left"),
        ("used as", "left"),
        ("count", "right"),
        ("rate", "right"),
    ):
        streams.add_column(col, justify=justify)  # type: ignore[arg-type]
    for row in stream_rows(result):
        streams.add_row(*row)
    console.print(streams)


def main() -> None:
    """Console-script entry point."""
    try:
        app()
    except KeyboardInterrupt:  # outside a command (e.g. while importing)
        typer.echo("gndreplay: interrupted", err=True)
        sys.exit(EXIT_INTERRUPTED)

"""One exception tree. Library code raises these; only ``cli.py`` turns them into a line and an exit code."""

from __future__ import annotations

import difflib
from collections.abc import Callable, Iterable
from typing import Any

__all__ = [
    "FOLLOW_NEEDS_SUBGOALS", "ConfigError", "GndReplayError", "LogFormatError", "OutputError",
    "ScanMatchError", "did_you_mean", "find_cause", "one_line",
]

FOLLOW_NEEDS_SUBGOALS = "navigation mode follow needs subgoals"
"""The one text of the "follow without subgoals" refusal (the stack, the replay, the scenario reader); each
caller adds where the subgoals come from (``f"{FOLLOW_NEEDS_SUBGOALS}: give --subgoals FILE ..."``)."""


class GndReplayError(Exception):
    """Root of every error gndreplay raises on purpose (bad input, bad config)."""


class LogFormatError(GndReplayError):
    """A log cannot be read: missing, unknown format, truncated, corrupt, or no scans.

    The message names the file and, when known, the line or record: ``"run3.clf line 42: ..."``.
    """


class ConfigError(GndReplayError):
    """A configuration file or option is invalid; the message names the key (and the file)."""


class ScanMatchError(GndReplayError):
    """A scan-matching setup error (not a failed match: a failed match is a value, see MatchResult)."""


class OutputError(GndReplayError):
    """An output path is unsafe to write (a file, the current folder, a folder holding inputs or files
    gndreplay did not write); the message names the path. Raised before any work is done."""


def one_line(err: BaseException | str, limit: int | None = None) -> str:
    """``err``'s text with its white space folded into single spaces and, past ``limit`` characters, its
    middle elided: a library's message may span lines or quote a whole input."""
    text = " ".join(str(err).split())
    if limit is None or len(text) <= limit:
        return text
    return f"{text[:limit - 20]}...{text[-17:]}"


def find_cause(err: BaseException, match: Callable[[BaseException], bool]) -> BaseException | None:
    """``err`` or the first exception along its chain of causes (``__cause__``, else the context unless
    suppressed) that ``match`` accepts, else None: a signal or a full disk met inside a library call may
    reach the caller wrapped, several deep."""
    seen: set[int] = set()
    e: BaseException | None = err
    while e is not None and id(e) not in seen:
        if match(e):
            return e
        seen.add(id(e))
        e = e.__cause__ if e.__cause__ is not None else (None if e.__suppress_context__ else e.__context__)
    return None


def did_you_mean(value: Any, choices: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` when ``value`` is a string close to one of ``choices``, else ``""``: the
    tail of a message refusing a misspelt name."""
    if not isinstance(value, str) or not value or len(value) > 100:
        return ""
    names = list(choices)
    within = [c for c in names if value.lower() in c]  # "icp" is kiss-icp more than idc
    close = within if len(within) == 1 else difflib.get_close_matches(value.lower(), names, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""

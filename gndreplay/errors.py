"""One exception tree. Library code raises these; only ``cli.py`` turns them into a line and an exit code."""

from __future__ import annotations

__all__ = [
    "FOLLOW_NEEDS_SUBGOALS", "ConfigError", "GndReplayError", "LogFormatError", "OutputError",
    "ScanMatchError",
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

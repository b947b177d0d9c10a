"""A log's scan clock: its median period and whether it was generated rather than recorded.

``gndreplay info`` reports it, and ``scanmatch --relations`` names it when the relations do not match the
log's stamps (relations are stamped on the recording's clock, which a generated clock has replaced).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..types import NS_PER_S

__all__ = ["fmt_ns", "scan_clock"]

#: A clock is synthetic when its first stamp is a multiple of this (a whole millisecond) and every scan
#: period is the same to the nanosecond (over at least ``_MIN_SYNTHETIC_SCANS`` scans): a recorded clock
#: jitters.
_ROUND_START_NS = 1_000_000
_MIN_SYNTHETIC_SCANS = 3


def fmt_ns(ns: int) -> str:
    """Nanoseconds as seconds with as many decimals as they need (up to nine)."""
    sign, ns = ("-", -ns) if ns < 0 else ("", ns)
    return f"{sign}{ns // NS_PER_S}.{ns % NS_PER_S:09d}".rstrip("0").rstrip(".")


def scan_clock(stamps: ArrayLike) -> tuple[float | None, str | None]:
    """The median period of the scan ``stamps`` [s] (int ns, any order; None under two) and a warning when
    the clock is synthetic: every period the same to the nanosecond from a round start (a whole
    millisecond), as a generator or a converter writes them; a recorded clock jitters."""
    t = np.sort(np.asarray(stamps, dtype=np.int64))
    if t.size < 2:
        return None, None
    periods = np.diff(t)
    median = float(np.median(periods)) / NS_PER_S
    period = int(periods[0])
    synthetic = (t.size >= _MIN_SYNTHETIC_SCANS and period > 0 and int(t[0]) % _ROUND_START_NS == 0
                 and bool(np.all(periods == period)))
    if not synthetic:
        return median, None
    return median, (f"synthetic clock: all {t.size} scan stamps are exactly {fmt_ns(period)} s apart from "
                    f"a round start ({fmt_ns(int(t[0]))} s): generated, not recorded, so the rate and the "
                    "gaps describe the generator, not the sensor")

"""Every kernel a replay uses is compiled (or loaded from numba's cache) by the warm-up, before the first
timed tick: no numba dispatcher of gndreplay gains a signature during the replay itself (a kernel first
compiled inside a tick costs that tick hundreds of milliseconds on a cold cache)."""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import pytest
from numba.core.registry import CPUDispatcher

from gndreplay.config import CliOverrides, configure
from gndreplay.io import ReadOptions
from gndreplay.replay import RunOptions, run_log, warm_up_all

SAMPLE_LOG = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"


def _signatures() -> dict[str, int]:
    """Compiled signatures per numba dispatcher of every loaded gndreplay module."""
    out: dict[str, int] = {}
    for name, module in list(sys.modules.items()):
        if not name.startswith("gndreplay") or module is None:
            continue
        for attr, value in vars(module).items():
            if isinstance(value, CPUDispatcher):
                out[f"{name}.{attr}"] = len(value.signatures)
    return out


@pytest.mark.parametrize(("preset", "planner"), [("wheelchair", "nf1"), ("wheelchair", "tunnel"),
                                                 ("xr4000", "nf1"), ("compact", "nf1")])
def test_a_replay_compiles_nothing_after_the_warm_up(preset: str, planner: str) -> None:
    cfg = configure(preset_name=preset, overrides=CliOverrides(planner=planner))
    warm_up_all(cfg)
    before = _signatures()
    with tempfile.TemporaryDirectory() as tmp:
        run_log(SAMPLE_LOG, cfg, Path(tmp) / "run", options=RunOptions(), read=ReadOptions())
    after = _signatures()
    assert len(before) > 20
    grown = {k: (before.get(k, 0), n) for k, n in after.items() if n > before.get(k, 0)}
    assert grown == {}, f"compiled during the replay, not by the warm-up: {grown}"

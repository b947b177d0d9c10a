"""First run after install: every numba kernel is compiled (or loaded) by the warm-up, before the first timed
tick, so no tick reports JIT time as planner or model time.

The check runs in a fresh interpreter with an empty NUMBA_CACHE_DIR (a cold cache, as after install): it
snapshots the compiled signatures of every numba dispatcher in gndreplay when ``run_replay`` announces the
"replay" stage (warm-up done) and compares them after the run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "office.clf.bz2"

PROBE = textwrap.dedent(
    """
    import importlib, json, pkgutil, sys
    from pathlib import Path

    from numba.core.dispatcher import Dispatcher

    import gndreplay
    from gndreplay.config import PRESETS
    from gndreplay.replay import RunOptions, run_log

    def dispatchers():
        found = {}
        for info in pkgutil.walk_packages(gndreplay.__path__, "gndreplay."):
            mod = sys.modules.get(info.name)
            if mod is None:
                continue
            for name, obj in vars(mod).items():
                if isinstance(obj, Dispatcher):
                    found[f"{info.name}.{name}"] = obj
        return found

    log, out, until, preset = sys.argv[1], Path(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
    before = {}
    compiled_in_warm_up = []

    def on_stage(stage):
        if stage == "replay":
            before.update({k: len(d.signatures) for k, d in dispatchers().items()})

    run_log(Path(log), PRESETS[preset], out, options=RunOptions(until_s=until), on_stage=on_stage,
            on_compile=compiled_in_warm_up.append)
    after = {k: len(d.signatures) for k, d in dispatchers().items()}
    late = {k: [before.get(k, 0), n] for k, n in after.items() if n != before.get(k, 0)}
    print(json.dumps({"late": late, "kernels": len(after), "compiled_in_warm_up": len(compiled_in_warm_up)}))
    """
)


def first_run(
    log: Path, out: Path, cache: Path | None, until_s: float, preset: str = "wheelchair"
) -> dict[str, object]:
    """Replay ``log`` in a fresh interpreter with the numba cache at ``cache`` (None: numba's default, next
    to the sources); the probe's findings."""
    env = {**os.environ, "MPLBACKEND": "Agg"}
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    proc = subprocess.run(
        [sys.executable, "-c", PROBE, str(log), str(out), str(until_s), preset],
        env=env, capture_output=True, text=True, timeout=900, check=False,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    result: dict[str, object] = json.loads(proc.stdout.strip().splitlines()[-1])
    return result


def test_no_kernel_compiles_after_the_warm_up_on_a_cold_cache(tmp_path: Path) -> None:
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    found = first_run(SAMPLE, tmp_path / "run", cache, until_s=20.0)
    assert found["kernels"] and int(str(found["kernels"])) > 10  # the probe saw gndreplay's kernels
    assert int(str(found["compiled_in_warm_up"])) > 10  # the cache was cold: the warm-up compiled them
    assert found["late"] == {}, f"kernels compiled during timed ticks: {found['late']}"
    assert any(cache.rglob("*.nbi")), "kernels are cached on disk (cache=True)"


@pytest.mark.slow
def test_no_kernel_compiles_after_the_warm_up_on_mit_csail(datasets: Path, tmp_path: Path) -> None:
    """The first minute of MIT CSAIL reaches the planner's escape (``nf1._line_cells``: 538 ms at tick 49
    before it was in the warm-up). Whether the cache is warm does not matter: a kernel loaded from it after
    the warm-up adds a signature too."""
    found = first_run(datasets / "carmen" / "mit-csail.clf.bz2", tmp_path / "run", None, until_s=60.0)
    assert found["late"] == {}, f"kernels compiled during timed ticks: {found['late']}"

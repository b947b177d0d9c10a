"""Shared fixtures: the real logs in ../shared/datasets (tests skip cleanly when absent), a dask cluster."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

DATASETS = Path(__file__).resolve().parents[1].parent / "shared" / "datasets"


@pytest.fixture(scope="session")
def datasets() -> Path:
    """Path of ../shared/datasets; skips the test when the folder is not there."""
    if not DATASETS.is_dir():
        pytest.skip(f"real logs not available ({DATASETS})")
    return DATASETS


@pytest.fixture(scope="session")
def dask_cluster() -> Any:
    """A dask.distributed LocalCluster of two single-threaded worker processes (skipped without dask)."""
    distributed = pytest.importorskip("distributed")
    # ":0": any free port for the scheduler's HTTP server (None still binds the fixed 8787, and a second
    # test run on the same machine then fails to start its cluster)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        yield cluster

"""Shared fixtures: the real logs in ../shared/datasets (tests skip cleanly when absent)."""

from __future__ import annotations

from pathlib import Path

import pytest

DATASETS = Path(__file__).resolve().parents[1].parent / "shared" / "datasets"


@pytest.fixture(scope="session")
def datasets() -> Path:
    """Path of ../shared/datasets; skips the test when the folder is not there."""
    if not DATASETS.is_dir():
        pytest.skip(f"real logs not available ({DATASETS})")
    return DATASETS

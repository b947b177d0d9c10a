"""Shards of a batch: ``--shard I/N`` runs a deterministic 1/N of the inputs, so N machines (CI jobs, a
Kubernetes Indexed Job, an AWS Batch array job) share one batch; ``gndreplay batch --merge`` puts the shard
folders back together.

The rule: over the batch's expanded, ordered input list (a scenario: one entry per scenario and seed, as
``expand_inputs`` orders them), shard I of N runs the inputs of index i with ``i % N == I`` (0-based).
It is a pure function of that list, the same on every machine; round robin spreads the seeds of a
scenario and the inputs of one folder over the shards. ``--shard N`` takes I from the environment:
``JOB_COMPLETION_INDEX`` (Kubernetes Indexed Job) or ``AWS_BATCH_JOB_ARRAY_INDEX`` (AWS Batch array job).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

from ..errors import ConfigError
from ..io.userfile import brief

__all__ = ["INDEX_ENV_VARS", "MAX_SHARDS", "Shard", "parse_shard", "shard_indices"]

#: Environment variables giving a shard's index when ``--shard N`` gives only the count, in the order read.
INDEX_ENV_VARS: tuple[str, ...] = ("JOB_COMPLETION_INDEX", "AWS_BATCH_JOB_ARRAY_INDEX")
#: Most shards one batch may be split into (Kubernetes allows 100,000 completions, AWS Batch 10,000).
MAX_SHARDS = 100_000
_SHARD = re.compile(r"(?:([0-9]{1,9})/)?([0-9]{1,9})")
_INDEX = re.compile(r"[0-9]{1,9}")


@dataclass(frozen=True, slots=True)
class Shard:
    """Shard ``index`` (0-based) of ``count``: the inputs of index i with ``i % count == index``."""

    index: int
    count: int

    def __post_init__(self) -> None:
        if not 1 <= self.count <= MAX_SHARDS:
            raise ConfigError(f"--shard: the number of shards must be 1 to {MAX_SHARDS}, got {self.count}")
        if not 0 <= self.index < self.count:
            raise ConfigError(
                f"--shard: index {self.index} is out of range for {self.count} shards (0 to {self.count - 1})"
            )

    def __str__(self) -> str:
        return f"{self.index}/{self.count}"


def shard_indices(total: int, shard: Shard | None) -> list[int]:
    """The indices into a batch of ``total`` inputs that ``shard`` runs, ascending (None: all of them)."""
    if shard is None:
        return list(range(total))
    return list(range(shard.index, total, shard.count))


def parse_shard(text: str, env: Mapping[str, str]) -> Shard:
    """``--shard I/N`` (shard I of N, 0-based) or ``--shard N`` (the index from ``env``: the first of
    ``INDEX_ENV_VARS`` that is set; both set must agree).

    Raises:
        ConfigError: not ``I/N`` or ``N``; N < 1 or above ``MAX_SHARDS``; I out of range; for ``N`` alone,
            no index variable set, or one that is not a non-negative integer, or two that disagree.
    """
    m = _SHARD.fullmatch(text.strip())
    if m is None:
        raise ConfigError(
            f"--shard: expected I/N (shard I of N, from 0) or N (I from {' or '.join(INDEX_ENV_VARS)}), "
            f"got {brief(text)}"
        )
    count = int(m.group(2))
    if not 1 <= count <= MAX_SHARDS:
        raise ConfigError(f"--shard: the number of shards must be 1 to {MAX_SHARDS}, got {count}")
    if m.group(1) is not None:
        return Shard(int(m.group(1)), count)
    given = {name: env[name].strip() for name in INDEX_ENV_VARS if env.get(name, "").strip()}
    if not given:
        raise ConfigError(
            f"--shard {count}: the shard index comes from {' or '.join(INDEX_ENV_VARS)} (a Kubernetes "
            f"Indexed Job, an AWS Batch array job) and neither is set; give --shard I/{count}"
        )
    for name, value in given.items():
        if _INDEX.fullmatch(value) is None:
            raise ConfigError(f"--shard {count}: {name}={brief(value)} is not a shard index (0, 1, ...)")
    if len({int(v) for v in given.values()}) > 1:
        shown = ", ".join(f"{k}={v}" for k, v in given.items())
        raise ConfigError(f"--shard {count}: {shown} disagree; give --shard I/{count}")
    name, value = next(iter(given.items()))
    index = int(value)
    if index >= count:
        raise ConfigError(
            f"--shard {count}: {name}={index} is out of range for {count} shards (0 to {count - 1}); "
            f"--shard must give the job's number of completions / array size"
        )
    return Shard(index, count)

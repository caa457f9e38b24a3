"""Splitting work across jobs: the ``--shard`` spec of ``spacedg export`` and ``spacedg qa build``.

A shard is ``(i, n)`` with ``0 <= i < n``: job ``i`` of ``n`` takes the work items ``k`` with
``k % n == i`` (export: chunks of items; qa build: scene folders in sorted order), so every job
computes the same list and the jobs together cover it once. ``--shard i/n`` names it; ``--shard
env`` reads it from the launcher (:func:`shard_from_env`). This module imports nothing heavy (no
torch), so commands that only need the spec stay fast to start.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from spacedg.errors import ParameterError

__all__ = ["chunk_ids", "parse_shard", "resolve_shard", "shard_from_env"]


def parse_shard(text: str) -> tuple[int, int]:
    """``"i/n"`` → ``(i, n)`` with ``0 <= i < n``; a :class:`ParameterError` otherwise."""
    try:
        i_text, n_text = str(text).split("/")
        i, n = int(i_text), int(n_text)
    except ValueError:
        raise ParameterError(f"--shard must read i/n with integers 0 <= i < n (e.g. 0/4), or 'env'; got {text!r}") from None
    if n < 1 or not 0 <= i < n:
        m = max(n, 1)
        raise ParameterError(f"--shard {text}: need 0 <= i < n (shards of n={m} are 0/{m} … {m - 1}/{m})")
    return i, n


def shard_from_env(environ: Mapping[str, str]) -> tuple[int, int]:
    """``(i, n)`` from a launcher's environment: ``RANK``/``WORLD_SIZE`` (torchrun, accelerate,
    deepspeed), ``SLURM_ARRAY_TASK_ID``/``SLURM_ARRAY_TASK_COUNT`` (a job array starting at
    ``SLURM_ARRAY_TASK_MIN``, default 0), or ``SLURM_PROCID``/``SLURM_NTASKS`` (``srun``)."""
    pairs = (("RANK", "WORLD_SIZE"), ("SLURM_ARRAY_TASK_ID", "SLURM_ARRAY_TASK_COUNT"), ("SLURM_PROCID", "SLURM_NTASKS"))
    for rank_key, size_key in pairs:
        if rank_key in environ and size_key in environ:
            try:
                rank = int(environ[rank_key]) - (int(environ.get("SLURM_ARRAY_TASK_MIN", "0")) if rank_key.startswith("SLURM_ARRAY") else 0)
            except ValueError:
                raise ParameterError(f"--shard env: {rank_key}={environ[rank_key]!r} is not an integer") from None
            return parse_shard(f"{rank}/{environ[size_key]}")
    names = ", ".join(f"{a}/{b}" for a, b in pairs)
    raise ParameterError(f"--shard env: none of {names} is set; pass --shard i/n explicitly")


def chunk_ids(total_items: int, shard_size: int, shard: tuple[int, int] = (0, 1)) -> list[int]:
    """The chunks of an export of ``total_items`` items that ``shard=(i, n)`` owns (``k % n == i``)."""
    if isinstance(shard_size, bool) or not isinstance(shard_size, int) or shard_size < 1:
        raise ParameterError(f"shard_size must be an integer >= 1, got {shard_size!r}")
    i, n = shard
    if n < 1 or not 0 <= i < n:
        raise ParameterError(f"shard must be (i, n) with 0 <= i < n, got {shard!r}")
    return [k for k in range(math.ceil(total_items / shard_size)) if k % n == i]


def resolve_shard(text: str, environ: Mapping[str, str]) -> tuple[int, int]:
    """A ``--shard`` argument: ``"env"`` (any case, spaces ignored) → :func:`shard_from_env`, else :func:`parse_shard`."""
    return shard_from_env(environ) if str(text).strip().lower() == "env" else parse_shard(text)

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
    if n < 1:
        raise ParameterError(f"--shard {text}: the number of shards n must be at least 1 (e.g. 0/4 … 3/4 for four jobs)")
    if not 0 <= i < n:
        raise ParameterError(f"--shard {text}: need 0 <= i < n (shards of n={n} are 0/{n} … {n - 1}/{n})")
    return i, n


#: The launchers :func:`shard_from_env` reads, in this order: (rank variable, size variable).
ENV_PAIRS = (("RANK", "WORLD_SIZE"), ("SLURM_ARRAY_TASK_ID", "SLURM_ARRAY_TASK_COUNT"), ("SLURM_PROCID", "SLURM_NTASKS"))


def shard_from_env(environ: Mapping[str, str]) -> tuple[int, int]:
    """``(i, n)`` from a launcher's environment: ``RANK``/``WORLD_SIZE`` (torchrun, accelerate,
    deepspeed), ``SLURM_ARRAY_TASK_ID``/``SLURM_ARRAY_TASK_COUNT`` (a job array: task ids from
    ``SLURM_ARRAY_TASK_MIN``, default 0, every ``SLURM_ARRAY_TASK_STEP``, default 1, so
    ``--array=0-15:4`` is shards 0/4 … 3/4; ids that are not evenly spaced up to ``SLURM_ARRAY_TASK_MAX``,
    such as a resubmission of some tasks, are refused), or ``SLURM_PROCID``/``SLURM_NTASKS`` (``srun``).

    The first launcher whose two variables are both set decides. When none is, one variable of a pair
    set alone is a :class:`ParameterError` naming the other; so is a value that is not an integer or a
    task id off the array's steps."""
    for rank_key, size_key in ENV_PAIRS:
        if rank_key in environ and size_key in environ:
            size = _env_int(environ, size_key)
            rank = _array_position(environ, size) if rank_key == "SLURM_ARRAY_TASK_ID" else _env_int(environ, rank_key)
            return parse_shard(f"{rank}/{size}")
    for rank_key, size_key in ENV_PAIRS:  # no whole pair: one set alone is a launcher half configured
        if rank_key in environ or size_key in environ:
            have, missing = (rank_key, size_key) if rank_key in environ else (size_key, rank_key)
            raise ParameterError(f"--shard env: {have} is set but {missing} is not; set both, or pass --shard i/n explicitly")
    names = ", ".join(f"{a}/{b}" for a, b in ENV_PAIRS)
    raise ParameterError(f"--shard env: none of {names} is set; pass --shard i/n explicitly")


def _array_position(environ: Mapping[str, str], size: int) -> int:
    """This task's position in a SLURM job array of ``size`` tasks whose ids run from
    ``SLURM_ARRAY_TASK_MIN`` (default 0) in steps of ``SLURM_ARRAY_TASK_STEP`` (default 1) to
    ``SLURM_ARRAY_TASK_MAX``; a :class:`ParameterError` when the ids are not evenly spaced so."""
    task, first = _env_int(environ, "SLURM_ARRAY_TASK_ID"), _env_int(environ, "SLURM_ARRAY_TASK_MIN", 0)
    step = _env_int(environ, "SLURM_ARRAY_TASK_STEP", 1)
    last = _env_int(environ, "SLURM_ARRAY_TASK_MAX", first + (size - 1) * max(step, 1))
    if step < 1 or (task - first) % step != 0 or last - first != (size - 1) * step:
        raise ParameterError(
            f"--shard env: the job array's task ids are not evenly spaced from SLURM_ARRAY_TASK_MIN={first} by "
            f"SLURM_ARRAY_TASK_STEP={step} to SLURM_ARRAY_TASK_MAX={last} over SLURM_ARRAY_TASK_COUNT={size} tasks "
            f"(this one SLURM_ARRAY_TASK_ID={task}), so they cannot name their shares (a resubmission of some tasks, "
            f"e.g. --array=5,17, is such an array); pass --shard i/n explicitly, e.g. --shard ${{SLURM_ARRAY_TASK_ID}}/32 "
            f"for the shares of the original --array=0-31")
    return (task - first) // step


def _env_int(environ: Mapping[str, str], key: str, default: int | None = None) -> int:
    """The integer value of the launcher variable ``key`` (``default`` when it is not set)."""
    if key not in environ and default is not None:
        return default
    try:
        return int(environ[key])
    except ValueError:
        raise ParameterError(f"--shard env: {key}={environ[key]!r} is not an integer") from None


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

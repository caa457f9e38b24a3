"""``spacedg kernels [--jobs N] [--group NAME]``: compile the CPU kernels into numba's on-disk cache.

Run it once after installing (or after an upgrade) on a machine that will start several processes
at once — DataLoader workers, a job array on a shared file system, ``qa build --jobs`` — so that
they load the compiled kernels instead of each compiling them (:mod:`spacedg.data.kernel_warmup`
says which, and why it matters). Each group runs in a process of its own, ``--jobs`` of them at a
time; a kernel the cache already holds is loaded, not compiled, so a second run takes seconds.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from spacedg.commands import _args


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``kernels`` subcommand on ``subparsers``."""
    from spacedg.data.kernel_warmup import GROUPS

    parser = _args.add_command(subparsers, "kernels", run, help="compile the CPU kernels into numba's cache (once per install)")
    parser.add_argument("--jobs", type=_args.whole(1), default=None,
                        help="groups compiled at once, one process each (default: one per group, at most the cores this process may use)")
    parser.add_argument("--group", choices=list(GROUPS), default=None,
                        help="compile only this group, in this process (--jobs does not apply)")
    return parser


def run(args: argparse.Namespace) -> int:
    """Compile spacedg's CPU kernels into numba's on-disk cache, so that the processes started later
    (DataLoader workers, a job array, qa build --jobs) load them instead of each compiling them
    again at the same time. Run it once per install; kernels the cache holds load in seconds."""
    from spacedg.data.kernel_warmup import GROUPS, warm
    from spacedg.data.workers import pool_plan

    if args.group is not None:
        print(f"spacedg kernels: {args.group} in {warm(args.group):.1f} s", flush=True)
        return 0
    plan = pool_plan(len(GROUPS), jobs=args.jobs)
    t0 = time.perf_counter()

    def run_group(group: str) -> int:
        return subprocess.run([sys.executable, "-m", "spacedg", "kernels", "--group", group], check=False).returncode

    with ThreadPoolExecutor(plan.processes) as pool:
        codes = dict(zip(GROUPS, pool.map(run_group, GROUPS)))
    failed = [group for group, code in codes.items() if code != 0]
    if failed:
        print(f"spacedg kernels: the group(s) {', '.join(failed)} failed (the error is above); "
              f"'spacedg kernels --group {failed[0]}' runs one alone", file=sys.stderr, flush=True)
        return 1
    print(f"spacedg kernels: {len(GROUPS)} groups in {time.perf_counter() - t0:.1f} s ({plan.processes} at a time)", flush=True)
    return 0

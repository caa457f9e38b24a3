"""``spacedg kernels [--jobs N] [--group NAME]``: compile the CPU kernels into numba's on-disk cache.

Run it once after installing (or after an upgrade) on a machine that will start several processes
at once — DataLoader workers, a job array on a shared file system, ``qa build --jobs`` — so that
they load the compiled kernels instead of each compiling them (:mod:`spacedg.data.kernel_warmup`
says which, and why it matters). Each group runs in a process of its own, ``--jobs`` of them at a
time; a kernel the cache already holds is loaded, not compiled, so a second run takes seconds.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from typing import Any

from spacedg.commands import _args
from spacedg.errors import SpaceDGError


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``kernels`` subcommand on ``subparsers``."""
    from spacedg.data.kernel_warmup import GROUPS

    parser = _args.add_command(subparsers, "kernels", run, help="compile the CPU kernels into numba's cache (once per install)")
    parser.add_argument("--jobs", type=_args.whole(1), default=None,
                        help="groups compiled at once, one process each (default: one per group, at most the cores)")
    parser.add_argument("--group", choices=list(GROUPS), default=None,
                        help="compile only this group, in this process")
    return parser


def run(args: argparse.Namespace) -> int:
    """Compile spacedg's CPU kernels into numba's on-disk cache, so that the processes started later
    (DataLoader workers, a job array, qa build --jobs) load them instead of each compiling them
    again at the same time. Run it once per install; kernels the cache holds load in seconds."""
    from spacedg.data.kernel_warmup import GROUPS, warm

    if args.group is not None:
        print(f"spacedg kernels: {args.group} in {warm(args.group):.1f} s", flush=True)
        return 0
    jobs = args.jobs or max(1, min(len(GROUPS), os.cpu_count() or 1))
    t0 = time.perf_counter()
    pending = list(GROUPS)
    running: list[tuple[str, subprocess.Popen[bytes]]] = []
    failed: list[str] = []
    while pending or running:
        while pending and len(running) < jobs:
            group = pending.pop(0)
            running.append((group, subprocess.Popen([sys.executable, "-m", "spacedg", "kernels", "--group", group])))
        group, process = running.pop(0)
        if process.wait() != 0:
            failed.append(group)
    if failed:
        raise SpaceDGError(f"spacedg kernels: the group(s) {', '.join(failed)} failed (their error is above); "
                           f"run 'spacedg kernels --group {failed[0]}' to see it alone")
    print(f"spacedg kernels: {len(GROUPS)} groups in {time.perf_counter() - t0:.1f} s ({jobs} at a time)", flush=True)
    return 0

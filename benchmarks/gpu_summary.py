"""The summary of ``benchmarks/gpu_check.sh``: one row per step, then the README GPU table's numbers.

    python benchmarks/gpu_summary.py STEPS_TSV LOG_DIR TOTAL_SECONDS

``STEPS_TSV`` has one line per step: name, status, exit code, seconds, timeout. The numbers are
read from the step logs: ``render.log`` (``benchmarks/render.py --device``'s table: ours gsplat,
gsplat own, ratio, ours torch, ours cpu per size), ``dataset.log`` (ms per bench question on the
device and on the CPU path) and ``setup.log`` (the card).
"""

from __future__ import annotations

import re
import sys
from pathlib import Path


def read(path: Path) -> str:
    return path.read_text(errors="replace") if path.is_file() else ""


def card(setup_log: str) -> str:
    match = re.search(r"cuda available True, ([^,]+), (\d+) GiB", setup_log)
    return f"{match.group(1)} ({match.group(2)} GiB)" if match else "no CUDA device seen"


def render_rows(log: str) -> dict[str, list[str]]:
    """``{"100k": [visible, ours, own, ratio, torch, cpu, ...]}`` from the device render table."""
    rows = {}
    for line in log.splitlines():
        parts = line.split()
        if len(parts) >= 8 and parts[0] == "random" and parts[1].endswith("k"):
            rows[parts[1]] = parts[2:]
    return rows


def dataset_rows(log: str) -> dict[str, str]:
    """``{"device": ms, "cpu": ms}`` per bench question."""
    rows = {}
    for line in log.splitlines():
        match = re.match(r"(device \S+|cpu \(compiled \+ numpy\))\s+([\d.]+)\s", line)
        if match:
            rows["cpu" if match.group(1).startswith("cpu") else "device"] = match.group(2)
    return rows


def tests_line(log: str) -> str:
    found = re.findall(r"^=*\s*(\d+ (?:passed|failed|skipped|error).*?) in [\d.]+s", log, flags=re.M)
    return found[-1] if found else ""


def failure_line(log: str) -> str:
    """The last line of a failed step's log that names an error, else its last non-empty line (100 chars)."""
    lines = [line.strip() for line in log.splitlines() if line.strip() and not set(line.strip()) <= set("=-")]
    named = [line for line in lines if re.search(r"Error|error:|FAILED|assert|Traceback|Killed", line)]
    return (named or lines or [""])[-1][:100]


def main(steps_tsv: str, log_dir: str, total: str) -> None:
    logs = Path(log_dir)
    lines = ["", "SUMMARY (benchmarks/gpu_check.sh)", f"{'step':<13} {'status':<8} {'rc':>4} {'s':>5} {'limit':>5}  note", "-" * 72]
    for raw in Path(steps_tsv).read_text().splitlines():
        name, status, rc, secs, limit = raw.split("\t")
        note = tests_line(read(logs / f"{name}.log")) if name.startswith("test_") else ""
        if status not in ("ok", "skipped") and not note:
            note = failure_line(read(logs / f"{name}.log"))
        lines.append(f"{name:<13} {status:<8} {rc:>4} {secs:>5} {limit:>5}  {note}")
    lines.append(f"total {total} s")
    setup = read(logs / "setup.log")
    rows, bench = render_rows(read(logs / "render.log")), dataset_rows(read(logs / "dataset.log"))
    lines += ["", f"README GPU table (640x480), card: {card(setup)}"]
    for size in ("100k", "1000k"):
        r = rows.get(size)
        if r:
            lines.append(f"  {size:>5} Gaussians: ours (gsplat) {r[1]} ms / gsplat.rasterization() {r[2]} ms = {r[3]}x (goal <= 1.2); "
                         f"ours torch on CUDA {r[4]} ms; our CPU path {r[5]} ms; visible {r[0]}")
        else:
            lines.append(f"  {size:>5} Gaussians: not measured (see render.log)")
    if bench:
        lines.append(f"  bench question (clean + nine, 10 items, 30k-Gaussian rooms): {bench.get('device', '?')} ms on the device "
                     f"(goal <= 30 ms); CPU path {bench.get('cpu', '?')} ms")
    else:
        lines.append("  bench question: not measured (see dataset.log)")
    print("\n".join(lines))


if __name__ == "__main__":
    main(*sys.argv[1:4])

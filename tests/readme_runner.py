"""Run the code blocks of the README and the docs pages in order, as a reader would, and report each block's outcome.

``python -m tests.readme_runner README.md [docs/PAGE.md …] WORKDIR`` executes every
```` ```bash ```` and ```` ```python ```` block of each Markdown file top to bottom, file after
file, inside one ``WORKDIR`` (shell blocks with ``bash -euo pipefail``; the Python blocks of one
file in one persistent namespace, so a block may use what an earlier block of the same file
defined, as a reader's session would; each file starts a fresh namespace but sees the files the
earlier ones wrote, e.g. the README's ``runs/demo``), and prints one JSON line per block:
``{"file", "line", "lang", "status", "seconds", "output"}`` with status ``ok``, ``failed``,
``skipped`` (with the reason) or ``not-run`` (an earlier block of the same file failed).

A block may be preceded by one directive comment, on the line just before its fence:

- ``<!-- readme-test: skip REASON -->``: not run (the reason is reported; e.g. the test suite itself);
- ``<!-- readme-test: file NAME -->``: the block is a file's content; it is written to ``NAME``;
- ``<!-- readme-test: server PATTERN -->``: a long-running command (a web server): started, it
  must print a line matching the regular expression ``PATTERN`` within 120 s; the block then
  counts as ok and the process is stopped;
- ``<!-- readme-test: hub MODEL -->``: the block needs model weights from the Hugging Face hub,
  which tests cannot download: it is run offline (``HF_HUB_OFFLINE=1``) and must fail only when
  loading ``MODEL`` (its output names ``MODEL`` and shows no Python traceback), which proves
  everything before the model load works;
- ``<!-- readme-test: gpu -->``: needs a CUDA device; run only where torch sees one, else skipped.

``pip install`` in a shell block installs into ``WORKDIR/site`` (``PIP_TARGET``, no dependency
resolution), which is on ``PYTHONPATH``: the README's commands never change the environment
that runs them.
"""

from __future__ import annotations

import io
import json
import os
import re
import subprocess
import sys
import time
import traceback
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Block", "read_blocks", "run_blocks", "run_files"]

_FENCE = re.compile(r"^```(\w*)\s*$")
_DIRECTIVE = re.compile(r"^<!--\s*readme-test:\s*(\w+)\s*(.*?)\s*-->\s*$")
_KINDS = ("skip", "file", "server", "hub", "gpu")
_OUTPUT_TAIL = 4000


@dataclass(frozen=True)
class Block:
    """One fenced code block: its first line number (1-based, the fence), language, code, directive
    and the Markdown file it comes from (as given to :func:`read_blocks`)."""

    line: int
    lang: str
    code: str
    directive: str = ""
    argument: str = ""
    source: str = "README.md"


def read_blocks(markdown: str, source: str = "README.md") -> list[Block]:
    """The ``bash``/``sh``/``python`` blocks of ``markdown`` (the text of the file named ``source``)
    in order (other languages are prose: TOML, YAML, plain text)."""
    blocks: list[Block] = []
    lines = markdown.splitlines()
    i = 0
    while i < len(lines):
        match = _FENCE.match(lines[i])
        if not match:
            i += 1
            continue
        start, lang = i, match.group(1).lower()
        i += 1
        body: list[str] = []
        while i < len(lines) and not lines[i].startswith("```"):
            body.append(lines[i])
            i += 1
        i += 1
        directive = _DIRECTIVE.match(lines[start - 1]) if start > 0 else None
        kind, argument = (directive.group(1), directive.group(2)) if directive else ("", "")
        if kind and kind not in _KINDS:
            raise ValueError(f"{source} line {start}: unknown readme-test directive {kind!r}; use one of {_KINDS}")
        if lang in ("bash", "sh", "shell", "python"):
            code = "\n".join(body) + "\n"
            blocks.append(Block(start + 1, "python" if lang == "python" else "bash", code, kind, argument, source))
    return blocks


def _environment(workdir: Path, offline_hub: bool) -> dict[str, str]:
    env = dict(os.environ)
    site = workdir / "site"
    site.mkdir(exist_ok=True)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join([str(site), str(workdir), *filter(None, [env.get("PYTHONPATH")])])
    # PIP_NO_BUILD_ISOLATION=0 means "--no-build-isolation" (pip reads negated options inverted)
    env.update(PIP_TARGET=str(site), PIP_NO_DEPS="1", PIP_DISABLE_PIP_VERSION_CHECK="1", PIP_NO_INDEX="1", PIP_NO_BUILD_ISOLATION="0",
               PYTHONUNBUFFERED="1", MPLBACKEND="Agg")
    if offline_hub:
        env.update(HF_HUB_OFFLINE="1", TRANSFORMERS_OFFLINE="1")
    return env


def _tail(text: str) -> str:
    return text[-_OUTPUT_TAIL:]


def _run_shell(block: Block, workdir: Path, timeout: float) -> tuple[bool, str]:
    env = _environment(workdir, offline_hub=block.directive == "hub")
    script = "set -euo pipefail\n" + block.code
    if block.directive == "server":
        return _run_server(script, block.argument, workdir, env)
    proc = subprocess.run(["bash", "-c", script], cwd=workdir, env=env, capture_output=True, text=True, timeout=timeout)
    output = proc.stdout + proc.stderr
    if block.directive == "hub":
        model = block.argument
        ok = proc.returncode != 0 and model in output and "Traceback (most recent call last)" not in output
        return ok, f"(expected to stop at loading {model} offline, with one clear error)\n{output}"
    return proc.returncode == 0, output


def _run_server(script: str, pattern: str, workdir: Path, env: dict[str, str]) -> tuple[bool, str]:
    proc = subprocess.Popen(["bash", "-c", "exec " + script.split("\n", 1)[1].strip()], cwd=workdir, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    deadline = time.monotonic() + 120
    ok = False
    try:
        assert proc.stdout is not None
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if re.search(pattern, line):
                ok = True
                break
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
    return ok, "".join(lines)


def _run_python(block: Block, namespace: dict[str, object]) -> tuple[bool, str]:
    buffer = io.StringIO()
    try:
        with redirect_stdout(buffer), redirect_stderr(buffer):
            exec(compile(block.code, f"{block.source}:{block.line}", "exec"), namespace)  # noqa: S102 - the README is ours
    except BaseException:  # noqa: BLE001 - report any failure of the block
        return False, buffer.getvalue() + traceback.format_exc()
    return True, buffer.getvalue()


def _cuda() -> bool:
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a dependency
        return False
    return bool(torch.cuda.is_available())


def _prepare(workdir: Path) -> None:
    """Run from ``workdir`` with its ``site/`` (the README's ``pip install`` target) importable."""
    os.chdir(workdir)
    os.environ.update({k: v for k, v in _environment(workdir, offline_hub=False).items() if k.startswith(("PIP_", "PYTHON"))})
    sys.path[:0] = [str(workdir / "site"), str(workdir)]


def _run_one(block: Block, workdir: Path, namespace: dict[str, object], timeout: float) -> dict[str, object]:
    """Run one block (its directive decides how) and return its result dict."""
    result: dict[str, object] = {"file": block.source, "line": block.line, "lang": block.lang, "seconds": 0.0, "output": ""}
    if block.directive == "skip":
        return {**result, "status": "skipped", "output": block.argument}
    if block.directive == "gpu" and not _cuda():
        return {**result, "status": "skipped", "output": "needs a CUDA device (none here)"}
    if block.directive == "file":
        (workdir / block.argument).write_text(block.code)
        return {**result, "status": "ok", "output": f"wrote {block.argument}"}
    start = time.perf_counter()
    if block.lang == "python":
        ok, output = _run_python(block, namespace)
    else:
        try:
            ok, output = _run_shell(block, workdir, timeout)
        except subprocess.TimeoutExpired as err:
            ok, output = False, f"timed out after {err.timeout} s"
    return {**result, "status": "ok" if ok else "failed", "output": _tail(output), "seconds": round(time.perf_counter() - start, 2)}


def run_blocks(blocks: list[Block], workdir: Path, timeout: float = 600.0) -> list[dict[str, object]]:
    """Run the ``blocks`` of one file in order inside ``workdir``, in one fresh Python namespace;
    one result dict per block (see the module docstring). After a failure the rest are ``not-run``."""
    results: list[dict[str, object]] = []
    namespace: dict[str, object] = {"__name__": "__readme__"}
    failed_at: int | None = None
    for block in blocks:
        if failed_at is not None and block.directive != "skip":
            result: dict[str, object] = {"file": block.source, "line": block.line, "lang": block.lang, "seconds": 0.0,
                                         "status": "not-run", "output": f"block at {block.source} line {failed_at} failed"}
        else:
            result = _run_one(block, workdir, namespace, timeout)
            if result["status"] == "failed":
                failed_at = block.line
        results.append(result)
        print(json.dumps(result), flush=True)
    return results


def run_files(files: list[Path], workdir: Path, root: Path | None = None, timeout: float = 600.0) -> list[dict[str, object]]:
    """Run every file's blocks (:func:`run_blocks`), file after file, in one ``workdir``; blocks are
    named by their path relative to ``root`` (default: the current directory)."""
    root = (root or Path.cwd()).resolve()
    named = [(path.resolve(), path.resolve().relative_to(root).as_posix()) for path in files]
    _prepare(workdir)
    results: list[dict[str, object]] = []
    for path, name in named:
        results += run_blocks(read_blocks(path.read_text(encoding="utf-8"), name), workdir, timeout)
    return results


def main(argv: list[str] | None = None) -> int:
    """``python -m tests.readme_runner FILE.md [FILE.md …] WORKDIR`` (files named relative to the current directory)."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) < 2:
        print("usage: python -m tests.readme_runner FILE.md [FILE.md ...] WORKDIR", file=sys.stderr)
        return 2
    files, workdir = [Path(a) for a in args[:-1]], Path(args[-1]).resolve()
    workdir.mkdir(parents=True, exist_ok=True)
    results = run_files(files, workdir)
    return 0 if all(r["status"] in ("ok", "skipped") for r in results) else 1


if __name__ == "__main__":
    raise SystemExit(main())

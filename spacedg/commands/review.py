"""``spacedg review BENCH_DIR [--port …]``: a local page to inspect, filter and correct a bench."""

from __future__ import annotations

import argparse
import contextlib
import select
import signal
import socket
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

from spacedg.commands import _args


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = _args.add_command(
        subparsers, "review", run, help="serve a local page to inspect, filter, edit and drop bench items (edits go to a new file + log)",
    )
    parser.add_argument("bench", type=Path, help="exported bench folder (spacedg export) or its .tsv")
    parser.add_argument("--port", type=int, default=8765, help="port on 127.0.0.1, 0-65535 (default 8765; 0 = any free port)")
    parser.add_argument("--out", type=Path, default=None, help="reviewed TSV (default: <bench>.reviewed.tsv beside the original)")
    parser.add_argument("--reviewer", default=None, help="name recorded in the edit log for every change made through this "
                                                        "server (default: the login name)")
    parser.add_argument("--scenes", type=Path, nargs="+", default=None, help="scene folders, to show each record's geometry")
    parser.add_argument("--verbose", action="store_true", help="log every request")


def _login_name() -> str:
    import getpass

    try:
        return getpass.getuser()
    except (KeyError, OSError):  # no login name (a container without a passwd entry)
        return "reviewer"


def run(args: argparse.Namespace) -> int:
    """Serve a review page for an exported bench on 127.0.0.1. Each item shows its images (with a clean vs
    degraded toggle), question, answer, metadata and the record's geometry; reviewers filter by question
    type, task group, degradation or keyword, edit questions, answers and options, and drop items. Every
    change is validated, then written atomically to a new TSV (never the original) with an edit log.
    """
    from spacedg.review.server import check_port, check_reviewer, make_server

    check_port(args.port)  # before anything is opened or written
    reviewer = check_reviewer(args.reviewer if args.reviewer is not None else _login_name())
    server = make_server(args.bench, out=args.out, reviewer=reviewer, scenes=args.scenes, port=args.port, verbose=args.verbose)
    print(f"reviewing {server.store.table} ({len(server.store)} items) as {server.httpd.reviewer}")
    print(f"edits → {server.store.out}, log → {server.store.log}")
    try:
        with _stop_signals() as stopped:
            if stopped is not None:
                server.start()
            print(f"open {server.url}  (the token in this address is the session's key; Ctrl+C to stop)", flush=True)
            if stopped is None:  # not the main thread: no signals to watch, served here until the process ends
                server.httpd.serve_forever()
            else:
                stopped()
        print("stopped")
    except KeyboardInterrupt:  # a Ctrl+C before the signals were watched
        print("stopped")
    finally:
        server.close()
    return 0


@contextlib.contextmanager
def _stop_signals() -> Iterator[Callable[[], None] | None]:
    """Within the block, SIGINT (Ctrl+C) and SIGTERM only wake the function it yields, which returns
    when one of them arrives (``None`` outside the main thread, where signals cannot be watched).

    Why not Python's ``KeyboardInterrupt``: with the server's threads running, CPython 3.11 could
    leave a SIGINT unhandled in the main thread for good (a thread other than the main one
    recomputes the flag that makes the main thread look at its pending signals; seen once in about
    forty stops under load, the server then serving on). The C-level handler writes every signal's
    number to the wakeup descriptor whatever thread it lands on, and the main thread waits on that
    descriptor itself."""
    if threading.current_thread() is not threading.main_thread():
        yield None
        return
    read_end, write_end = socket.socketpair()
    read_end.setblocking(False)
    write_end.setblocking(False)
    watched = (signal.SIGINT, signal.SIGTERM)
    previous = {sig: signal.signal(sig, lambda signum, frame: None) for sig in watched}
    previous_fd = signal.set_wakeup_fd(write_end.fileno(), warn_on_full_buffer=False)

    def stopped() -> None:
        wanted = {int(sig) for sig in watched}
        while True:
            select.select([read_end], [], [])
            try:
                data = read_end.recv(512)
            except BlockingIOError:
                continue
            if wanted & set(data):
                return

    try:
        yield stopped
    finally:
        signal.set_wakeup_fd(previous_fd)
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        read_end.close()
        write_end.close()


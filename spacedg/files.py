"""Shared helpers of the readers and writers: atomic writes, bounded reads, JSON loading.

- :func:`atomic_write`: write a file through a temporary sibling and ``os.replace``, so a
  reader never sees a half-written file (the old file stays until the new one is complete).
- :func:`write_png`: the one PNG writer (RGB or single-channel, encoded in memory, written
  atomically); :func:`read_rgb` reads an image back as RGB.
- :func:`read_json`: parse a JSON file and turn a syntax error into a
  :class:`~spacedg.errors.FileFormatError` naming the line and column.
- :func:`exclusive_lock`: one writer per output file (``fcntl.flock`` on ``<file>.lock``); a
  second process gets a :class:`~spacedg.errors.ParameterError` naming the holder.
- :func:`remove_stale_temps`: delete the temporary siblings that :func:`atomic_write` leaves
  when a process is killed mid-write (only names of that exact pattern).
- :class:`FileValueError`: the error raised when a file parses but holds values that break a
  convention (NaN positions, zero quaternions, ...). It is both a
  :class:`~spacedg.errors.FileFormatError` (the file is bad) and an
  :class:`~spacedg.errors.InvalidDataError` (its values are bad), so callers catching either
  see it.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import tempfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from spacedg.errors import FileFormatError, FileValueError, InvalidDataError, ParameterError  # noqa: F401  (re-exported)

#: JSON files larger than this are refused (a scene/instance/transforms file is kilobytes).
MAX_JSON_BYTES = 256 * 1024 * 1024
#: Longest integer literal (digits) read from JSON: every such integer converts to a finite float (< 1e308);
#: longer ones exceed every float (1.8e308), count and id, and Python refuses past 4300 digits anyway.
MAX_JSON_INT_DIGITS = 308


class _LongInteger(Exception):
    def __init__(self, digits: int) -> None:
        super().__init__(digits)
        self.digits = digits


def _parse_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_JSON_INT_DIGITS:
        raise _LongInteger(digits)
    return int(text)


def _long_integer_error(path: Path, what: str, text: str, digits: int) -> FileFormatError:
    """Name the field (the key before the number, when there is one) and the line of a too-long integer."""
    found = re.search(r"\d{%d,}" % (MAX_JSON_INT_DIGITS + 1), text)
    where = ""
    if found is not None:
        line = text.count("\n", 0, found.start()) + 1
        key = re.search(r'"((?:[^"\\]|\\.){0,200})"\s*:\s*-?$', text[max(0, found.start() - 300) : found.start()])
        where = (f"field {key.group(1)!r}, " if key else "") + f"line {line}: "
    return FileFormatError(
        f"{path}: {what}: {where}an integer of {digits:,} digits; no number in a {what} can be that long "
        f"(the limit is {MAX_JSON_INT_DIGITS} digits, past every float). The file is corrupt or hostile: repair that value"
    )


PathLike = str | os.PathLike[str]


def as_path(path: PathLike, what: str) -> Path:
    """``path`` as a :class:`Path`, or a :class:`FileFormatError` for non-path arguments."""
    if not isinstance(path, (str, os.PathLike)):
        raise FileFormatError(f"{what}: expected a file path, got {type(path).__name__}")
    return Path(path)


def require_file(path: Path, what: str) -> int:
    """Size in bytes of the regular file ``path``, or a clear error if it is missing.

    ``what`` names the file for messages (``"PLY file"``, ``".splat file"``, ``"scene.json"``).
    """
    if not path.exists():
        raise FileFormatError(f"{path}: {what} not found; check the path")
    if not path.is_file():
        noun = what if re.search(r"(?i)\bfile$", what.strip()) else f"{what} file"
        raise FileFormatError(f"{path}: expected a {noun}, found a directory or special file")
    return path.stat().st_size


def _usual_permissions(fd: int) -> None:
    """Give a ``mkstemp`` file (created 0600) the permissions a plain ``open`` would: 0666 minus the umask."""
    umask = os.umask(0)
    os.umask(umask)
    os.fchmod(fd, 0o666 & ~umask)


@contextmanager
def atomic_write(path: PathLike, mode: str = "wb") -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path``; on success flush, fsync and ``os.replace`` it.

    On any exception inside the block the temporary file is removed and ``path`` is left
    untouched (it keeps its previous content, or stays absent).
    """
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=folder)
    _usual_permissions(fd)
    tmp = Path(tmp_name)
    try:
        with os.fdopen(fd, mode, **({} if "b" in mode else {"encoding": "utf-8"})) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_write`)."""
    with atomic_write(path, "wb") as handle:
        handle.write(data)


#: The names :func:`atomic_write` gives its temporary files: ``".<target name>.<8 characters
#: of tempfile's random set>.tmp"``.
_TEMP_NAME = re.compile(r"\.(?P<target>.+)\.[a-z0-9_]{8}\.tmp")


def temp_target(name: str) -> str | None:
    """The file a temporary file called ``name`` was going to become (``None``: not one of ours)."""
    match = _TEMP_NAME.fullmatch(name)
    return match.group("target") if match else None


def remove_stale_temps(folder: PathLike, targets: Iterable[str] | Callable[[str], bool]) -> list[Path]:
    """Delete the temporary files :func:`atomic_write` left in ``folder`` (a killed writer's) for
    the target files named in ``targets`` (or for which ``targets(name)`` is true). The caller
    must own those targets: no live writer may be writing them. Files that do not match the
    temporary-name pattern are never touched. Returns what was removed."""
    root = Path(folder)
    owns = targets if callable(targets) else set(targets).__contains__
    if not root.is_dir():
        return []
    removed = []
    for entry in os.scandir(root):
        target = temp_target(entry.name)
        if target is not None and owns(target) and entry.is_file(follow_symlinks=False):
            Path(entry.path).unlink(missing_ok=True)
            removed.append(Path(entry.path))
    return removed


class ExclusiveLock:
    """An exclusive advisory lock held on ``path`` (see :func:`exclusive_lock`); ``release()``
    (or leaving the ``with`` block, or the process ending, even by ``kill -9``) frees it."""

    def __init__(self, path: Path, fd: int | None) -> None:
        self.path = path
        self._fd = fd

    @property
    def held(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        """Remove the lock file and free the lock (idempotent)."""
        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            self.path.unlink(missing_ok=True)  # while still locked: a waiter re-checks the inode and retries
        except OSError:
            pass
        os.close(fd)

    def __enter__(self) -> ExclusiveLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __del__(self) -> None:  # pragma: no cover - a forgotten lock is freed with its object
        try:
            self.release()
        except Exception:  # noqa: BLE001
            pass


def exclusive_lock(path: PathLike, what: str) -> ExclusiveLock:
    """Take an exclusive, non-blocking lock on the file ``path`` (created, holding this pid).

    ``what`` completes the error message (``"preds.jsonl is being written by another spacedg
    predict"``). Raises :class:`~spacedg.errors.ParameterError` naming the holder's pid when another
    process (or another lock in this one) holds it. Without ``fcntl`` (Windows) no lock is taken.
    """
    target = Path(path)
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        return ExclusiveLock(target, None)
    for _ in range(50):
        try:
            fd = os.open(target, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as err:
            raise ParameterError(f"cannot create the lock file {target} ({err.strerror}); choose an output folder you can write to") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "?"
            except OSError:
                holder = "?"
            os.close(fd)
            raise ParameterError(f"{what} (pid {holder}, lock file {target}); wait for it to finish or use another output") from None
        except OSError as err:
            os.close(fd)
            raise ParameterError(f"cannot lock {target} ({err.strerror}); put the output on a local disk") from None
        try:
            same = os.path.samestat(os.stat(target), os.fstat(fd))
        except FileNotFoundError:
            same = False
        if not same:  # the previous holder removed the file between our open and our lock: start again
            os.close(fd)
            continue
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
        return ExclusiveLock(target, fd)
    raise ParameterError(f"cannot lock {target}: it keeps being replaced; {what}")  # pragma: no cover


def write_temp_sibling(path: PathLike, writer: Callable[[Path], None]) -> Path:
    """Run ``writer(tmp)`` on a fresh temporary path beside ``path`` and return that path.

    The caller renames it into place (``os.replace``) when it is ready to commit; on error the
    temporary file is removed.
    """
    target = Path(path)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    _usual_permissions(fd)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        writer(tmp)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def sha256_of(path: PathLike, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file, read in chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while block := handle.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def read_json(path: PathLike, what: str) -> Any:
    """Parse the JSON file ``path``; errors name the file, line and column.

    Raises:
        FileFormatError: missing file, file over :data:`MAX_JSON_BYTES`, not UTF-8, or not JSON.
    """
    p = as_path(path, what)
    size = require_file(p, what)
    if size > MAX_JSON_BYTES:
        raise FileFormatError(f"{p}: {what} is {size} bytes, over the {MAX_JSON_BYTES} byte limit for a JSON file")
    raw = p.read_bytes()
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise FileFormatError(f"{p}: {what} is not UTF-8 text (byte {err.start}); save it as UTF-8 JSON") from None
    try:
        return json.loads(text, parse_int=_parse_int)
    except _LongInteger as err:
        raise _long_integer_error(p, what, text, err.digits) from None
    except json.JSONDecodeError as err:
        raise FileFormatError(
            f"{p}: {what} is not valid JSON: {err.msg} at line {err.lineno}, column {err.colno}"
        ) from None
    except RecursionError:
        raise FileFormatError(f"{p}: {what} is nested too deeply to be a {what}") from None


def dump_json(data: Any) -> str:
    """Deterministic, human-readable JSON (``allow_nan=False``: NaN is not JSON)."""
    try:
        return json.dumps(data, indent=2, ensure_ascii=False, allow_nan=False) + "\n"
    except ValueError as err:
        raise InvalidDataError(f"cannot write JSON: {err} (NaN/Inf values are not valid JSON)") from err
    except TypeError as err:
        raise InvalidDataError(f"cannot write JSON: {err}; metadata and attributes must be JSON-serialisable") from err


def write_png(path: PathLike, image: Any, what: str, *, compression: int | None = None) -> None:
    """Write ``image`` as a PNG file at ``path``, atomically (encoded in memory, then one rename).

    Args:
        path: the ``.png`` file; its folder is created when missing.
        image: an H×W×3 **RGB** array (uint8 or uint16) or an H×W single-channel one (e.g. uint16
            depth in millimetres); channels are reordered to OpenCV's BGR here, never by the caller.
        what: how messages name the file (a command-line flag such as ``"--out"``, or ``"image"``).
        compression: zlib level 0-9 (``cv2.IMWRITE_PNG_COMPRESSION``); ``None`` = OpenCV's default.

    Raises:
        ParameterError: ``image`` is not an H×W or H×W×3 uint8/uint16 array, or ``compression``
            is outside 0-9.
        InvalidDataError: OpenCV could not encode the image.
    """
    import cv2
    import numpy as np

    shape, dtype = getattr(image, "shape", None), getattr(image, "dtype", None)
    if shape is None or not (len(shape) == 2 or (len(shape) == 3 and shape[2] == 3)) or dtype not in (np.uint8, np.uint16):
        raise ParameterError(f"{what} {path}: image must be an H×W or H×W×3 uint8/uint16 array, got {dtype} {shape}")
    if compression is not None and (isinstance(compression, bool) or compression not in range(10)):
        raise ParameterError(f"{what} {path}: compression must be an integer 0-9, got {compression!r}")
    pixels = image[:, :, ::-1] if len(shape) == 3 else image
    params = [] if compression is None else [cv2.IMWRITE_PNG_COMPRESSION, int(compression)]
    ok, data = cv2.imencode(".png", np.ascontiguousarray(pixels), params)
    if not ok:  # pragma: no cover - OpenCV encodes any uint8/uint16 image
        raise InvalidDataError(f"{what} {path}: OpenCV could not encode the image as PNG")
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(target, data.tobytes())


def read_rgb(path: PathLike) -> Any:
    """An image file as a uint8 H×W×3 RGB array, or ``None`` when it is missing or unreadable."""
    import cv2

    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    return None if image is None else cv2.cvtColor(image, cv2.COLOR_BGR2RGB)

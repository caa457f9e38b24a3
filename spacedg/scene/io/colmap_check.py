"""Clear messages for COLMAP models that pycolmap refuses.

pycolmap reports a bad model with C++ text (``"[reconstruction_io_text.cc:246] Check failed:
line_stream1 >> image_id >> …"``, ``"Rig with ID 7 does not exist"``, ``"unordered_map::at"``)
that names neither the file nor the line. Two helpers turn that into a message that does:

- :func:`check_text_model` reads a text model (``cameras.txt``, ``images.txt``, ``rigs.txt``,
  ``frames.txt``) the way COLMAP does, line by line, before pycolmap sees it, and raises
  :class:`~spacedg.errors.FileFormatError` naming the file, the line, what the line should
  hold and what is wrong: a field that is not a number, a parameter count that does not match
  the camera model, an unknown model, or an id that refers to nothing (an image's camera, a
  frame's rig, a frame's images, a rig's cameras);
- :func:`pycolmap_message` explains what pycolmap raised for a binary model (whose records
  :mod:`spacedg.scene.io.colmap` already walked) or anything the text check did not foresee:
  the known messages are rewritten naming the file that holds the dangling id, any other
  loses its C++ location and ``Check failed`` expression.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from spacedg.errors import FileFormatError

__all__ = ["check_text_model", "pycolmap_message"]

_LAYOUT = {
    "cameras": "CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]",
    "images": "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, then a line of POINTS2D[] as (X Y POINT3D_ID)",
    "rigs": "RIG_ID NUM_SENSORS REF_SENSOR_TYPE REF_SENSOR_ID, then (SENSOR_TYPE SENSOR_ID HAS_POSE [QW QX QY QZ TX TY TZ]) per other sensor",
    "frames": "FRAME_ID RIG_ID QW QX QY QZ TX TY TZ NUM_DATA_IDS, then (SENSOR_TYPE SENSOR_ID DATA_ID) per data id",
}
_FIX = "re-export the model with COLMAP (e.g. `colmap model_converter --output_type TXT`) or fix that line"
_FIX_MODEL = "re-export the model with COLMAP (e.g. `colmap model_converter`) from the project it came from"
_SENSOR_TYPES = ("CAMERA", "IMU")


def _models() -> dict[str, str]:
    """Camera model name → its parameter names (``"fx, fy, cx, cy"``), from pycolmap itself."""
    import pycolmap

    found = {}
    for name, model in pycolmap.CameraModelId.__members__.items():
        if name == "INVALID":
            continue
        try:
            camera = pycolmap.Camera.create_from_model_id(1, model, 1.0, 10, 10)
        except Exception:  # noqa: BLE001 - a model pycolmap cannot build is left to pycolmap
            continue
        found[name] = str(camera.params_info)
    return found


class _Line:
    """One data line of a text model file, consumed token by token with clear errors."""

    def __init__(self, path: Path, number: int, text: str, kind: str) -> None:
        self.path, self.lineno, self.kind = path, number, kind
        self.tokens = text.split()
        self.at = 0

    def fail(self, what: str) -> FileFormatError:
        return FileFormatError(f"{self.path}:{self.lineno}: {what}; each {self.path.name} line reads {_LAYOUT[self.kind]}; {_FIX}")

    def _next(self, field: str) -> str:
        if self.at >= len(self.tokens):
            raise self.fail(f"the line ends before {field} (it has {len(self.tokens)} field(s))")
        token = self.tokens[self.at]
        self.at += 1
        return token

    def integer(self, field: str) -> int:
        token = self._next(field)
        if not re.fullmatch(r"[+-]?\d+", token):
            raise self.fail(f"{field} is {token[:40]!r}, not a whole number")
        if len(token.lstrip("+-")) > 19:  # COLMAP ids are 32/64-bit; int() of 5,000 digits raises
            raise self.fail(f"{field} has {len(token):,} digits, more than any 64-bit id")
        return int(token)

    def number(self, field: str) -> float:
        token = self._next(field)
        try:
            return float(token)
        except ValueError:
            raise self.fail(f"{field} is {token[:40]!r}, not a number") from None

    def word(self, field: str) -> str:
        return self._next(field)

    def rest(self) -> list[str]:
        return self.tokens[self.at:]


def _lines(path: Path, kind: str) -> Iterator[tuple[_Line, Iterator[tuple[int, str]]]]:
    """Data lines of ``path`` (comments and blank lines skipped), with the raw line iterator
    (``images.txt`` takes its POINTS2D line from it)."""
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise FileFormatError(f"{path}: not UTF-8 text (byte {err.start}); a COLMAP text model is plain text") from None
    raw = iter(enumerate(text.splitlines(), 1))
    for number, line in raw:
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        yield _Line(path, number, line, kind), raw


def _pose(line: _Line) -> None:
    for field in ("QW", "QX", "QY", "QZ", "TX", "TY", "TZ"):
        line.number(field)


def check_text_model(folder: Path) -> None:
    """Check a COLMAP text model line by line (see the module docstring); nothing is returned."""
    cameras: set[int] = set()
    models = _models()
    for line, _ in _lines(folder / "cameras.txt", "cameras"):
        camera_id = line.integer("CAMERA_ID")
        model = line.word("MODEL")
        if model not in models:
            raise line.fail(f"camera {camera_id}: unknown camera model {model!r} (COLMAP's: {', '.join(models)})")
        for field in ("WIDTH", "HEIGHT"):
            if line.integer(field) <= 0:
                raise line.fail(f"camera {camera_id}: {field} must be a positive number of pixels")
        params = line.rest()
        names = models[model]
        want = len(names.split(","))
        if len(params) != want:
            raise line.fail(f"camera {camera_id}: a {model} camera takes {want} parameters ({names}), the line has {len(params)}")
        for name, token in zip(names.split(","), params):
            try:
                float(token)
            except ValueError:
                raise line.fail(f"camera {camera_id}: parameter {name.strip()} is {token[:40]!r}, not a number") from None
        cameras.add(camera_id)

    images: dict[int, int] = {}
    for line, raw in _lines(folder / "images.txt", "images"):
        image_id = line.integer("IMAGE_ID")
        _pose(line)
        camera_id = line.integer("CAMERA_ID")
        line.word("NAME")
        if camera_id not in cameras:
            raise line.fail(f"image {image_id} uses camera {camera_id}, which cameras.txt does not define")
        images[image_id] = camera_id
        points = next(raw, None)  # COLMAP takes the next line, blank or not, as this image's POINTS2D
        if points is not None and len(points[1].split()) % 3:
            raise FileFormatError(
                f"{line.path}:{points[0]}: the POINTS2D line of image {image_id} holds {len(points[1].split())} values, "
                f"not triplets (X Y POINT3D_ID); every image line is followed by exactly one such line (blank when it has "
                f"none); {_FIX}"
            )

    rigs: set[int] = set()
    rigs_path = folder / "rigs.txt"
    if rigs_path.is_file():
        for line, _ in _lines(rigs_path, "rigs"):
            rig_id = line.integer("RIG_ID")
            count = line.integer("NUM_SENSORS")
            sensors = []
            if count > 0:
                sensors.append((line.word("REF_SENSOR_TYPE"), line.integer("REF_SENSOR_ID")))
                for _ in range(count - 1):
                    kind, sensor = line.word("SENSOR_TYPE"), line.integer("SENSOR_ID")
                    if line.integer("HAS_POSE"):
                        _pose(line)
                    sensors.append((kind, sensor))
            for kind, sensor in sensors:
                if kind not in _SENSOR_TYPES:
                    raise line.fail(f"rig {rig_id}: sensor type {kind[:20]!r} is not one of {', '.join(_SENSOR_TYPES)}")
                if kind == "CAMERA" and sensor not in cameras:
                    raise line.fail(f"rig {rig_id} lists camera {sensor}, which cameras.txt does not define")
            rigs.add(rig_id)

    frames_path = folder / "frames.txt"
    if frames_path.is_file():
        for line, _ in _lines(frames_path, "frames"):
            frame_id = line.integer("FRAME_ID")
            rig_id = line.integer("RIG_ID")
            _pose(line)
            count = line.integer("NUM_DATA_IDS")
            if rig_id not in rigs:
                known = ", ".join(map(str, sorted(rigs)[:10])) or "none"
                raise line.fail(f"frame {frame_id} refers to rig {rig_id}, which rigs.txt does not define (its rigs: {known})")
            for _ in range(max(count, 0)):
                kind, sensor, data = line.word("SENSOR_TYPE"), line.integer("SENSOR_ID"), line.integer("DATA_ID")
                if kind == "CAMERA" and images.get(data) != sensor:
                    if data not in images:
                        raise line.fail(f"frame {frame_id} lists image {data}, which images.txt does not define")
                    raise line.fail(f"frame {frame_id} lists image {data} with camera {sensor}, but images.txt gives "
                                    f"image {data} camera {images[data]}")


_KNOWN: list[tuple[re.Pattern[str], str]] = [
    (re.compile(r"Rig with ID (\d+) does not exist"), "frames.{ext} refers to rig {0}, which rigs.{ext} does not define"),
    (re.compile(r"Camera (\d+) from rig (\d+) not found"), "rigs.{ext}: rig {1} lists camera {0}, which cameras.{ext} does not define"),
    (re.compile(r"Image (\d+) does not exist in frame (\d+)"),
     "image {0} of images.{ext} is not listed in frame {1} of frames.{ext} (their camera ids disagree)"),
    (re.compile(r"Camera with ID (\d+) does not exist"), "an image or rig refers to camera {0}, which cameras.{ext} does not define"),
    (re.compile(r"Frame with ID (\d+) does not exist"), "an image refers to frame {0}, which frames.{ext} does not define"),
    (re.compile(r"Image with ID (\d+) does not exist"), "frames.{ext} lists image {0}, which images.{ext} does not define"),
    (re.compile(r"(?:unordered_)?map::at"), "frames.{ext} or images.{ext} refers to an id its file does not define"),
    (re.compile(r"Check failed: camera\.VerifyParams\(\)"),
     "cameras.{ext}: a camera's parameter count does not match its model (PINHOLE takes fx, fy, cx, cy)"),
    (re.compile(r"Check failed: line_stream"), "a line of the text model could not be read as COLMAP's layout"),
]


def pycolmap_message(folder: Path, ext: str, err: Any) -> str:
    """``"<folder>: <what is wrong, naming the file>; <fix>"`` for an error pycolmap raised."""
    text = str(err)
    for pattern, template in _KNOWN:
        match = pattern.search(text)
        if match:
            return f"{folder}: {template.format(*match.groups(), ext=ext)}; the model's files do not agree: {_FIX_MODEL}"
    cleaned = re.sub(r"\[[\w./-]+:\d+\]\s*", "", text)
    cleaned = re.sub(r"Check failed: .*?(?=\s[A-Z][a-z]|$)", "", cleaned).strip(" :.")
    kind = "binary" if ext == "bin" else "text"
    return f"{folder}: pycolmap could not read this COLMAP {kind} model ({cleaned or type(err).__name__}); {_FIX_MODEL}"

"""Seeded fuzz cases against spacedg's public entry points (shared by ``tests/test_fuzz_hardening.py``
and ``benchmarks/fuzz.py``).

A case is ``(family, seed)``: :func:`run_case` builds hostile or random input from the seed,
calls one public entry point and classifies what happened:

- ``ok`` — it worked, and every float it returned is finite and in its range;
- ``clear`` — it raised a :class:`spacedg.errors.SpaceDGError` (one clear message), or argparse
  exited with its usage status 2;
- ``traceback`` — any other exception escaped the entry point (a bug);
- ``nonfinite`` — it returned NaN/Inf or values out of range (a bug).

Families: readers (``ply``, ``splat``, ``spz``, ``scene_json``, ``colmap_text``, ``colmap_bin``,
``transforms``, ``inria``, ``instances``), ``render`` (random and degenerate Gaussians and
cameras, fisheye, defocus, motion, both backends), ``degradation`` (every built-in at random
valid parameters including the hard limits, on black, white, random and HDR images) and ``cli``
(``spacedg`` subcommands in-process through :func:`spacedg.cli.main` with hostile arguments).
Files are written under a work folder; :class:`Assets` (a tiny valid scene and the files made
from it) is built once per folder and reused by every case.
"""

from __future__ import annotations

import contextlib
import gzip
import io
import json
import math
import shutil
import struct
import traceback
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

OUTCOMES = ("ok", "clear", "traceback", "nonfinite")
READERS = ("ply", "splat", "spz", "scene_json", "colmap_text", "colmap_bin", "transforms", "inria", "instances")
FAMILIES = (*READERS, "render", "degradation", "cli")
_HUGE = "__HUGE_INTEGER__"


@dataclass
class Result:
    family: str
    seed: int
    outcome: str
    detail: str = ""


class NonFinite(Exception):
    """Raised by the checks below: an entry point returned NaN/Inf or out-of-range values."""


# ----------------------------------------------------------------------------- checks
def _finite(name: str, array: Any, low: float | None = None, high: float | None = None) -> None:
    if array is None:
        return
    a = np.asarray(array)
    if a.dtype.kind == "f" and not np.isfinite(a).all():
        raise NonFinite(f"{name}: {int((~np.isfinite(a)).sum())} non-finite values")
    if low is not None and a.size and a.min() < low:
        raise NonFinite(f"{name}: minimum {a.min()} < {low}")
    if high is not None and a.size and a.max() > high:
        raise NonFinite(f"{name}: maximum {a.max()} > {high}")


def check_frame(frame: Any) -> None:
    _finite("rgb", frame.rgb, 0.0)
    _finite("alpha", frame.alpha, 0.0, 1.0)
    _finite("depth", frame.depth, 0.0)
    _finite("median_depth", frame.median_depth, 0.0)
    if frame.instance_ids is not None and frame.instance_ids.size and frame.instance_ids.min() < -1:
        raise NonFinite("instance_ids below -1")


def check_gaussians(g: Any) -> None:
    for name in ("means", "quats", "scales", "opacities", "sh"):
        _finite(name, getattr(g, name))


def classify(family: str, seed: int, fn: Callable[[], Any]) -> Result:
    """Run ``fn`` and classify its outcome (see the module docstring)."""
    from spacedg.errors import SpaceDGError

    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fn()
    except SpaceDGError as err:
        return Result(family, seed, "clear", f"{type(err).__name__}: {str(err)[:300]}")
    except SystemExit as err:
        code = err.code if isinstance(err.code, int) else 1
        if code in (0, 2):
            return Result(family, seed, "ok" if code == 0 else "clear", f"exit {code}")
        return Result(family, seed, "traceback", f"SystemExit({err.code!r})")
    except NonFinite as err:
        return Result(family, seed, "nonfinite", str(err))
    except BaseException as err:  # noqa: BLE001 - what the fuzz is looking for
        if isinstance(err, KeyboardInterrupt):
            raise
        tb = traceback.format_exc(limit=-4)
        return Result(family, seed, "traceback", f"{type(err).__name__}: {str(err)[:300]}\n{tb[-1500:]}")
    return Result(family, seed, "ok")


# ----------------------------------------------------------------------------- hostile values
def hostile_number(rng: np.random.Generator) -> Any:
    """A number (or not) that a careless reader mishandles."""
    pool: list[Any] = [
        0, -1, 1, 2, 0.5, -0.0, 1e-300, 5e-324, 1e300, 1.7e308, -1.7e308, math.nan, math.inf, -math.inf,
        2**31, 2**32, 2**63 - 1, 2**63, 2**64, 10**12, 10**30, 10**300, -(10**300), 1e6, 1e9, 16384, 16385, 3e38,
        _HUGE, "12", "abc", "", None, True, False, [], {}, [1, 2], [[1]], {"a": 1},
    ]
    return pool[int(rng.integers(len(pool)))]


def dumps(value: Any, rng: np.random.Generator) -> str:
    """JSON text (NaN/Infinity allowed, as Python writes them) with 5,000-digit integers where a value was _HUGE."""
    text = json.dumps(value, allow_nan=True)
    digits = "9" * int(rng.choice([400, 4301, 5000]))
    return text.replace(f'"{_HUGE}"', digits)


def mutate_json(value: Any, rng: np.random.Generator, edits: int = 2) -> Any:
    """``value`` with ``edits`` random leaves or nodes replaced by hostile values, or deleted."""
    value = json.loads(json.dumps(value))
    for _ in range(edits):
        path: list[Any] = []
        node = value
        while isinstance(node, (dict, list)) and node and rng.random() < 0.8:
            key = list(node)[int(rng.integers(len(node)))] if isinstance(node, dict) else int(rng.integers(len(node)))
            path.append(key)
            node = node[key]
        if not path:
            continue
        parent = value
        for key in path[:-1]:
            parent = parent[key]
        if isinstance(parent, dict) and rng.random() < 0.15:
            del parent[path[-1]]
        else:
            parent[path[-1]] = hostile_number(rng)
    return value


def flip_bytes(data: bytes, rng: np.random.Generator) -> bytes:
    buf = bytearray(data)
    kind = int(rng.integers(4))
    if kind == 0 and buf:  # flip a few bytes
        for _ in range(int(rng.integers(1, 9))):
            buf[int(rng.integers(len(buf)))] = int(rng.integers(256))
    elif kind == 1:  # truncate
        del buf[int(rng.integers(len(buf) + 1)):]
    elif kind == 2:  # append garbage
        buf += rng.integers(0, 256, int(rng.integers(1, 200))).astype(np.uint8).tobytes()
    elif buf:  # overwrite a run with 0xff / 0x7f (huge counts, NaN payloads)
        start = int(rng.integers(len(buf)))
        for i in range(start, min(len(buf), start + int(rng.integers(1, 9)))):
            buf[i] = int(rng.choice([0xFF, 0x7F, 0x00, 0x80]))
    return bytes(buf)


# ----------------------------------------------------------------------------- assets
@dataclass
class Assets:
    """A tiny valid scene and the files made from it, built once in ``root``."""

    root: Path
    scene_dir: Path = field(init=False)
    view: str = field(init=False)
    ply: bytes = field(init=False)
    ply_ascii: bytes = field(init=False)
    splat: bytes = field(init=False)
    spz: bytes = field(init=False)
    scene_json: dict = field(init=False)
    transforms: dict = field(init=False)
    inria: list = field(init=False)
    instances: list = field(init=False)
    colmap_images_bin: bytes = field(init=False)

    def __post_init__(self) -> None:
        from spacedg.scene.io import save_scene
        from spacedg.scene.io.instances import instance_record
        from spacedg.scene.io.ply import write_ply
        from spacedg.scene.io.splat import write_splat
        from tests.scene import capture_layouts as cl

        self.root.mkdir(parents=True, exist_ok=True)
        self.scene_dir = self.root / "scene"
        if not (self.scene_dir / "scene.json").is_file():
            scene = tiny_scene()
            save_scene(scene, self.scene_dir)
        from spacedg.scene.io import load_scene

        scene = load_scene(self.scene_dir)
        self.view = sorted(scene.views)[0]
        g = scene.gaussians.subset(slice(0, 64))
        write_ply(self.root / "base.ply", g)
        self.ply = (self.root / "base.ply").read_bytes()
        self.ply_ascii = _ascii_ply(g)
        write_splat(self.root / "base.splat", g.with_sh_degree(0) if g.sh_degree == 0 else _degree0(g), allow_lossy=True)
        self.splat = (self.root / "base.splat").read_bytes()
        cl.write_spz(self.root / "base.spz", _degree0(g))
        self.spz = (self.root / "base.spz").read_bytes()
        self.scene_json = json.loads((self.scene_dir / "scene.json").read_text())
        self.transforms = cl.transforms_json(scene)
        self.inria = cl.inria_cameras(scene)
        self.instances = [instance_record(inst) for inst in scene.instances]
        text = cl.write_colmap_text(self.root / "colmap_text", scene)
        import pycolmap

        binary = self.root / "colmap_bin_base"
        binary.mkdir(exist_ok=True)
        pycolmap.Reconstruction(str(text)).write_binary(str(binary))
        self.colmap_images_bin = (binary / "images.bin").read_bytes()


def tiny_scene() -> Any:
    """A small room made by hand: 2,000 Gaussians on a box, 4 views at 32×24, two instances."""
    from spacedg.render.camera import Camera, look_at
    from spacedg.render.gaussians import Gaussians
    from spacedg.scene.box import OrientedBox
    from spacedg.scene.model import Instance, Scene

    rng = np.random.default_rng(0)
    n = 2000
    means = rng.uniform([-2, -2, 0], [2, 2, 2.5], (n, 3))
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    scales = np.exp(rng.uniform(np.log(0.02), np.log(0.15), (n, 3)))
    ids = np.where(means[:, 0] < -1, 0, np.where(means[:, 0] > 1, 1, -1)).astype(np.int32)
    g = Gaussians.from_colors(means, quats, scales, rng.uniform(0.3, 1.0, n), rng.uniform(0, 1, (n, 3)), instance_ids=ids)
    views = {}
    for k, eye in enumerate(([0, -3.5, 1.2], [3.5, 0, 1.4], [0, 3.5, 1.0], [-3.5, 0.3, 1.3])):
        views[f"v{k}"] = Camera(30.0, 30.0, 16.0, 12.0, 32, 24, look_at(np.array(eye, float), np.array([0, 0, 1.0]), np.array([0, 0, 1.0])))
    boxes = [OrientedBox(np.array([-1.5, 0, 1.2]), np.array([1.0, 4.0, 2.5]), np.eye(3)),
             OrientedBox(np.array([1.5, 0, 1.2]), np.array([1.0, 4.0, 2.5]), np.eye(3))]
    instances = [Instance(0, "chair", "", boxes[0]), Instance(1, "table", "", boxes[1])]
    return Scene("tiny", g, views, instances, [0.0, 0.0, 1.0])


def _degree0(g: Any) -> Any:
    from dataclasses import replace

    return replace(g, sh=g.sh[:, :1, :].copy(), instance_ids=None)


def _ascii_ply(g: Any) -> bytes:
    from spacedg.render.gaussians import SH_COEFFS

    k = SH_COEFFS[g.sh_degree]
    names = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", *(f"f_rest_{i}" for i in range(3 * (k - 1))),
             "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    rows = []
    for i in range(len(g)):
        rest = g.sh[i, 1:, :].T.reshape(-1)
        o = float(np.clip(g.opacities[i], 1e-6, 1 - 1e-6))
        values = [*g.means[i], *g.sh[i, 0], *rest, math.log(o / (1 - o)), *np.log(g.scales[i]), *g.quats[i]]
        rows.append(" ".join(repr(float(v)) for v in values))
    header = ["ply", "format ascii 1.0", f"element vertex {len(g)}", *[f"property float {n}" for n in names], "end_header"]
    return ("\n".join(header + rows) + "\n").encode()


# ----------------------------------------------------------------------------- readers
def _header_edit(data: bytes, rng: np.random.Generator) -> bytes:
    """One hostile edit of a PLY header line (counts, types, names, extra or missing lines)."""
    end = data.find(b"end_header\n")
    if end < 0:
        return flip_bytes(data, rng)
    lines = data[:end].decode("ascii", "replace").split("\n")
    i = int(rng.integers(1, len(lines)))
    tokens = lines[i].split()
    choice = int(rng.integers(6))
    if tokens and tokens[0] == "element" and choice < 3:
        tokens[-1] = str(rng.choice(["9" * 5000, "1000000000000", "-3", "1e6", "0", str(2**64), "abc"]))
        lines[i] = " ".join(tokens)
    elif tokens and tokens[0] == "property" and choice < 4:
        if rng.random() < 0.5:
            tokens[1] = str(rng.choice(["float", "double", "uchar", "int", "list", "quad", "int64"]))
        else:
            tokens[-1] = str(rng.choice(["f_rest_" + "1" * 5000, "f_rest_9999", "f_dc_0", "x", "instance_id", "filter_3D", ""]))
        lines[i] = " ".join(tokens)
    elif choice == 4:
        lines.insert(i, str(rng.choice(["element chunk 5", "property float x", "format ascii 1.0", "comment ok", "obj_info x"])))
    else:
        del lines[i]
    return "\n".join(lines).encode() + data[end:]


def _poke_float(data: bytes, rng: np.random.Generator) -> bytes:
    """Overwrite float32 values after the header with NaN / Inf / huge / tiny numbers."""
    end = data.find(b"end_header\n") + len(b"end_header\n")
    buf = bytearray(data)
    for _ in range(int(rng.integers(1, 6))):
        if len(buf) - end < 4:
            break
        at = end + 4 * int(rng.integers((len(buf) - end) // 4))
        value = float(rng.choice([math.nan, math.inf, -math.inf, 3e38, -3e38, 1e20, 1e-40, 120.0, -120.0, 0.0]))
        buf[at:at + 4] = struct.pack("<f", value)
    return bytes(buf)


def case_ply(rng: np.random.Generator, a: Assets, work: Path) -> Callable[[], Any]:
    from spacedg.scene.io import read_gaussians

    base = a.ply_ascii if rng.random() < 0.2 else a.ply
    kind = int(rng.integers(5))
    if kind == 0:
        data = _header_edit(base, rng)
    elif kind == 1:
        data = _poke_float(base, rng)
    elif kind == 2:
        data = flip_bytes(base, rng)
    elif kind == 3:
        data = b"ply\n" + rng.integers(0, 256, int(rng.integers(0, 3000))).astype(np.uint8).tobytes()
    else:
        data = _header_edit(_poke_float(base, rng), rng)
    path = work / "case.ply"
    path.write_bytes(data)
    return lambda: check_gaussians(read_gaussians(path))


def case_splat(rng: np.random.Generator, a: Assets, work: Path) -> Callable[[], Any]:
    from spacedg.scene.io import read_gaussians

    if rng.random() < 0.3:
        data = rng.integers(0, 256, 32 * int(rng.integers(0, 40)) + int(rng.choice([0, 0, 7]))).astype(np.uint8).tobytes()
    else:
        data = flip_bytes(a.splat, rng) if rng.random() < 0.5 else _poke_splat(a.splat, rng)
    path = work / "case.splat"
    path.write_bytes(data)
    return lambda: check_gaussians(read_gaussians(path))


def _poke_splat(data: bytes, rng: np.random.Generator) -> bytes:
    buf = bytearray(data)
    for _ in range(int(rng.integers(1, 5))):
        record = int(rng.integers(max(1, len(buf) // 32)))
        at = 32 * record + 4 * int(rng.integers(6))  # position (3 f32) or scale (3 f32)
        if at + 4 <= len(buf):
            buf[at:at + 4] = struct.pack("<f", float(rng.choice([math.nan, math.inf, -1.0, 3e38, 1e-45, 0.0])))
    return bytes(buf)


def case_spz(rng: np.random.Generator, a: Assets, work: Path) -> Callable[[], Any]:
    from spacedg.scene.io import read_gaussians

    raw = gzip.decompress(a.spz)
    kind = int(rng.integers(5))
    if kind == 0:  # header fields
        buf = bytearray(raw)
        field_at = int(rng.choice([0, 4, 8, 12, 13, 14]))
        size = 4 if field_at < 12 else 1
        value = int(rng.choice([0, 1, 2, 3, 4, 255, 2**32 - 1, 2**31, 10**6]))
        buf[field_at:field_at + size] = (value % (1 << (8 * size))).to_bytes(size, "little")
        data = gzip.compress(bytes(buf))
    elif kind == 1:
        data = gzip.compress(flip_bytes(raw, rng))
    elif kind == 2:
        data = flip_bytes(a.spz, rng)
    elif kind == 3:  # a decompression bomb claiming many points
        header = struct.pack("<IIIBBBB", 0x5053474E, 3, 2**31, 0, 12, 0, 0)
        data = gzip.compress(header + bytes(int(rng.choice([10**5, 10**7]))), compresslevel=9)
    else:
        data = rng.integers(0, 256, int(rng.integers(0, 500))).astype(np.uint8).tobytes()
    path = work / "case.spz"
    path.write_bytes(data)
    return lambda: check_gaussians(read_gaussians(path))


def _render_scene(scene: Any) -> None:
    g = scene.gaussians
    check_gaussians(g)
    from spacedg.render import render

    for name in list(scene.views)[:2]:
        cam = scene.views[name]
        if cam.width * cam.height > 64 * 48:
            cam = cam.resized(min(cam.width, 64), min(cam.height, 48))
        check_frame(render(g, cam, outputs="all"))


def case_scene_json(rng: np.random.Generator, a: Assets, work: Path) -> Callable[[], Any]:
    from spacedg.scene.io import load_scene

    folder = work / "scene"
    if folder.exists():
        shutil.rmtree(folder)
    shutil.copytree(a.scene_dir, folder)
    record = a.scene_json
    if rng.random() < 0.5:  # aim at the cameras
        record = json.loads(json.dumps(record))
        view = record["views"][a.view]
        key = str(rng.choice(list(view)))
        view[key] = hostile_number(rng)
    else:
        record = mutate_json(record, rng, int(rng.integers(1, 4)))
    (folder / "scene.json").write_text(dumps(record, rng))
    return lambda: _render_scene(load_scene(folder))


def case_colmap_text(rng: np.random.Generator, a: Assets, work: Path) -> Callable[[], Any]:
    from spacedg.scene.io.colmap import read_colmap

    folder = work / "colmap_text"
    if folder.exists():
        shutil.rmtree(folder)
    shutil.copytree(a.root / "colmap_text", folder)
    target = folder / ("cameras.txt" if rng.random() < 0.6 else "images.txt")
    lines = target.read_text().split("\n")
    data_lines = [i for i, line in enumerate(lines) if line and not line.startswith("#")]
    i = int(rng.choice(data_lines))
    tokens = lines[i].split()
    j = int(rng.integers(1, len(tokens)))
    value = hostile_number(rng)
    tokens[j] = "9" * 5000 if value == _HUGE else (json.dumps(value) if not isinstance(value, str) else value)
    if rng.random() < 0.2:
        tokens[1] = str(rng.choice(["OPENCV", "FULL_OPENCV", "OPENCV_FISHEYE", "RADIAL", "NOPE", "SIMPLE_PINHOLE"]))
    lines[i] = " ".join(tokens)
    target.write_text("\n".join(lines))
    return lambda: [_finite("camera", c.cam_to_world) for c in read_colmap(folder).values()]


def case_colmap_bin(rng: np.random.Generator, a: Assets, work: Path) -> Callable[[], Any]:
    from spacedg.scene.io.colmap import read_colmap

    folder = work / "colmap_bin"
    folder.mkdir(exist_ok=True)
    widths, heights = [32, 0, 10**9, 2**63, 2**64 - 1, 16384, 16385], [24, 1, 10**6, 2**63]
    hostile = rng.random() < 0.8
    cameras = [
        (1, 1, widths[int(rng.integers(len(widths)))] if hostile else 32, heights[int(rng.integers(len(heights)))] if hostile else 24,
         [float(rng.choice([30.0, 0.0, -1.0, math.nan, math.inf, 1e300])) if hostile else 30.0, 30.0, 16.0, 12.0])
    ] + [(cid, 1, 32, 24, [30.0, 30.0, 16.0, 12.0]) for cid in (2, 3, 4)]
    data = struct.pack("<Q", len(cameras))
    for cid, model, w, h, params in cameras:
        data += struct.pack("<IiQQ", cid, model, w, h) + struct.pack("<4d", *params)
    if rng.random() < 0.3:
        data = flip_bytes(data, rng)
    (folder / "cameras.bin").write_bytes(data)
    images = a.colmap_images_bin if rng.random() < 0.7 else flip_bytes(a.colmap_images_bin, rng)
    (folder / "images.bin").write_bytes(images)
    return lambda: [_finite("camera", c.cam_to_world) for c in read_colmap(folder).values()]


def case_transforms(rng: np.random.Generator, a: Assets, work: Path) -> Callable[[], Any]:
    from spacedg.scene.io.nerfstudio import read_transforms

    data = mutate_json(a.transforms, rng, int(rng.integers(1, 4)))
    if rng.random() < 0.4:
        data["w"] = hostile_number(rng)
    path = work / "transforms.json"
    path.write_text(dumps(data, rng))
    return lambda: read_transforms(path, opencv_distortion="drop")


def case_inria(rng: np.random.Generator, a: Assets, work: Path) -> Callable[[], Any]:
    from spacedg.scene.io.inria import read_inria_cameras

    data = mutate_json(a.inria, rng, int(rng.integers(1, 4)))
    path = work / "cameras.json"
    path.write_text(dumps(data, rng))
    return lambda: read_inria_cameras(path)


def case_instances(rng: np.random.Generator, a: Assets, work: Path) -> Callable[[], Any]:
    from spacedg.scene.io.embodiedscan import read_embodiedscan_boxes
    from spacedg.scene.io.instances import read_instances
    from spacedg.scene.io.scannetpp import read_segments_anno
    from tests.scene import capture_layouts as cl

    kind = int(rng.integers(3))
    scene = _SCENE_CACHE.setdefault("tiny", tiny_scene())
    base: Any = {"instances": a.instances} if kind == 0 else (cl.segments_anno(scene) if kind == 1 else cl.embodiedscan_infos(scene))
    data = mutate_json(base, rng, int(rng.integers(1, 4)))
    path = work / "instances.json"
    path.write_text(dumps(data, rng))
    reader = (lambda: read_instances(path, views=list(scene.views))) if kind == 0 else (
        (lambda: read_segments_anno(path)) if kind == 1 else (lambda: read_embodiedscan_boxes(path)))
    return reader


_SCENE_CACHE: dict[str, Any] = {}


# ----------------------------------------------------------------------------- renders
_SCALES = (0.0, 1e-30, 1e-6, 0.01, 0.2, 1.0, 1e6, 1e12, 1e20, 3e38)


def random_gaussians(rng: np.random.Generator) -> Any:
    """1–40 Gaussians with degenerate values: zero and huge scales, points behind and at the camera, SH at ±SH_MAX."""
    from spacedg.render.gaussians import SH_MAX, Gaussians

    n = int(rng.integers(1, 41))
    means = rng.normal(0, 1, (n, 3)) + [0, 0, 3]
    kind = rng.integers(0, 8, n)
    means[kind == 0] = 0.0  # at the camera centre
    means[kind == 1, 2] = -rng.uniform(0, 5, int((kind == 1).sum()))  # behind the camera
    means[kind == 2] *= 1e8  # far
    means[kind == 3, 2] = 0.0100001  # on the near plane
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    scales = rng.choice(_SCALES, (n, 3)) if rng.random() < 0.5 else np.exp(rng.uniform(-6, 1, (n, 3)))
    opacities = rng.choice([0.0, 1e-7, 1 / 255, 0.3, 0.99, 1.0], n)
    degree = int(rng.integers(0, 4))
    sh = rng.normal(0, 1, (n, (degree + 1) ** 2, 3)) * rng.choice([0.0, 1.0, 100.0, SH_MAX], (n, 1, 1))
    sh = np.clip(sh, -SH_MAX, SH_MAX)
    return Gaussians(means, quats, scales, opacities, sh, rng.integers(-1, 4, n).astype(np.int32))


def random_camera(rng: np.random.Generator) -> Any:
    from spacedg.render.camera import Camera, FisheyeLens
    from spacedg.render.gaussians import quat_to_matrix

    lens = None
    if rng.random() < 0.3:
        k = rng.choice([-0.24, 0.0, 1e-4, 0.5, -1.0, 3.0], 4)
        lens = FisheyeLens(*[float(v) for v in k], max_theta=float(rng.choice([0.05, 0.3, 1.5, 3.1])))
    width, height = int(rng.integers(1, 65)), int(rng.integers(1, 49))
    f = float(rng.choice([1e-3, 1.0, 20.0, 300.0, 1e6]))
    pose = np.eye(4)
    if rng.random() < 0.3:
        q = rng.normal(size=4)
        pose[:3, :3] = quat_to_matrix((q / np.linalg.norm(q))[None])[0]
        pose[:3, 3] = rng.normal(0, 1, 3)
    return Camera(f, f * float(rng.choice([1.0, 0.5, 2.0])), width * float(rng.uniform(-0.5, 1.5)), height / 2, width, height, pose, lens)


def case_render(rng: np.random.Generator, a: Assets, work: Path) -> Callable[[], Any]:
    from spacedg.render import Defocus, MotionBlur, RasterSettings, render

    g, cam = random_gaussians(rng), random_camera(rng)
    kw: dict[str, Any] = {"outputs": "all", "backend": "torch" if rng.random() < 0.15 else "cpu"}
    kw["settings"] = RasterSettings(alpha_max=float(rng.choice([0.5, 0.99, 0.999999])), antialiased=bool(rng.random() < 0.3),
                                    defocus_extent=None if rng.random() < 0.2 else 2.5)
    if rng.random() < 0.4:
        kw["defocus"] = Defocus(aperture=float(rng.choice([0.0, 1e-6, 2.0, 15.0, 1000.0, 1e4])),
                                focus=float(rng.choice([1e-6, 0.01, 1.0, 3.0, 1e4])))
    if rng.random() < 0.1:
        kw["motion"] = MotionBlur(translation=tuple(rng.normal(0, 1, 3) * float(rng.choice([0.1, 1e3]))),
                                  rotation=(0.0, float(rng.uniform(0, 3.1)), 0.0), sub_steps=int(rng.integers(1, 4)),
                                  fast=bool(rng.random() < 0.5))
    return lambda: check_frame(render(g, cam, **kw))


# ----------------------------------------------------------------------------- degradations
def _param(spec: Any, rng: np.random.Generator) -> Any:
    low, high = spec.low, spec.high
    pick = rng.random()
    value = low if pick < 0.2 else (high if pick < 0.4 else low + (high - low) * rng.random())
    return int(round(value)) if spec.integer else float(value)


def _image(rng: np.random.Generator) -> np.ndarray:
    h, w = int(rng.integers(1, 40)), int(rng.integers(1, 40))
    kind = int(rng.integers(4))
    if kind == 0:
        return np.zeros((h, w, 3), np.uint8)
    if kind == 1:
        return np.full((h, w, 3), 255, np.uint8)
    return rng.integers(0, 256, (h, w, 3)).astype(np.uint8)


def case_degradation(rng: np.random.Generator, a: Assets, work: Path) -> Callable[[], Any]:
    from spacedg.plugins import list_degradations
    from spacedg.plugins.specs import Stage

    specs = list_degradations()
    spec = specs[int(rng.integers(len(specs)))]
    params = {p.name: _param(p, rng) for p in spec.params}
    if spec.name == "motion_blur":
        params["sub_steps"] = min(params["sub_steps"], int(rng.choice([1, 2, 8, 64])))
    chain = {"name": spec.name, "params": params}
    seed = int(rng.integers(2**31))
    if spec.stage is Stage.RASTER:
        from spacedg.data.pipeline import PipelineOptions, degrade
        from spacedg.scene.io import load_scene

        scene = _SCENE_CACHE.setdefault("asset_scene", load_scene(a.scene_dir))
        size = (int(rng.integers(8, 40)), int(rng.integers(8, 30)))
        return lambda: _check_u8(degrade(scene, [a.view], chain, seed=seed, options=PipelineOptions(image_size=size)).images)
    if spec.stage is Stage.LINEAR and rng.random() < 0.5:  # the plugin on linear HDR light, depth with holes
        h, w = int(rng.integers(1, 40)), int(rng.integers(1, 40))
        rgb = (rng.random((h, w, 3)) * float(rng.choice([0.0, 1.0, 1e3, 1e6, 1e12]))).astype(np.float32)
        depth = rng.uniform(0, 10, (h, w)).astype(np.float32)
        depth[rng.random((h, w)) < 0.2] = float(rng.choice([0.0, math.nan, math.inf]))
        aux = {"depth": depth, "alpha": rng.random((h, w)).astype(np.float32), "far_depth": float(rng.choice([0.0, 5.0, 1e6]))}
        return lambda: _finite(spec.name, spec.apply(rgb, aux, params, np.random.default_rng(seed)))  # sensor noise may go below 0
    from spacedg.data.pipeline import degrade_image

    image = _image(rng)
    depth = None
    if rng.random() < 0.5:
        depth = rng.uniform(0, 10, image.shape[:2]).astype(np.float32)
        depth[rng.random(image.shape[:2]) < 0.3] = float(rng.choice([0.0, math.nan, math.inf, -3.0, -math.inf]))
    return lambda: _check_u8(degrade_image(image, chain, seed, depth=depth)[0])


def _check_u8(images: np.ndarray) -> None:
    if images.dtype != np.uint8:
        raise NonFinite(f"images are {images.dtype}, not uint8")


# ----------------------------------------------------------------------------- command line
def _hostile_arg(rng: np.random.Generator) -> str:
    return str(rng.choice(["0", "-1", "1", "nan", "inf", "-inf", "1e309", "9" * 5000, "", "abc", "1.5", "100000", "16385",
                           "16384", "100000x100000", "0x0", "8x8", "-5x7", "1x", "x", "2/1", "1/0", "0/0", "-1/2", "a,b",
                           "1,2,3", "1e400,1", "0,0,0,0,0,0", "nan,1", "1,inf", "5000,0.01", "0.5,0.5", "1e4,1e-9", "3.2,0"]))


def _cli_argv(rng: np.random.Generator, a: Assets, work: Path) -> list[str]:
    scene, view, out = str(a.scene_dir), a.view, str(work / "cli_out.png")
    h = _hostile_arg
    kind = int(rng.integers(10))
    if kind == 0:
        flag = str(rng.choice(["--n", "--width", "--height", "--gaussians", "--min-views", "--max-views", "--seed", "--splat-size"]))
        argv = ["scenes", "synth", "--n", "1", "--out", str(work / "synth"), "--gaussians", "10000", "--min-views", "4",
                "--max-views", "4", "--width", "32", "--height", "24"]
        value = h(rng)
        if flag in argv:
            argv[argv.index(flag) + 1] = value
        else:
            argv += [flag, value]
        if value.lstrip("-").replace(".", "").isdigit() and flag in ("--n", "--gaussians") and float(value) >= 1:
            argv[argv.index("--gaussians") + 1] = "1"  # keep a valid huge count from generating for minutes
        return argv
    if kind in (1, 2, 3):
        flags = ["--width", "--height", "--defocus", "--fisheye", "--motion", "--sub-steps", "--backend", "--device"]
        argv = ["render", scene, "--view", view, "--out", out]
        for flag in rng.choice(flags, int(rng.integers(1, 3)), replace=False):
            argv += [str(flag), h(rng)]
        if "--sub-steps" in argv and "--motion" not in argv:
            argv += ["--motion", "0.01,0,0,0,0,0"]
        return argv
    if kind == 4:
        return ["render", scene, "--view", str(rng.choice([view, "nope", "", "../" * 40])), "--out",
                str(rng.choice([out, str(work / "x.jpg"), str(work), ""])), "--width", str(int(rng.integers(1, 65)))]
    if kind == 5:
        return ["gallery", scene, "--out", str(work / "g.png"), "--thumb-width", h(rng), "--degradations",
                str(rng.choice(["haze", "nope", "", "haze,haze", "low_res:9"])), "--seed", h(rng)]
    if kind == 6:
        flag = str(rng.choice(["--image-size", "--shard", "--shard-size", "--split-fractions", "--max-questions", "--clean-prob",
                               "--seed", "--per-sub-type", "--degradations", "--question-types", "--split"]))
        return ["export", "--split", "bench", "--scenes", scene, "--out", str(work / "export"), "--all-bench",
                "--max-questions", "0", flag, h(rng)]
    if kind == 7:
        flag = str(rng.choice(["--min-pixels", "--max-pixels", "--image-size", "--batch-size", "--limit", "--shard", "--seed"]))
        return ["predict", "--model", str(work / "no-model"), "--bench", str(work / "no-bench"), "--out", str(work / "p.jsonl"), flag, h(rng)]
    if kind == 8:
        return ["scenes", str(rng.choice(["info", "preview"])), str(rng.choice([scene, str(work / "none"), ""])),
                *(["--out", str(work / "plan.png"), "--columns", h(rng)] if rng.random() < 0.5 else [])]
    return [str(rng.choice(["plugins", "qa", "eval", "review", "nope", "--help"])), *([h(rng)] if rng.random() < 0.7 else [])]


def case_cli(rng: np.random.Generator, a: Assets, work: Path) -> Callable[[], Any]:
    from spacedg.cli import main

    argv = _cli_argv(rng, a, work)
    if argv[0] == "review" and len(argv) == 2 and len(argv[1]) < 200 and Path(argv[1]).exists():
        argv = ["review", str(work / "no-bench")]  # a valid bench would start serving (and never return)
    return lambda: main(argv)


CASES: dict[str, Callable[[np.random.Generator, Assets, Path], Callable[[], Any]]] = {
    "ply": case_ply, "splat": case_splat, "spz": case_spz, "scene_json": case_scene_json, "colmap_text": case_colmap_text,
    "colmap_bin": case_colmap_bin, "transforms": case_transforms, "inria": case_inria, "instances": case_instances,
    "render": case_render, "degradation": case_degradation, "cli": case_cli,
}


def run_case(family: str, seed: int, assets: Assets, work: Path) -> Result:
    """Build case ``(family, seed)`` and run it (building the input may itself fail: that is a fuzz bug, a traceback)."""
    rng = np.random.default_rng([FAMILIES.index(family), seed])
    work.mkdir(parents=True, exist_ok=True)
    try:
        fn = CASES[family](rng, assets, work)
    except Exception as err:  # noqa: BLE001 - an input the generator could not build
        from spacedg.errors import SpaceDGError

        if isinstance(err, SpaceDGError):  # e.g. a Camera the generator drew is itself refused: a clear error
            return Result(family, seed, "clear", f"{type(err).__name__}: {str(err)[:300]}")
        return Result(family, seed, "traceback", f"building the case: {type(err).__name__}: {err}\n{traceback.format_exc(limit=-3)}")
    return classify(family, seed, fn)

"""Captures of unknown units for the units tests and ``benchmarks/units.py``: a truth in metres
scaled into file units by a factor the importer is not told, and an object-on-a-table capture
written as a COLMAP project (text model + Gaussians + Holi-Spatial JSON) by ``capture_layouts``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from spacedg.render.camera import Camera, look_at
from spacedg.render.gaussians import Gaussians
from spacedg.scene.box import OrientedBox
from spacedg.scene.io import write_ply
from spacedg.scene.io.capture import scale_gaussians, scale_instances, scale_views
from spacedg.scene.model import Instance, Scene
from tests.scene import capture_layouts as cl

#: The capture's unknown scale: metres per file unit.
MPU = 0.145


def in_file_units(scene: Scene, mpu: float = MPU) -> Scene:
    """The truth (metres) as a reconstruction without metric scale stores it: every length / ``mpu``."""
    k = 1.0 / mpu
    return Scene(scene.id, scale_gaussians(scene.gaussians, k), scale_views(scene.views, k), scale_instances(scene.instances, k),
                 scene.up, scene.vocabulary, {})


def _surface(box: OrientedBox, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points on the faces of ``box`` (metres)."""
    local = rng.uniform(-0.5, 0.5, (n, 3))
    axis = rng.integers(0, 3, n)
    local[np.arange(n), axis] = np.where(rng.random(n) < 0.5, -0.5, 0.5)
    return box.center + (local * box.extents) @ box.rotation.T


def tabletop(labels: tuple[str, ...] = ("box", "cup", "bowl", "book", "laptop", "bottle", "doily")) -> Scene:
    """An object-on-a-table capture in metres: a 1.2 m table, a 12.5 cm card box, a cup, … and a doily
    (a label without a typical size); 8 phone views on a ring 1.4 m above the floor."""
    on_table = {"box": (0.125, 0.09, 0.05), "cup": (0.08, 0.08, 0.1), "bowl": (0.2, 0.2, 0.08), "book": (0.24, 0.17, 0.03),
                "laptop": (0.33, 0.23, 0.02), "bottle": (0.07, 0.07, 0.25), "doily": (0.3, 0.3, 0.005)}
    spots = [(-0.4, -0.2), (-0.15, 0.15), (0.1, -0.15), (0.35, 0.15), (0.4, -0.2), (-0.4, 0.2), (0.0, 0.05)]
    boxes = [("table", OrientedBox(np.array([0.0, 0.0, 0.375]), np.array([1.2, 0.7, 0.75]), np.eye(3)))]
    for (x, y), label in zip(spots, labels):
        ext = np.array(on_table[label])
        boxes.append((label, OrientedBox(np.array([x, y, 0.75 + ext[2] / 2]), ext, np.eye(3))))
    rng = np.random.default_rng(3)
    means = np.concatenate([_surface(b, 6000 if label == "table" else 800, rng) for label, b in boxes])
    n = len(means)
    g = Gaussians(means, np.tile([1.0, 0, 0, 0], (n, 1)), np.full((n, 3), 0.012), np.full(n, 0.9), rng.uniform(-0.5, 0.5, (n, 1, 3)))
    instances = [Instance(k, label, label, box) for k, (label, box) in enumerate(boxes)]
    up = np.array([0.0, 0.0, 1.0])
    views = {}
    for k in range(8):
        a = 2 * math.pi * k / 8
        eye = np.array([1.5 * math.cos(a), 1.5 * math.sin(a), 1.4])
        views[f"IMG_{k:04d}"] = Camera(150.0, 150.0, 80.0, 60.0, 160, 120, look_at(eye, np.array([0.0, 0.0, 0.8]), up))
    return Scene("tabletop", g, views, instances, up.tolist(), None, {})


def write_colmap_project(root: Path, scene: Scene) -> Path:
    """A COLMAP project (``sparse/0`` text model), the trained Gaussians beside it and a Holi-Spatial JSON."""
    cl.write_colmap_text(root / "sparse" / "0", scene)
    write_ply(root / "point_cloud.ply", cl.without_ids(scene.gaussians))
    (root / "instances.json").write_text(json.dumps(cl.holi_spatial_json(scene, {})))
    return root


def write_unit_fixtures(root: Path, mpu: float = MPU) -> list[tuple[str, Path, Path]]:
    """The two captures without metric scale (``mpu`` metres per file unit), written under ``root``:
    a room (INRIA output + COLMAP model + Holi-Spatial JSON) and an object on a table (COLMAP
    project). Returns ``(name, source folder, instances JSON)`` for each."""
    room = in_file_units(cl.truth_room(seed=5, gaussians=10_000, views=8), mpu)
    src = cl.write_inria_output(root / "room", room)
    (root / "room" / "holi.json").write_text(json.dumps(cl.holi_spatial_json(room, {})))
    table = write_colmap_project(root / "table", in_file_units(tabletop(), mpu))
    return [("room (INRIA + COLMAP + Holi-Spatial JSON)", src, root / "room" / "holi.json"),
            ("object on a table (COLMAP project)", table, table / "instances.json")]

"""A tiny scene written in the layout of Holi-Spatial's release (Hugging Face ``Holi-Spatial/ScanNetPP``).

The layout, as read in the release listing and the pipeline that made it (re-stated, nothing copied):
``GS_model_w_mesh_pp/<scene id>/`` is a PGSR output folder (``cfg_args``, ``cameras.json`` as
``camera_to_JSON`` writes it, ``input.ply``, ``multi_view.json``, ``point_cloud/iteration_30000/point_cloud.ply``,
``mesh/tsdf_fusion_post.ply``), and ``3d_bounding_box_pp/<scene id>.json`` the boxes, as
``3d_bounding_instance_gs_rerun_da3.py`` writes them: ``ins_id`` strings counted from 0, ``bounding_box``
corners as ``{x, y, z}``, ``obb_transform`` / ``obb_extents``, ``images`` = sorted absolute SAM3 mask paths
``<mask root>/<scene id>/<image stem>/<label>.png`` (not shipped), ``highest_confidence_mask`` and
``mask_encodings`` = one COCO RLE (``pycocotools.mask.encode``, counts as a str) per image, same order.

The scene: a floor and three objects (a few hundred Gaussians), four 160×120 views, metres, z up in
ScanNet++'s scan frame; the files hold it in the frame PGSR trained in, the world of ScanNet++'s nerfstudio
JSON (rows y, x, -z of the scan frame: :func:`released`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from spacedg.render import render
from spacedg.render.camera import Camera, look_at
from spacedg.render.gaussians import Gaussians
from spacedg.scene.box import OrientedBox
from spacedg.scene.io import write_ply
from spacedg.scene.model import Instance, Scene
from tests.scene.capture_layouts import SCANNETPP_JSON, inria_cameras, without_ids

SCENE_ID = "0a5c013435"
MASK_ROOT = "/mnt/holi/sam3_masks_scannetppv2_new"
#: (label, centre, full sides) of the three objects, metres.
OBJECTS = (("chair", (-0.7, 0.4, 0.3), (0.4, 0.4, 0.6)), ("table", (0.5, 0.3, 0.35), (0.8, 0.5, 0.7)),
           ("trash can", (0.0, -0.7, 0.2), (0.3, 0.3, 0.4)))


def _block(centre: np.ndarray, sides: np.ndarray, per_axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Centres of a ``per_axis``³ grid filling the box, and one scale per Gaussian (metres)."""
    axes = [np.linspace(-0.5, 0.5, per_axis) * s * (per_axis - 1) / per_axis for s in sides]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3) + centre
    return grid, np.tile(sides / per_axis * 0.6, (len(grid), 1))


def tiny_scene() -> Scene:
    """The truth: 144 floor + 3 × 64 object Gaussians (ids on them), four views around, z up."""
    floor = np.stack(np.meshgrid(np.linspace(-1.5, 1.5, 12), np.linspace(-1.5, 1.5, 12), indexing="ij"), -1).reshape(-1, 2)
    means = [np.column_stack([floor, np.zeros(len(floor))])]
    scales = [np.tile([0.16, 0.16, 0.01], (len(floor), 1))]
    ids = [np.full(len(floor), -1)]
    colours = [np.tile([0.1, 0.1, 0.1], (len(floor), 1))]
    instances = []
    for k, (label, centre, sides) in enumerate(OBJECTS):
        c, s = np.array(centre), np.array(sides)
        m, sc = _block(c, s, 4)
        means.append(m)
        scales.append(sc)
        ids.append(np.full(len(m), k))
        colours.append(np.tile(np.eye(3)[k] * 1.2 - 0.3, (len(m), 1)))
        instances.append(Instance(k, label, "", OrientedBox(c, s * 1.02, np.eye(3))))
    n = sum(len(m) for m in means)
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    g = Gaussians(np.concatenate(means), quats, np.concatenate(scales), np.full(n, 0.95),
                  np.concatenate(colours)[:, None, :], np.concatenate(ids).astype(np.int32))
    views = {}
    for v in range(4):
        angle = math.pi / 4 + v * math.pi / 2
        eye = np.array([2.6 * math.cos(angle), 2.6 * math.sin(angle), 1.5])
        views[f"DSC0{5860 + v}"] = Camera(140.0, 140.0, 80.0, 60.0, 160, 120, look_at(eye, np.array([0, 0, 0.3]), np.array([0, 0, 1.0])))
    return Scene(SCENE_ID, g, views, instances, [0.0, 0.0, 1.0], None, {})


def released(truth: Scene) -> Scene:
    """The truth in the world of the files: ScanNet++'s nerfstudio JSON frame (up is -z there)."""
    return truth.transformed(SCANNETPP_JSON[:3, :3], np.zeros(3))


def rle(mask: np.ndarray) -> dict:
    """COCO RLE of a bool mask as Holi-Spatial stores it (pycocotools, counts decoded to str)."""
    from pycocotools import mask as coco_mask

    enc = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(v) for v in enc["size"]], "counts": enc["counts"].decode("ascii")}


def box_records(scene: Scene, min_pixels: int = 20) -> list[dict]:
    """The scene's boxes and rendered instance masks, as the release's ``<scene id>.json``."""
    masks: dict[int, dict[str, np.ndarray]] = {}
    for view, cam in scene.views.items():
        rendered = render(scene.gaussians, cam, outputs="instance_ids").instance_ids
        for inst in scene.instances:
            if (rendered == inst.id).sum() >= min_pixels:
                masks.setdefault(inst.id, {})[f"{MASK_ROOT}/{scene.id}/{view}/{inst.label.replace(' ', '_')}.png"] = rendered == inst.id
    out = []
    for inst in scene.instances:
        box = inst.box
        transform = np.eye(4)
        transform[:3, :3], transform[:3, 3] = box.rotation, box.center
        paths = sorted(masks.get(inst.id, {}))
        out.append({
            "ins_id": str(inst.id), "label": inst.label,
            "bounding_box": [{"x": float(x), "y": float(y), "z": float(z)} for x, y, z in box.corners()],
            "obb_transform": transform.tolist(), "obb_extents": box.extents.tolist(), "images": paths,
            "highest_confidence_mask": max(paths, key=lambda p: int(masks[inst.id][p].sum())),
            "mask_encodings": [rle(masks[inst.id][p]) for p in paths],
        })
    return out


def write_release(root: Path, scene: Scene, records: list[dict] | None = None) -> Path:
    """``root/GS_model_w_mesh_pp/<id>`` (returned) and ``root/3d_bounding_box_pp/<id>.json``."""
    folder = root / "GS_model_w_mesh_pp" / scene.id
    (folder / "point_cloud" / "iteration_30000").mkdir(parents=True)
    (folder / "mesh").mkdir()
    (folder / "cfg_args").write_text(
        f"Namespace(data_device='cuda', eval=False, images='resized_undistorted_images', model_path='{folder}', resolution=-1, "
        f"sh_degree=0, source_path='/mnt/scannetppv2/data/{scene.id}/dslr/nerfstudio', white_background=False)"
    )
    (folder / "cameras.json").write_text(json.dumps(inria_cameras(scene)))
    (folder / "multi_view.json").write_text("".join(json.dumps({"ref_name": v, "nearest_name": []}) + "\n" for v in scene.views))
    write_ply(folder / "point_cloud" / "iteration_30000" / "point_cloud.ply", without_ids(scene.gaussians))
    write_ply(folder / "input.ply", without_ids(scene.gaussians.subset(slice(0, 20))))
    (folder / "mesh" / "tsdf_fusion_post.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    boxes = root / "3d_bounding_box_pp" / f"{scene.id}.json"
    boxes.parent.mkdir(parents=True, exist_ok=True)
    boxes.write_text(json.dumps(records if records is not None else box_records(scene), indent=2))
    return folder

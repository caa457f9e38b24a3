"""Write a known scene in the published layouts of other tools, for the importer's round trips.

Each writer follows the layout its project documents or writes (read there, re-stated here;
nothing is copied): INRIA 3DGS output folders (``cameras.json`` as ``camera_to_JSON`` writes it,
``cfg_args`` as the repr of its argparse Namespace, ``point_cloud/iteration_N/point_cloud.ply``),
COLMAP text models, nerfstudio ``transforms.json`` (OpenGL poses, ``frames`` + ``test_frames``,
``applied_transform``) with splatfacto's ``dataparser_transforms.json`` and its normalised ply,
ScanNet++ scene folders and ``segments_anno.json``, Holi-Spatial's instance JSON and SAM3 mask
folders, EmbodiedScan 9-DoF boxes, PlayCanvas compressed plys and ``.spz``.

The truth is a small synthetic room whose Gaussians carry instance ids; the files written
never carry them (real captures do not), so the importer has to assign them.
"""

from __future__ import annotations

import gzip
import json
import math
import struct
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from spacedg.render.gaussians import SH_C0, Gaussians, quat_from_matrix
from spacedg.scene.io import write_ply
from spacedg.scene.model import Scene

GL = np.diag([1.0, -1.0, -1.0, 1.0])
#: nerfstudio's colmap_to_json world change: rows (x, z, y) with the last negated: p_json = A p_colmap.
APPLIED = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])
#: ScanNet++'s nerfstudio JSON world (its toolkit's convert_frames): rows (y, x, -z) of the scan frame.
SCANNETPP_JSON = np.array([[0, 1.0, 0, 0], [1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 0, 0, 1.0]])


def truth_room(seed: int = 5, gaussians: int = 20_000, views: int = 10, shift: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Scene:
    """A small z-up synthetic room (ids on its Gaussians), optionally shifted away from the origin."""
    from spacedg.scene.synthetic import CaptureConfig, RoomConfig, generate_room

    room = generate_room(seed, RoomConfig(gaussians=gaussians, capture=CaptureConfig(160, 120, views, views), world_frame="z_up", row_probability=0.0))
    if any(shift):
        room = room.transformed(np.eye(3), np.asarray(shift, dtype=np.float64))
    return room


def without_ids(g: Gaussians) -> Gaussians:
    return replace(g, instance_ids=None)


# ----------------------------------------------------------------------------- COLMAP / INRIA
def write_colmap_text(folder: Path, scene: Scene, names: dict[str, str] | None = None) -> Path:
    """A COLMAP text model (cameras.txt: PINHOLE; images.txt: world-to-camera qvec/tvec; empty points3D.txt)."""
    folder.mkdir(parents=True, exist_ok=True)
    cams, imgs = ["# Camera list with one line of data per camera:", "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]"], [
        "# Image list with two lines of data per image:",
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
        "#   POINTS2D[] as (X, Y, POINT3D_ID)",
    ]
    for k, (view, cam) in enumerate(scene.views.items(), start=1):
        cams.append(f"{k} PINHOLE {cam.width} {cam.height} " + " ".join(repr(float(v)) for v in (cam.fx, cam.fy, cam.cx, cam.cy)))
        c2w = np.asarray(cam.cam_to_world, dtype=np.float64)
        rot = c2w[:3, :3].T
        t = -rot @ c2w[:3, 3]
        q = quat_from_matrix(rot)
        values = " ".join(repr(float(v)) for v in (*q, *t))
        imgs.append(f"{k} {values} {k} {(names or {}).get(view, view + '.jpg')}")
        imgs.append("")
    (folder / "cameras.txt").write_text("\n".join(cams) + "\n")
    (folder / "images.txt").write_text("\n".join(imgs) + "\n")
    (folder / "points3D.txt").write_text("# 3D point list with one line of data per point:\n")
    return folder


def inria_cameras(scene: Scene) -> list[dict]:
    """``cameras.json`` records as the INRIA writer makes them (centre, c2w rotation rows, focal from the FoV)."""
    out = []
    for k, (view, cam) in enumerate(scene.views.items()):
        c2w = np.asarray(cam.cam_to_world, dtype=np.float64)
        fovx = 2 * math.atan(cam.width / (2 * cam.fx))
        fovy = 2 * math.atan(cam.height / (2 * cam.fy))
        out.append({"id": k, "img_name": view, "width": cam.width, "height": cam.height, "position": c2w[:3, 3].tolist(),
                    "rotation": [row.tolist() for row in c2w[:3, :3]],
                    "fy": cam.height / (2 * math.tan(fovy / 2)), "fx": cam.width / (2 * math.tan(fovx / 2))})
    return out


def write_inria_output(root: Path, scene: Scene, *, with_colmap: bool = True) -> Path:
    """``root/data`` (images' COLMAP model in sparse/0) and ``root/output`` (the INRIA model folder)."""
    data, out = root / "data", root / "output"
    if with_colmap:
        write_colmap_text(data / "sparse" / "0", scene)
    out.mkdir(parents=True, exist_ok=True)
    source = str(data.resolve())
    (out / "cfg_args").write_text(
        f"Namespace(data_device='cuda', eval=False, images='images', model_path='{out}', resolution=-1, "
        f"sh_degree=3, source_path='{source}', white_background=False)"
    )
    (out / "cameras.json").write_text(json.dumps(inria_cameras(scene)))
    early = scene.gaussians.subset(slice(0, len(scene.gaussians) // 3))
    for iteration, g in ((7000, early), (30000, scene.gaussians)):
        folder = out / "point_cloud" / f"iteration_{iteration}"
        folder.mkdir(parents=True, exist_ok=True)
        write_ply(folder / "point_cloud.ply", without_ids(g))
    return out


# ----------------------------------------------------------------------------- nerfstudio
def transforms_json(scene: Scene, *, world: np.ndarray = np.eye(4), test_every: int = 8, applied: bool = True,
                    camera_model: str = "OPENCV") -> dict:
    """A nerfstudio transforms.json (per-frame intrinsics, OpenGL c2w in the frame ``world · scene``)."""
    frames, tests = [], []
    for k, (view, cam) in enumerate(scene.views.items()):
        c2w = world @ np.asarray(cam.cam_to_world, dtype=np.float64) @ GL
        frame = {"file_path": f"images/{view}.jpg", "transform_matrix": c2w.tolist(), "fl_x": cam.fx, "fl_y": cam.fy,
                 "cx": cam.cx, "cy": cam.cy, "w": cam.width, "h": cam.height}
        (tests if test_every and k % test_every == test_every - 1 else frames).append(frame)
    data: dict = {"camera_model": camera_model, "frames": frames, "test_frames": tests}
    if camera_model == "OPENCV":
        data.update(k1=0.0, k2=0.0, p1=0.0, p2=0.0)
    if applied:
        data["applied_transform"] = APPLIED[:3].tolist()
    return data


def splatfacto_normalisation(scene: Scene, world: np.ndarray) -> tuple[np.ndarray, float]:
    """nerfstudio's auto-orient-free normalisation: centre the cameras, scale so they fit in [-1, 1]."""
    centres = np.array([(world @ np.asarray(c.cam_to_world))[:3, 3] for c in scene.views.values()])
    transform = np.eye(4)
    transform[:3, 3] = -centres.mean(axis=0)
    moved = centres - centres.mean(axis=0)
    return transform, float(1.0 / np.abs(moved).max())


def write_splatfacto(folder: Path, scene: Scene, world: np.ndarray) -> tuple[Path, Path]:
    """``splat.ply`` in the normalised frame and ``dataparser_transforms.json`` beside it (as ns-export leaves them)."""
    transform, scale = splatfacto_normalisation(scene, world)
    total = transform @ world
    g = without_ids(scene.gaussians).transformed(total[:3, :3], total[:3, 3] * 1.0).transformed(scale=scale)
    folder.mkdir(parents=True, exist_ok=True)
    write_ply(folder / "splat.ply", g)
    (folder / "dataparser_transforms.json").write_text(json.dumps({"transform": transform[:3].tolist(), "scale": scale}))
    return folder / "splat.ply", folder / "dataparser_transforms.json"


# ----------------------------------------------------------------------------- annotations
def render_masks(scene: Scene, mask_root: Path) -> dict[int, dict[str, Path]]:
    """SAM3-style masks ``<mask_root>/<image stem>/<label>.png`` (0/255) from the truth instance ids."""
    from spacedg.render import render

    out: dict[int, dict[str, Path]] = {}
    for view, cam in scene.views.items():
        ids = render(scene.gaussians, cam, outputs="instance_ids").instance_ids
        for inst in scene.instances:
            mask = ids == inst.id
            if mask.sum() < 30:
                continue
            path = mask_root / view / f"{inst.label.replace(' ', '_')}_{inst.id:02d}.png"
            path.parent.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(path), (mask * 255).astype(np.uint8))
            out.setdefault(inst.id, {})[view] = path
    return out


def _rle(png: str) -> dict:
    """COCO RLE of a mask file, as Holi-Spatial stores it (pycocotools, counts decoded to str)."""
    from pycocotools import mask as coco_mask

    enc = coco_mask.encode(np.asfortranarray((cv2.imread(png, cv2.IMREAD_GRAYSCALE) > 0).astype(np.uint8)))
    return {"size": [int(v) for v in enc["size"]], "counts": enc["counts"].decode("ascii")}


def holi_spatial_json(scene: Scene, masks: dict[int, dict[str, Path]], *, world: np.ndarray = np.eye(4)) -> list[dict]:
    """Records as Holi-Spatial's 3d_bounding_instance_gs_rerun_da3.py writes them (+ the description step)."""
    out = []
    for k, inst in enumerate(sorted(scene.instances, key=lambda i: i.id), start=1):
        box = inst.box.transformed(world[:3, :3], world[:3, 3])
        transform = np.eye(4)
        transform[:3, :3], transform[:3, 3] = box.rotation, box.center
        paths = sorted(str(p.resolve()) for p in masks.get(inst.id, {}).values())
        out.append({
            "ins_id": str(inst.id),
            "label": inst.label,
            "bounding_box": [{"x": float(x), "y": float(y), "z": float(z)} for x, y, z in box.corners()],
            "obb_transform": transform.tolist(),
            "obb_extents": box.extents.tolist(),
            "images": paths,
            "highest_confidence_mask": paths[0] if paths else "",
            "mask_encodings": [_rle(p) for p in paths],
            "description": f"a {inst.description}" if inst.description else "",
        })
        if not paths:
            del out[-1]["highest_confidence_mask"]
    return out


def segments_anno(scene: Scene) -> dict:
    """ScanNet++ ``segments_anno.json`` with OBBs (normalizedAxes = the three axes one after the other)."""
    groups = []
    for inst in scene.instances:
        b = inst.box
        groups.append({"id": inst.id, "objectId": inst.id, "label": inst.label, "segments": [1, 2, 3],
                       "obb": {"centroid": b.center.tolist(), "axesLengths": b.extents.tolist(),
                               "normalizedAxes": b.rotation.T.reshape(-1).tolist(),
                               "min": b.corners().min(axis=0).tolist(), "max": b.corners().max(axis=0).tolist()}})
    return {"sceneId": scene.id, "segGroups": groups}


def zxy_angles(rot: np.ndarray) -> list[float]:
    """Euler angles (α, β, γ) with ``R = R_z(α) R_x(β) R_y(γ)`` (EmbodiedScan's "ZXY")."""
    beta = math.asin(max(-1.0, min(1.0, rot[2, 1])))
    return [math.atan2(-rot[0, 1], rot[1, 1]), beta, math.atan2(-rot[2, 0], rot[2, 2])]


def embodiedscan_infos(scene: Scene) -> dict:
    labels = sorted({i.label for i in scene.instances})
    cats = {label: k for k, label in enumerate(labels)}
    inst = [{"bbox_3d": [*i.box.center.tolist(), *i.box.extents.tolist(), *zxy_angles(i.box.rotation)],
             "bbox_label_3d": cats[i.label], "bbox_id": i.id} for i in scene.instances]
    return {"metainfo": {"categories": cats}, "data_list": [
        {"sample_idx": "scannet/other_scene", "instances": []},
        {"sample_idx": f"scannet/{scene.id}", "instances": inst},
    ]}


# ----------------------------------------------------------------------------- compressed formats
def _pack_unorm(value: np.ndarray, bits: int) -> np.ndarray:
    t = (1 << bits) - 1
    return np.clip(np.floor(value * t + 0.5), 0, t).astype(np.uint32)


def write_compressed_ply(path: Path, g: Gaussians) -> None:
    """PlayCanvas / SuperSplat compressed ply: 256-Gaussian chunks with bounds, 4 packed uint words, uchar SH."""
    n = len(g)
    chunks = (n + 255) // 256
    means = g.means.astype(np.float64)
    logs = np.log(g.scales.astype(np.float64))
    rgb = 0.5 + SH_C0 * g.sh[:, 0, :].astype(np.float64)
    cfields = [f"{m}_{a}" for m in ("min", "max") for a in "xyz"] + [f"{m}_scale_{a}" for m in ("min", "max") for a in "xyz"] \
        + [f"{m}_{c}" for m in ("min", "max") for c in "rgb"]
    chunk = np.zeros(chunks, dtype=[(f, "<f4") for f in cfields])
    pos = np.zeros(n, np.uint32)
    sca = np.zeros(n, np.uint32)
    col = np.zeros(n, np.uint32)
    for c in range(chunks):
        sl = slice(256 * c, min(n, 256 * (c + 1)))

        def norm(v: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
            return np.where(hi > lo, (v - lo) / np.where(hi > lo, hi - lo, 1), 0.0)

        for key, values in (("", means[sl]), ("scale_", logs[sl])):
            lo, hi = values.min(axis=0), values.max(axis=0)
            for j, a in enumerate("xyz"):
                chunk[f"min_{key}{a}"][c], chunk[f"max_{key}{a}"][c] = lo[j], hi[j]
            lo32 = np.array([chunk[f"min_{key}{a}"][c] for a in "xyz"], np.float64)
            hi32 = np.array([chunk[f"max_{key}{a}"][c] for a in "xyz"], np.float64)
            t = norm(values, lo32, hi32)
            word = (_pack_unorm(t[:, 0], 11) << 21) | (_pack_unorm(t[:, 1], 10) << 11) | _pack_unorm(t[:, 2], 11)
            (pos if key == "" else sca)[sl] = word
        lo, hi = rgb[sl].min(axis=0), rgb[sl].max(axis=0)
        for j, ch in enumerate("rgb"):
            chunk[f"min_{ch}"][c], chunk[f"max_{ch}"][c] = lo[j], hi[j]
        t = norm(rgb[sl], np.array([chunk[f"min_{ch}"][c] for ch in "rgb"], np.float64), np.array([chunk[f"max_{ch}"][c] for ch in "rgb"], np.float64))
        col[sl] = (_pack_unorm(t[:, 0], 8) << 24) | (_pack_unorm(t[:, 1], 8) << 16) | (_pack_unorm(t[:, 2], 8) << 8) \
            | _pack_unorm(g.opacities[sl].astype(np.float64), 8)
    q = g.quats.astype(np.float64)  # (w, x, y, z) = (rot_0..rot_3)
    largest = np.abs(q).argmax(axis=1)
    q = q * np.where(q[np.arange(n), largest] < 0, -1.0, 1.0)[:, None]
    rot = largest.astype(np.uint32)
    for i in range(4):
        other = largest != i
        rot = np.where(other, (rot << 10) | _pack_unorm(q[:, i] * (math.sqrt(2) * 0.5) + 0.5, 10), rot)
    vertex = np.zeros(n, dtype=[("packed_position", "<u4"), ("packed_rotation", "<u4"), ("packed_scale", "<u4"), ("packed_color", "<u4")])
    vertex["packed_position"], vertex["packed_rotation"], vertex["packed_scale"], vertex["packed_color"] = pos, rot, sca, col
    k = g.sh.shape[1]
    header = ["ply", "format binary_little_endian 1.0", "comment generated by a test (PlayCanvas compressed layout)",
              f"element chunk {chunks}", *[f"property float {f}" for f in cfields],
              f"element vertex {n}", *[f"property uint {f}" for f in vertex.dtype.names]]
    sh_bytes = b""
    if k > 1:
        rest = g.sh[:, 1:, :].transpose(0, 2, 1).reshape(n, -1).astype(np.float64)  # channel-major like f_rest
        sh = np.clip(np.floor((rest + 4.0) * 255.0 / 8.0 + 0.5), 0, 255).astype(np.uint8)
        header += [f"element sh {n}", *[f"property uchar f_rest_{i}" for i in range(sh.shape[1])]]
        sh_bytes = sh.tobytes()
    header.append("end_header")
    path.write_bytes(("\n".join(header) + "\n").encode() + chunk.tobytes() + vertex.tobytes() + sh_bytes)


def write_spz(path: Path, g: Gaussians, *, version: int = 3, frac_bits: int = 12) -> None:
    """Niantic .spz (gzip; header, positions, alphas, colours, scales, rotations, SH), from the format spec.
    The Gaussians are given in RDF and stored RUB, as Niantic's packer does with from=RDF."""
    g = g.transformed(np.diag([1.0, -1.0, -1.0]))
    n, k = len(g), g.sh.shape[1]
    degree = {1: 0, 4: 1, 9: 2, 16: 3}[k]
    fixed = np.round(g.means.astype(np.float64) * (1 << frac_bits)).astype(np.int64) & 0xFFFFFF
    pos = np.stack([(fixed >> s) & 0xFF for s in (0, 8, 16)], axis=-1).astype(np.uint8).reshape(n, 9)
    alpha = np.clip(np.round(g.opacities.astype(np.float64) * 255), 0, 255).astype(np.uint8)[:, None]
    colour = np.clip(np.round((g.sh[:, 0, :].astype(np.float64) * 0.15 + 0.5) * 255), 0, 255).astype(np.uint8)
    scale = np.clip(np.round((np.log(g.scales.astype(np.float64)) + 10.0) * 16), 0, 255).astype(np.uint8)
    xyzw = g.quats.astype(np.float64)[:, [1, 2, 3, 0]]
    if version >= 3:
        largest = np.abs(xyzw).argmax(axis=1)
        xyzw = xyzw * np.where(xyzw[np.arange(n), largest] < 0, -1.0, 1.0)[:, None]
        word = largest.astype(np.uint32)
        for i in range(4):
            other = largest != i
            mag = np.clip(np.round(np.abs(xyzw[:, i]) / math.sqrt(0.5) * 511), 0, 511).astype(np.uint32)
            sign = (xyzw[:, i] < 0).astype(np.uint32)
            word = np.where(other, (word << 10) | (sign << 9) | mag, word)
        rot = word.astype("<u4").view(np.uint8).reshape(n, 4)
    else:
        xyzw = xyzw * np.where(xyzw[:, 3] < 0, -1.0, 1.0)[:, None]
        rot = np.clip(np.round((xyzw[:, :3] + 1.0) * 127.5), 0, 255).astype(np.uint8)
    parts = [struct.pack("<IIIBBBB", 0x5053474E, version, n, degree, frac_bits, 0, 0), pos.tobytes(), alpha.tobytes(),
             colour.tobytes(), scale.tobytes(), rot.tobytes()]
    if k > 1:
        parts.append(np.clip(np.round(g.sh[:, 1:, :].astype(np.float64) * 128 + 128), 0, 255).astype(np.uint8).tobytes())
    path.write_bytes(gzip.compress(b"".join(parts)))


def write_scannetpp_dslr(scene_dir: Path, scene: Scene) -> Path:
    """A ScanNet++ scene folder as published (no Gaussians): ``dslr/nerfstudio/transforms_undistorted.json``,
    whose world is the scan frame with rows (y, x, -z) (:data:`SCANNETPP_JSON`), and
    ``scans/segments_anno.json`` with the boxes in the scan frame. Returns ``scene_dir``."""
    ns = scene_dir / "dslr" / "nerfstudio"
    ns.mkdir(parents=True)
    (ns / "transforms_undistorted.json").write_text(json.dumps(transforms_json(scene, world=SCANNETPP_JSON, applied=False,
                                                                               camera_model="PINHOLE")))
    (scene_dir / "scans").mkdir()
    (scene_dir / "scans" / "segments_anno.json").write_text(json.dumps(segments_anno(scene)))
    return scene_dir


# ----------------------------------------------------------------------------- ScanNet++ iPhone (ARKit)
#: ARKit's own session world of the iPhone fixture: a rigid change away from the scan frame (``pose`` is given in it).
ARKIT_WORLD = np.array([[0.0, 0.0, 1.0, 2.0], [1.0, 0.0, 0.0, -1.0], [0.0, 1.0, 0.0, 0.5], [0.0, 0.0, 0.0, 1.0]])


def pose_intrinsic_imu(scene: Scene, *, extra_frames: int = 0, flat: bool = False) -> dict:
    """ScanNet++'s ``iphone/pose_intrinsic_imu.json`` for ``scene``'s views (metres, scan frame), as its toolkit reads it
    (``iphone/arkit_pcl.py``): ``frame_NNNNNN`` → ``aligned_pose`` (4×4 camera-to-world, OpenCV axes, scan frame),
    ``pose`` (the same in ARKit's own world, :data:`ARKIT_WORLD`), ``intrinsic`` (3×3 K of the 1920×1440 frames: the
    views' K scaled from their size), ``timestamp`` and ``imu`` (not read). Frames are numbered 0, 10, 20, ... in view
    order, then ``extra_frames`` more between them (frames not extracted to ``rgb/``). ``flat``: matrices as flat lists."""
    out = {}
    cams = list(scene.views.values())
    for k in range(len(cams) + extra_frames):
        cam = cams[k % len(cams)]
        number = 10 * k if k < len(cams) else 10 * (k - len(cams)) + 5
        sx, sy = 1920 / cam.width, 1440 / cam.height
        kmat = [[cam.fx * sx, 0.0, cam.cx * sx], [0.0, cam.fy * sy, cam.cy * sy], [0.0, 0.0, 1.0]]
        pose = np.asarray(cam.cam_to_world, dtype=np.float64)
        mats = {"aligned_pose": pose.tolist(), "pose": (ARKIT_WORLD @ pose).tolist(), "intrinsic": kmat}
        if flat:
            mats = {key: np.asarray(v).ravel().tolist() for key, v in mats.items()}
        out[f"frame_{number:06d}"] = {"timestamp": 1000.0 + number / 60.0, **mats,
                                      "imu": {"gravity": [0.0, -9.81, 0.0], "rotation_rate": [0.0, 0.0, 0.0]}}
    return out


def write_scannetpp_iphone(scene_dir: Path, scene: Scene, *, rgb: bool = True, colmap: float | None = None, extra_frames: int = 2) -> Path:
    """A ScanNet++ scene folder with the iPhone's ARKit cameras as published: ``iphone/pose_intrinsic_imu.json``
    (:func:`pose_intrinsic_imu`), the frames extracted to ``iphone/rgb/frame_NNNNNN.jpg`` at the views' size (``rgb``;
    the extra frames not extracted), ``iphone/colmap/`` when ``colmap`` is a number (the same frames, scan frame,
    their centres ``colmap`` metres along +x from ARKit's: refined poses differ) and ``scans/segments_anno.json``."""
    iphone = scene_dir / "iphone"
    iphone.mkdir(parents=True)
    data = pose_intrinsic_imu(scene, extra_frames=extra_frames)
    (iphone / "pose_intrinsic_imu.json").write_text(json.dumps(data))
    names = {view: f"frame_{10 * k:06d}.jpg" for k, view in enumerate(scene.views)}
    if rgb:
        (iphone / "rgb").mkdir()
        for view, name in names.items():
            cam = scene.views[view]
            cv2.imwrite(str(iphone / "rgb" / name), np.full((cam.height, cam.width, 3), 128, np.uint8))
    if colmap is not None:
        moved = {}
        for view, cam in scene.views.items():
            pose = np.array(cam.cam_to_world, dtype=np.float64)
            pose[0, 3] += colmap
            moved[view] = cam.with_pose(pose)
        write_colmap_text(iphone / "colmap", Scene(scene.id, scene.gaussians, moved, scene.instances, scene.up, None, {}), names)
    (scene_dir / "scans").mkdir()
    (scene_dir / "scans" / "segments_anno.json").write_text(json.dumps(segments_anno(scene)))
    return scene_dir

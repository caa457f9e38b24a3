"""``import_scene``: a real capture (INRIA / COLMAP / nerfstudio / ScanNet++ + instance boxes) → a native scene folder.

What it does, in order (each step reported in :class:`ImportReport`):

1. **Detect the layout** of ``src`` (or take ``format``): an INRIA output folder
   (``point_cloud/iteration_*/point_cloud.ply``, the latest iteration; cameras from ``cfg_args``'
   ``source_path/sparse/0`` when it exists, else ``cameras.json``); a COLMAP project or model
   folder + a Gaussians file; a nerfstudio data folder or ``transforms.json`` (``frames`` and
   ``test_frames``) + a Gaussians file (a splatfacto export is brought back from nerfstudio's
   normalised frame with ``dataparser_transforms.json``, found next to the ply or given); a
   ScanNet++ scene folder (DSLR or iPhone nerfstudio JSON, ``scans/segments_anno.json`` boxes,
   Gaussians given or found in an INRIA output below it); a Holi-Spatial released scene (a PGSR
   output folder with ``mesh/tsdf_fusion_post.ply``, its boxes in ``3d_bounding_box[_pp]/<scene>.json``
   beside it, their COCO RLE masks voting the instance ids: :mod:`spacedg.scene.io.holispatial`);
   or a bare Gaussians file + cameras.
2. **Read** the Gaussians (INRIA ply, PlayCanvas compressed ply, colour-only ply, Mip-Splatting
   ``filter_3D``, ``.splat``, ``.spz``), the cameras and the instances (spacedg / Holi-Spatial JSON,
   ScanNet++ ``segments_anno.json``, EmbodiedScan JSON), apply ``metres_per_unit`` once to all.
   **Units** (:mod:`spacedg.scene.units`): given, metric by construction, or unknown and checked
   against the labelled objects' typical sizes (refused when implausible); recorded in ``metadata["units"]``.
3. **Up**: given (``"+z"``, ``"-y"``, ``"0,0,1"``), ScanNet++'s +z, or estimated from the cameras (else the
   boxes), and verified against the capture's evidence (:mod:`spacedg.scene.up_evidence`): a contradicted up is
   refused unless ``trust_up``; the evidence is kept in ``metadata.up_evidence``. Up, units and the box fill
   are decided by :mod:`spacedg.scene.capture_checks`, which :func:`~spacedg.scene.io.scene_from_files` runs too.
4. **Frame check** (:mod:`spacedg.scene.frame_check`): refused with the disagreeing parts and the
   probable cause unless ``frame_check="warn"``.
4b. **Box fill** (:mod:`spacedg.scene.box_fill`): every box must hold its object; an empty, shifted or
   mostly outside box is refused naming the box, the shift that fits it best and the causes that fit
   the layout, unless ``frame_check="warn"``; the summary and the fill table share its numbers.
5. **Instance ids**: kept when the Gaussians carry them; otherwise assigned
   (:func:`~spacedg.scene.labelling.assign_instances`, by boxes unless masks are asked for) and
   reported per instance (with the rendered-mask IoU where Holi-Spatial mask files are found).
6. **Write** the native scene folder (``scene.json`` + ``gaussians.ply``) that every command takes.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from spacedg.errors import FileFormatError, ParameterError
from spacedg.files import PathLike, read_json
from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians
from spacedg.scene.box_fill import BoxFillReport, measure_box_fill
from spacedg.scene.capture_checks import FRAME_CHECKS, FrameDecision, check_box_fill, check_metres_per_unit, decide_frame, parse_up
from spacedg.scene.frame_check import (
    FrameReport,
    check_frame,
    diagnose,
    generic_corrections,
    normalised_hint,
)
from spacedg.scene.io import (
    GAUSSIAN_SUFFIXES,
    read_gaussians,
    read_instances,
    save_scene,
)
from spacedg.scene.io.capture import (
    CameraFiles,
    colmap_model,
    find_cameras,
    read_cameras,
    scale_gaussians,
    scale_instances,
    scale_views,
)
from spacedg.scene.io.embodiedscan import read_embodiedscan_boxes
from spacedg.scene.io.holispatial import find_release_boxes, is_release_scene, rle_masks
from spacedg.scene.io.inria import (
    at_training_scale,
    is_inria_output,
    latest_point_cloud,
    read_cfg_args,
)
from spacedg.scene.io.nerfstudio import (
    denormalising_similarity,
    read_applied_transform,
    read_dataparser_transforms,
)
from spacedg.scene.io.scannetpp import (
    NERFSTUDIO_FROM_SCAN,
    is_scannetpp_scene,
    read_segments_anno,
    scannetpp_cameras,
)
from spacedg.scene.io.scannetpp_iphone import POSE_FILE, arkit_agreement
from spacedg.scene.labelling import AssignmentReport, MaskSource, assign_instances, load_mask
from spacedg.scene.model import Instance, Scene
from spacedg.scene.units import UnitDecision

__all__ = ["LAYOUTS", "CaptureLayout", "ImportReport", "import_scene", "detect_layout", "detect_capture", "parse_up", "read_any_instances"]

#: Layouts :func:`import_scene` knows (``format=``).
LAYOUTS = ("auto", "inria", "colmap", "nerfstudio", "scannetpp", "holi-spatial", "gaussians")
_SAFE_ID = re.compile(r"[^A-Za-z0-9_.\-]+")


@dataclass
class ImportReport:
    """What :func:`import_scene` found and did (printed by ``spacedg scenes import``)."""

    scene_id: str
    layout: str
    out: Path | None
    gaussians_path: str
    gaussians: int
    sh_degree: int
    views: int
    test_views: int
    cameras_path: str
    instances: int
    instances_path: str | None
    up: list[float]
    up_source: str
    metres_per_unit: float
    frame: FrameReport
    ids: str
    assignment: AssignmentReport | None = None
    box_fill: BoxFillReport | None = None
    notes: list[str] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    units: UnitDecision | None = None

    def text(self) -> str:
        """Human-readable summary, one fact per line."""
        lines = [
            f"layout       {self.layout}",
            f"gaussians    {self.gaussians:,} (SH degree {self.sh_degree}) from {self.gaussians_path}",
            f"views        {self.views} ({self.test_views} of them test views) from {self.cameras_path}",
            f"instances    {self.instances}" + (f" from {self.instances_path}" if self.instances_path else " (no annotation given)"),
            f"up           {[round(v, 4) for v in self.up]} ({self.up_source}); {self.metres_per_unit:g} m per file unit",
            f"frame check  {'ok' if self.frame.ok else 'MISMATCH'}: {self.frame.summary()}",
        ]
        if self.units is not None:
            lines.append(self.units.text())
        if self.box_fill is not None:
            lines += [f"box fill     {self.box_fill.summary()}", self.box_fill.table()]
        lines += [f"note         {n}" for n in self.notes]
        if self.assignment is not None:
            a = self.assignment
            iou = a.mean_mask_iou()
            covered = [c.box_coverage for c in a.instances if c.gaussians]
            lines.append(
                f"instance ids {self.ids}: {a.assigned:,} of {a.total:,} Gaussians assigned in {a.seconds:.2f} s, "
                f"{len(a.empty_instances)} instance(s) got none, mean box coverage "
                f"{np.mean(covered) if covered else 0:.0%}" + (f", mean rendered-mask IoU {iou:.2f}" if iou is not None else "")
            )
            lines.append(a.table())
        else:
            lines.append(f"instance ids {self.ids}")
        if self.out is not None:
            lines.append(f"wrote        {self.out}")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "scene_id": self.scene_id, "layout": self.layout, "out": None if self.out is None else str(self.out),
            "gaussians_path": self.gaussians_path, "gaussians": self.gaussians, "sh_degree": self.sh_degree,
            "views": self.views, "test_views": self.test_views, "cameras_path": self.cameras_path,
            "instances": self.instances, "instances_path": self.instances_path, "up": self.up, "up_source": self.up_source,
            "metres_per_unit": self.metres_per_unit, "frame_check": self.frame.to_dict(), "ids": self.ids,
            "assignment": None if self.assignment is None else self.assignment.to_dict(),
            "box_fill": None if self.box_fill is None else self.box_fill.to_dict(), "notes": list(self.notes),
            "seconds": {k: round(v, 3) for k, v in self.seconds.items()},
            "units": None if self.units is None else self.units.to_dict(),
        }


# --------------------------------------------------------------------------- detection
@dataclass(frozen=True)
class CaptureLayout:
    """The layout of a capture, detected once (:func:`detect_capture`) and passed along.

    Attributes:
        name: one of :data:`LAYOUTS` other than ``"auto"``.
        colmap: the COLMAP model folder found while detecting a ``"colmap"`` layout (``None`` otherwise).
    """

    name: str
    colmap: Path | None = None


def detect_capture(src: Path) -> CaptureLayout:
    """The layout of ``src`` (see :data:`LAYOUTS`), inspecting it once; :class:`FileFormatError` naming what was looked for."""
    if src.is_file():
        if src.suffix.lower() in GAUSSIAN_SUFFIXES or src.suffix.lower() == ".ksplat":
            return CaptureLayout("gaussians")
        if src.suffix.lower() == ".json":
            return CaptureLayout("nerfstudio")
        raise FileFormatError(f"{src}: not a Gaussians file ({', '.join(GAUSSIAN_SUFFIXES)}) nor a transforms.json")
    if not src.is_dir():
        raise FileFormatError(f"{src}: no such file or folder")
    if (src / "scene.json").is_file():
        raise FileFormatError(
            f"{src}: already a spacedg scene folder (scene.json + gaussians.ply): every command takes it as it is, there is "
            f"nothing to import; `spacedg scenes info {src}` prints its units, up check and boxes"
        )
    if is_release_scene(src):
        return CaptureLayout("holi-spatial")
    if is_inria_output(src):
        return CaptureLayout("inria")
    if is_scannetpp_scene(src):
        return CaptureLayout("scannetpp")
    if (src / "transforms.json").is_file():
        return CaptureLayout("nerfstudio")
    model = colmap_model(src)
    if model is not None:
        return CaptureLayout("colmap", model)
    raise FileFormatError(
        f"{src}: no known layout: looked for an INRIA output (point_cloud/iteration_*/point_cloud.ply), a ScanNet++ scene "
        "(dslr/nerfstudio, iphone/nerfstudio, iphone/pose_intrinsic_imu.json, scans/segments_anno.json), a Holi-Spatial released "
        "scene (mesh/tsdf_fusion_post.ply), a nerfstudio transforms.json, a COLMAP model (sparse/0 or cameras.bin/txt); "
        "pass --format, or a Gaussians file with --cameras"
    )


def detect_layout(src: Path) -> str:
    """The name of the layout of ``src`` (:func:`detect_capture`)."""
    return detect_capture(src).name


def _single_gaussians_file(folder: Path, what: str) -> Path:
    found = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in GAUSSIAN_SUFFIXES and p.name != "input.ply")
    if len(found) == 1:
        return found[0]
    listing = ", ".join(p.name for p in found[:5]) or "none"
    raise FileFormatError(f"{folder}: {what} needs a Gaussians file: pass --gaussians FILE (found {len(found)}: {listing})")


def read_any_instances(path: PathLike, views: Any = None, *, embodiedscan_scene: str | None = None,
                       data: Any = None) -> tuple[list[Instance], str]:
    """Instances from a spacedg / Holi-Spatial JSON, a ScanNet++ ``segments_anno.json`` or an
    EmbodiedScan JSON (told apart by content; ``data``: the file already parsed); returns ``(instances, format name)``."""
    p = Path(path)
    data = read_json(p, "instance JSON") if data is None else data
    if isinstance(data, dict) and "segGroups" in data:
        return read_segments_anno(p, data=data), "scannetpp segments_anno"
    first = data[0] if isinstance(data, list) and data else None
    if (isinstance(data, dict) and ("data_list" in data or ("instances" in data and data["instances"]
                                                            and isinstance(data["instances"][0], dict) and "bbox_3d" in data["instances"][0]))) \
            or (isinstance(first, dict) and "bbox_3d" in first):
        return read_embodiedscan_boxes(p, embodiedscan_scene, data=data), "embodiedscan"
    holi = isinstance(first, dict) and ("ins_id" in first or "bounding_box" in first)
    return read_instances(p, views=views, data=data), "holi-spatial" if holi else "spacedg"


def _scene_id(name: str | None, src: Path) -> str:
    raw = name if name is not None else (src.stem if src.is_file() else src.name)
    sid = _SAFE_ID.sub("-", raw).strip("-.") or "scene"
    if name is not None and sid != name:
        raise ParameterError(f"--name {name!r}: use letters, digits, '_', '.', '-' (e.g. {sid!r})")
    return sid if sid[0].isalnum() else "s" + sid


def _move_views(views: dict[str, Camera], matrix: np.ndarray) -> dict[str, Camera]:
    """Poses moved by the rigid world transform ``matrix`` (4×4): ``p' = M p``."""
    return {n: c.with_pose(matrix @ np.asarray(c.cam_to_world, dtype=np.float64)) for n, c in views.items()}


# --------------------------------------------------------------------------- import
@dataclass
class _Parts:
    layout: str
    gaussians_path: Path
    cameras: CameraFiles
    instances_path: Path | None
    dataparser: Path | None
    applied_transform: np.ndarray | None
    default_up: np.ndarray | None
    up_note: str
    notes: list[str]
    #: (4×4 rigid world change, the parts it applies to: "views", "gaussians", "instances") into the scan frame.
    to_scan: tuple[np.ndarray, frozenset[str]] | None = None
    #: ScanNet++'s iPhone ARKit poses, compared with the (COLMAP-refined) cameras used when both exist.
    arkit: Path | None = None
    #: an INRIA output's ``cfg_args`` ``(resolution, images)``: the size its Gaussians were trained at; ``None``: not one.
    inria_training: tuple[Any, Any] | None = None


def _cfg_args(src: Path) -> tuple[dict[str, Any] | None, FileFormatError | None]:
    """``src/cfg_args`` read once per import: ``(arguments, None)``, ``(None, the reading error)`` or
    ``(None, None)`` without one."""
    cfg = src / "cfg_args"
    if not cfg.is_file():
        return None, None
    try:
        return read_cfg_args(cfg), None
    except FileFormatError as err:
        return None, err


def _inria_cameras(src: Path, notes: list[str], cfg: tuple[dict[str, Any] | None, FileFormatError | None]) -> CameraFiles:
    args, error = cfg
    if error is not None:
        raise error
    if args is not None:
        source = args.get("source_path")
        if isinstance(source, str) and source:
            for base in (Path(source), src / source, src.parent / source):
                model = colmap_model(base) if base.is_dir() else None
                if model is not None:
                    notes.append(f"cameras from the COLMAP model of cfg_args' source_path ({model})")
                    return CameraFiles("colmap", model, model)
            notes.append(f"cfg_args' source_path {source!r} has no COLMAP model here; cameras from cameras.json (principal point at the image centre)")
    if (src / "cameras.json").is_file():
        return CameraFiles("inria", src / "cameras.json", src / "cameras.json")
    raise FileFormatError(f"{src}: INRIA output without cameras: neither cfg_args' source_path/sparse/0 nor cameras.json; pass --cameras")


def _resolve_parts(
    src: Path, layout: CaptureLayout, gaussians: Path | None, cameras: Path | None, instances: Path | None,
    dataparser: Path | None, device: str,
) -> _Parts:
    notes: list[str] = []
    default_up, up_note = None, ""
    to_scan: tuple[np.ndarray, frozenset[str]] | None = None
    arkit: Path | None = None
    given = None if cameras is None else find_cameras(cameras)
    cfg = _cfg_args(src) if layout.name in ("inria", "holi-spatial") else (None, None)
    if layout.name == "inria":
        gpath = gaussians or latest_point_cloud(src)
        if gaussians is None:
            notes.append(f"Gaussians of the latest iteration: {gpath.relative_to(src)}")
        files = given or _inria_cameras(src, notes, cfg)
    elif layout.name == "colmap":
        model = layout.colmap if layout.colmap is not None else colmap_model(src)
        if model is None and given is None:
            raise FileFormatError(f"{src}: no COLMAP model (cameras + images .bin/.txt) here or in sparse/0")
        files = given or CameraFiles("colmap", model, model)  # type: ignore[arg-type]
        gpath = gaussians or _single_gaussians_file(src, "a COLMAP model")
    elif layout.name == "nerfstudio":
        files = given or find_cameras(src if src.is_file() else src / "transforms.json")
        gpath = gaussians or _single_gaussians_file(src if src.is_dir() else src.parent, "a nerfstudio transforms.json")
    elif layout.name == "scannetpp":
        files, gpath, instances, to_scan, arkit = _scannetpp_parts(src, given, gaussians, instances, device, notes)
        default_up, up_note = np.array([0.0, 0.0, 1.0]), "ScanNet++ scan frame (z up)"
    elif layout.name == "holi-spatial":
        gpath = gaussians or latest_point_cloud(src)
        files = given or _inria_cameras(src, notes, cfg)
        instances = instances or find_release_boxes(src)
        if instances is None:
            raise FileFormatError(
                f"{src}: a Holi-Spatial scene folder without its boxes: looked for 3d_bounding_box_pp/{src.name}.json "
                f"(ScanNet v2: 3d_bounding_box/{src.name}.json) next to the scene's parent folders; pass --instances FILE"
            )
        default_up, up_note, to_scan = _holi_frame(src, instances, notes)
    elif layout.name == "gaussians":
        if given is None:
            raise ParameterError(f"{src}: a bare Gaussians file needs --cameras (a COLMAP model folder, a transforms.json or an INRIA cameras.json)")
        gpath, files = gaussians or src, given
    else:
        raise ParameterError(f"--format {layout.name!r}: choose one of {', '.join(LAYOUTS)}")
    if dataparser is None and (gpath.parent / "dataparser_transforms.json").is_file():
        dataparser = gpath.parent / "dataparser_transforms.json"
        notes.append(f"found {dataparser.name} next to the Gaussians: they are a splatfacto export in nerfstudio's normalised frame")
    applied = read_applied_transform(files.read_path) if files.kind == "nerfstudio" else None
    return _Parts(layout.name, Path(gpath), files, instances, dataparser, applied, default_up, up_note, notes, to_scan, arkit,
                  _inria_training(cfg, notes))


def _inria_training(cfg: tuple[dict[str, Any] | None, FileFormatError | None], notes: list[str]) -> tuple[Any, Any] | None:
    """``cfg_args``' ``(resolution, images)`` (:func:`_cfg_args`) of an INRIA output (or Holi-Spatial scene)
    folder; ``None`` without one, or when it cannot be read (noted: the cameras' own size is used)."""
    args, error = cfg
    if error is not None:
        notes.append(f"{error}: the Gaussians are taken as trained at the cameras' own size")
    return None if args is None else (args.get("resolution", -1), args.get("images"))


def _scannetpp_parts(
    src: Path, given: CameraFiles | None, gaussians: Path | None, instances: Path | None, device: str, notes: list[str],
) -> tuple[CameraFiles, Path, Path | None, tuple[np.ndarray, frozenset[str]] | None, Path | None]:
    """A ScanNet++ scene folder's cameras, Gaussians, boxes, world change and ARKit file to compare."""
    files = given or find_cameras(scannetpp_cameras(src, device))
    if instances is None and (src / "scans" / "segments_anno.json").is_file():
        instances = src / "scans" / "segments_anno.json"
    if gaussians is None:
        found = sorted(src.glob("**/point_cloud/iteration_*/point_cloud.ply"))
        if not found:
            raise FileFormatError(
                f"{src}: ScanNet++ ships no Gaussians: train them on the DSLR images (INRIA, gsplat or splatfacto) and pass --gaussians FILE"
            )
        gaussians = latest_point_cloud(found[-1].parents[2])
        notes.append(f"Gaussians found in the scene folder: {gaussians}")
    to_scan = None
    if given is None and files.kind == "nerfstudio":
        to_scan = (NERFSTUDIO_FROM_SCAN, frozenset({"views", "gaussians"}))
        notes.append("cameras and Gaussians taken from ScanNet++'s nerfstudio world (rows y, x, -z) back to the scan frame "
                     "of the mesh and segments_anno.json")
    arkit = src / "iphone" / POSE_FILE
    if files.kind == "scannetpp-iphone":
        notes.append(f"cameras: ARKit aligned_pose of {files.path} (scan frame, OpenCV axes); no iphone/nerfstudio or "
                     "iphone/colmap (bundle-adjusted poses, preferred when present) here")
    return files, gaussians, instances, to_scan, arkit if device == "iphone" and files.kind != "scannetpp-iphone" and arkit.is_file() else None


def _holi_frame(src: Path, boxes: Path, notes: list[str]) -> tuple[np.ndarray | None, str, tuple[np.ndarray, frozenset[str]] | None]:
    """Up, its reason and the world change of a Holi-Spatial release scene, by its dataset: ScanNet++
    (``3d_bounding_box_pp``, 10-hex-digit ids) was trained on the nerfstudio JSON (world rows y, x, -z of the
    scan frame), ScanNet v2 (``sceneNNNN_NN``) on the scan's own poses; both metric. Others: up from the cameras."""
    if re.fullmatch(r"scene\d{4}_\d{2}", src.name) or boxes.parent.name == "3d_bounding_box":
        notes.append("units: metres by construction (Holi-Spatial trains PGSR on ScanNet's metric poses, un-normalised)")
        return np.array([0.0, 0.0, 1.0]), "Holi-Spatial ScanNet v2 scene: ScanNet's scan frame (z up)", None
    if re.fullmatch(r"[0-9a-f]{10}", src.name) or boxes.parent.name == "3d_bounding_box_pp":
        notes.append("units: metres by construction (Holi-Spatial trains PGSR on ScanNet++'s metric poses, un-normalised)")
        notes.append("Gaussians, cameras and boxes taken from ScanNet++'s nerfstudio world (rows y, x, -z) back to its scan frame")
        return (np.array([0.0, 0.0, 1.0]), "Holi-Spatial ScanNet++ scene: ScanNet++'s scan frame (z up)",
                (NERFSTUDIO_FROM_SCAN, frozenset({"views", "gaussians", "instances"})))
    notes.append("units: not known (neither a ScanNet++ nor a ScanNet v2 scene id): check them, or give --metres-per-unit")
    return None, "", None


def import_scene(
    src: PathLike,
    out: PathLike | None = None,
    *,
    instances: PathLike | None = None,
    format: str = "auto",
    name: str | None = None,
    up: str | np.ndarray | None = "auto",
    metres_per_unit: float | None = None,
    units: Literal["auto", "metric"] = "auto",
    gaussians: PathLike | None = None,
    cameras: PathLike | None = None,
    dataparser_transforms: PathLike | None = None,
    undo_applied_transform: bool = False,
    masks: PathLike | None = None,
    assign: Literal["auto", "boxes", "masks", "none"] = "auto",
    device: str = "dslr",
    embodiedscan_scene: str | None = None,
    opencv_distortion: Literal["error", "drop"] = "error",
    frame_check: Literal["error", "warn"] = "error",
    trust_up: bool = False,
    overwrite: bool = False,
    progress: bool = True,
    backend: str = "auto",
) -> tuple[Scene, ImportReport]:
    """Turn a real capture into a native scene folder (see the module docstring).

    Args:
        src: the capture: an INRIA output folder, a COLMAP project/model folder, a nerfstudio data
            folder or ``transforms.json``, a ScanNet++ scene folder, or a Gaussians file.
        out: the scene folder to write (``None``: build and check only).
        instances: instance annotation (spacedg / Holi-Spatial JSON, ScanNet++ ``segments_anno.json``,
            EmbodiedScan JSON); ScanNet++ folders default to their own ``segments_anno.json``.
        format: one of :data:`LAYOUTS` (``"auto"`` detects).
        name: scene id (default: the folder or file name).
        up: ``"auto"`` (ScanNet++: +z; otherwise estimated from the cameras), an axis (``"+z"``,
            ``"-y"``) or three numbers, in the **files'** frame.
        metres_per_unit: metres per file unit, applied once to Gaussians, cameras and boxes; ``None``
            (not given): decided by :func:`~spacedg.scene.units.decide_units` (metric by construction,
            or unknown and checked against the labelled objects' typical sizes).
        units: ``"metric"`` states the files are in metres (not checked); ``"auto"`` decides as above.
        gaussians, cameras: override the Gaussians file / the cameras (COLMAP folder,
            ``transforms.json``, INRIA ``cameras.json``) the layout would pick.
        dataparser_transforms: splatfacto's ``dataparser_transforms.json`` (found next to the
            Gaussians file when not given): the Gaussians are taken back from the normalised frame.
        undo_applied_transform: move nerfstudio cameras back to the COLMAP frame (inverse of the
            JSON's ``applied_transform``), for Gaussians trained on the COLMAP model.
        masks: folder holding Holi-Spatial masks (``<image stem>/<label>.png``) when their recorded
            paths do not exist here.
        assign: instance ids when the Gaussians carry none: ``"auto"`` (= ``"boxes"``: every
            annotation has boxes; mask files, when found, still give the report's rendered-mask
            IoU; for a Holi-Spatial release scene = ``"masks"`` with its COCO RLE ``mask_encodings``),
            ``"boxes"``, ``"masks"`` (vote with Holi-Spatial's masks: RLE, else the mask files), ``"none"``.
        device: ScanNet++ cameras, ``"dslr"`` or ``"iphone"``.
        embodiedscan_scene: the scan in a multi-scan EmbodiedScan JSON.
        opencv_distortion: non-zero OPENCV distortion: ``"error"`` or ``"drop"`` (ideal pinholes).
        frame_check: ``"error"`` refuses a frame mismatch; ``"warn"`` notes it and writes anyway.
        trust_up: keep a given up that the capture's evidence contradicts (:mod:`spacedg.scene.up_evidence`;
            recorded as ``"overridden"`` in ``metadata.up_evidence``) instead of refusing it.
        overwrite: replace an existing scene folder.
        progress: progress bars.
        backend: renderer backend of the checks and the mask work.

    Returns:
        ``(scene, report)``; the scene is the one written (Gaussians in memory).

    Raises:
        FileFormatError / FileValueError: unreadable parts (the file, the field and the fix named).
        FrameMismatchError: the parts disagree (with ``frame_check="error"``).
        UpContradictedError / UpUndecidedError: the evidence contradicts the up used / cannot decide an auto up.
        UnitsImplausibleError: units unknown and the labelled objects implausible at 1 m per unit
            (the message gives the estimate and the option to pass).
    """
    src_path = Path(src)
    t0 = time.perf_counter()
    _check_arguments(out, overwrite, metres_per_unit, format, frame_check)
    layout = detect_capture(src_path) if format == "auto" else CaptureLayout(format)
    parts = _resolve_parts(
        src_path, layout, _opt_path(gaussians), _opt_path(cameras), _opt_path(instances), _opt_path(dataparser_transforms), device,
    )
    capture = _read_capture(parts, opencv_distortion=opencv_distortion, undo_applied_transform=undo_applied_transform,
                            embodiedscan_scene=embodiedscan_scene, assign=assign, masks=masks)
    timings = {"read_gaussians": capture.gaussians_seconds, "read": time.perf_counter() - t0}
    decided = decide_frame(capture.views, capture.instances, where=str(src_path), layout=parts.layout, up=up,
                           default_up=parts.default_up, default_note=parts.up_note, means=capture.gaussians.means,
                           instances_format=capture.instances_format, units=units, metres_per_unit=metres_per_unit, trust_up=trust_up)
    parts.notes.append(decided.note())
    scene = _scaled_scene(_scene_id(name, src_path), src_path, parts, capture, decided)
    t1 = time.perf_counter()
    frame, fill = _check_scene(scene, parts, src_path, frame_check=frame_check, backend=backend, gaussians_given=gaussians is not None)
    timings["frame_check"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    scene, assignment, ids_source = _instance_ids(scene, parts, capture.mask_source, assign=assign, masks=masks, progress=progress,
                                                  backend=backend)
    if assignment is not None:
        timings["assign_instances"] = time.perf_counter() - t2
    report = ImportReport(
        scene.id, parts.layout, None, str(parts.gaussians_path), len(scene.gaussians), scene.gaussians.sh_degree, len(scene.views),
        capture.test_views, str(parts.cameras.path), len(scene.instances), None if parts.instances_path is None else str(parts.instances_path),
        [float(v) for v in scene.up], decided.up_source, decided.metres_per_unit, frame, ids_source, assignment, fill, parts.notes,
        units=decided.units,
    )
    if out is not None:
        t3 = time.perf_counter()
        save_scene(scene, out)
        timings["save"] = time.perf_counter() - t3
        report.out = Path(out)
    timings["total"] = time.perf_counter() - t0
    report.seconds = timings
    return scene, report


def _opt_path(value: PathLike | None) -> Path | None:
    return None if value is None else Path(value)


def _check_arguments(out: PathLike | None, overwrite: bool, metres_per_unit: float | None, format: str, frame_check: str) -> None:
    """The arguments that can be checked before reading anything (one :class:`ParameterError` each)."""
    if out is not None and (Path(out) / "scene.json").is_file() and not overwrite:
        raise ParameterError(f"{out}: a scene folder already exists; pass --overwrite (overwrite=True) or choose another --out")
    check_metres_per_unit(metres_per_unit)
    if format not in LAYOUTS:
        raise ParameterError(f"--format {format!r}: choose one of {', '.join(LAYOUTS)}")
    if frame_check not in FRAME_CHECKS:
        raise ParameterError(f"frame_check {frame_check!r}: choose one of {', '.join(FRAME_CHECKS)}")


@dataclass
class _Capture:
    """The parts of a capture as read, in the files' frame and units (the scan frame once ``to_scan`` applied)."""

    gaussians: Gaussians
    views: dict[str, Camera]
    test_views: int
    instances: list[Instance]
    instances_format: str | None
    mask_source: MaskSource | None
    gaussians_seconds: float


def _read_capture(
    parts: _Parts, *, opencv_distortion: Literal["error", "drop"], undo_applied_transform: bool, embodiedscan_scene: str | None,
    assign: str, masks: PathLike | None,
) -> _Capture:
    """Read the Gaussians, cameras and instances of ``parts``; undo nerfstudio's frames; move to the scan frame."""
    t0 = time.perf_counter()
    gauss = read_gaussians(parts.gaussians_path)
    seconds = time.perf_counter() - t0
    views, test_views = read_cameras(parts.cameras, opencv_distortion), parts.cameras.test_frames()
    if parts.inria_training is not None:
        views, note = at_training_scale(views, *parts.inria_training)
        if note:
            parts.notes.append(note)
    if parts.dataparser is not None:
        transform, scale = read_dataparser_transforms(parts.dataparser)
        rot, trans, k = denormalising_similarity(transform, scale)
        gauss = gauss.transformed(rot, trans, k)
        parts.notes.append(f"Gaussians taken back from nerfstudio's normalised frame with {parts.dataparser} (scale 1/{scale:.4g})")
    if undo_applied_transform:
        if parts.applied_transform is None:
            raise ParameterError("--undo-applied-transform: the cameras are not a transforms.json with an applied_transform")
        views = _move_views(views, np.linalg.inv(parts.applied_transform))
        parts.notes.append("cameras moved back to the COLMAP frame (inverse of transforms.json's applied_transform)")
    found: list[Instance] = []
    instances_format = boxes_json = None
    if parts.instances_path is not None:
        boxes_json = read_json(parts.instances_path, "instance JSON")  # parsed once: the instances and their RLE masks
        found, instances_format = read_any_instances(parts.instances_path, views.keys(), embodiedscan_scene=embodiedscan_scene,
                                                     data=boxes_json)
        parts.notes.append(f"instances read as {instances_format}")
    mask_source = _rle_source(parts, instances_format, found, views, assign, masks, parts.notes, boxes_json)
    if parts.to_scan is not None:
        views, gauss, found = _to_scan(parts.to_scan, views, gauss, found)
    if parts.arkit is not None:
        parts.notes.append(arkit_agreement(views, parts.arkit))
    return _Capture(gauss, views, test_views, found, instances_format, mask_source, seconds)


def _scaled_scene(scene_id: str, src: Path, parts: _Parts, capture: _Capture, decided: FrameDecision) -> Scene:
    """The scene in metres (the decided metres per unit applied once), its import record in ``metadata``."""
    scale = decided.metres_per_unit
    views, instances = capture.views, capture.instances
    if scale != 1.0:
        views, instances = scale_views(views, scale), scale_instances(instances, scale)
    metadata: dict[str, Any] = {
        "source": {"layout": parts.layout, "src": str(src), "gaussians": str(parts.gaussians_path), "cameras": str(parts.cameras.path),
                   "instances": None if parts.instances_path is None else str(parts.instances_path),
                   "instances_format": capture.instances_format,
                   "dataparser_transforms": None if parts.dataparser is None else str(parts.dataparser)},
        **decided.metadata(),
    }
    return Scene(scene_id, scale_gaussians(capture.gaussians, scale), views, instances, decided.up.tolist(), None, metadata)


def _check_scene(
    scene: Scene, parts: _Parts, src: Path, *, frame_check: str, backend: str, gaussians_given: bool,
) -> tuple[FrameReport, BoxFillReport | None]:
    """Frame check then box fill (metres): refused with ``frame_check="error"``, else noted; both recorded in ``metadata``."""
    fill = measure_box_fill(scene.gaussians.means, scene.instances, instance_ids=scene.gaussians.instance_ids,
                            metres_per_file_unit=float(scene.metadata.get("scale_to_metres", 1.0))) if scene.instances else None
    report = check_frame(scene, backend=backend, box_share=None if fill is None else fill.held_share)
    if fill is not None and report.problems and set(report.problem_kinds()) == {"boxes"}:
        report = report.without("boxes")  # boxes only: the fill check below names them
    if not report.ok:
        report = diagnose(scene, report, _corrections(scene, parts), backend=backend)
        if not report.hints:
            hint = normalised_hint(scene, layout=parts.layout, gaussians_given=gaussians_given)
            if hint:
                report = replace(report, hints=(hint,))
        if frame_check == "error":
            report.raise_if_bad(scene.id, where=f"{src}")
        parts.notes.append("FRAME MISMATCH written anyway (frame_check='warn'): " + "; ".join(report.problems))
    fill, note = check_box_fill(scene.gaussians.means, scene.instances, where=f"{src}: {parts.instances_path}", layout=parts.layout,
                                frame_check=frame_check, fill=fill)
    if note:
        parts.notes.append(note)
    if fill is not None:
        scene.metadata["box_fill"] = fill.to_dict()
    scene.metadata["frame_check"] = report.to_dict()
    return report, fill


def _instance_ids(
    scene: Scene, parts: _Parts, mask_source: MaskSource | None, *, assign: str, masks: PathLike | None, progress: bool, backend: str,
) -> tuple[Scene, AssignmentReport | None, str]:
    """Instance ids: kept from the Gaussians file, or assigned (boxes / masks), or none; ``(scene, report, how)``."""
    if scene.gaussians.instance_ids is not None:
        return scene, None, "kept from the Gaussians file"
    if not scene.instances:
        return scene, None, "none (no instances: only camera questions can be built)"
    if assign == "none":
        return scene, None, "none (assign='none'): qa build will assign them by boxes on the fly"
    method = assign if assign != "auto" else "masks" if mask_source is not None and parts.layout == "holi-spatial" else "boxes"
    scene, assignment = assign_instances(scene, method, masks_root=masks, progress=progress, backend=backend,  # type: ignore[arg-type]
                                         mask_source=mask_source)
    scene.metadata["instance_assignment"] = {k: v for k, v in assignment.to_dict().items() if k != "instances"}
    return scene, assignment, f"assigned by {method} (the Gaussians file carried none)"


def _to_scan(
    change: tuple[np.ndarray, frozenset[str]], views: dict[str, Camera], gauss: Gaussians, instances: list[Instance],
) -> tuple[dict[str, Camera], Gaussians, list[Instance]]:
    """The parts named in ``change`` moved by its rigid world change (4×4)."""
    matrix, parts = change
    rot, trans = matrix[:3, :3], matrix[:3, 3]
    if "views" in parts:
        views = _move_views(views, matrix)
    if "gaussians" in parts:
        gauss = gauss.transformed(rot, trans)
    if "instances" in parts:
        instances = [replace(i, box=i.box.transformed(rot, trans)) for i in instances]
    return views, gauss, instances


def _rle_source(
    parts: _Parts, instances_format: str | None, instances: list[Instance], views: dict[str, Camera], assign: str,
    masks: PathLike | None, notes: list[str], data: Any = None,
) -> MaskSource | None:
    """Holi-Spatial's RLE masks (``mask_encodings``) as a mask source, mask files where an instance has no RLE;
    read (and every RLE checked) for the release layout, and for other layouts only when masks are asked for."""
    if instances_format != "holi-spatial" or parts.instances_path is None or not (parts.layout == "holi-spatial" or assign == "masks"):
        return None
    rle = rle_masks(parts.instances_path, instances, views, data=data)
    if rle.count == 0:
        return None
    notes.append(f"{rle.count} COCO RLE masks (mask_encodings) read from {parts.instances_path.name}")

    def source(iid: int, path: str) -> np.ndarray | None:
        mask = rle(iid, path)
        return mask if mask is not None else load_mask(path, masks)

    return source


def _corrections(scene: Scene, parts: _Parts) -> dict[str, Callable[[Scene], Scene]]:
    out: dict[str, Callable[[Scene], Scene]] = {}

    def with_gaussians(g: Gaussians) -> Callable[[Scene], Scene]:
        return lambda s: Scene(s.id, g, s.views, s.instances, s.up, s.vocabulary, s.metadata)

    if parts.dataparser is None:
        for candidate in _nearby_dataparser(parts):
            transform, scale = read_dataparser_transforms(candidate)
            rot, trans, k = denormalising_similarity(transform, scale)
            out[f"the Gaussians are in nerfstudio's normalised frame: pass dataparser_transforms.json (--dataparser-transforms {candidate})"] = \
                with_gaussians(scene.gaussians.transformed(rot, trans, k))
    if parts.applied_transform is not None:
        inv = np.linalg.inv(parts.applied_transform)
        out["the Gaussians are in the COLMAP frame while the cameras are in nerfstudio's transforms.json frame: "
            "pass --undo-applied-transform (or --cameras <the COLMAP model>)"] = lambda s: Scene(
            s.id, s.gaussians, _move_views(dict(s.views), inv), s.instances, s.up, s.vocabulary, s.metadata)
    if parts.layout == "scannetpp" and parts.to_scan is not None:
        back = np.linalg.inv(parts.to_scan[0])
        out["the Gaussians are already in ScanNet++'s scan frame (trained on dslr/colmap, not the nerfstudio JSON): "
            "pass --cameras <scene>/dslr/colmap"] = with_gaussians(scene.gaussians.transformed(back[:3, :3], back[:3, 3]))
    out.update(generic_corrections(scene))
    return out


def _nearby_dataparser(parts: _Parts) -> list[Path]:
    found = []
    for folder in (parts.gaussians_path.parent, parts.gaussians_path.parent.parent):
        # ns-train writes outputs/<experiment>/<method>/<timestamp>/dataparser_transforms.json
        for pattern in ("dataparser_transforms.json", "*/dataparser_transforms.json", "*/*/*/dataparser_transforms.json",
                        "*/*/*/*/dataparser_transforms.json"):
            found += [p for p in sorted(folder.glob(pattern))[:3] if p not in found]
    return found[:3]

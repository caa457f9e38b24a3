"""The scene model: Gaussians + views + annotated 3D instances, in metres.

- :class:`Instance`: an annotated object (id, label, view-invariant description, oriented
  box, the views it was annotated in, and per-view visibility filled by
  ``spacedg.scene.visibility``).
- :class:`Scene`: id, views (name → :class:`~spacedg.render.camera.Camera`), instances,
  ``up`` (unit vector against gravity, never assumed to be a world axis), and Gaussians
  loaded lazily on first access. Units are always metres: readers of non-metric sources
  take a ``scale`` and convert once.

A ``Scene`` pickles without its Gaussians when it can reload them (a loader was given), so
DataLoader workers receive a few kilobytes and load what they need themselves.
"""

from __future__ import annotations

import difflib
import functools
import re
from collections import Counter
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spacedg._checks import require_rotation
from spacedg.errors import InvalidDataError, ParameterError
from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians
from spacedg.scene.box import OrientedBox
from spacedg.scene.language import strip_article

_ID_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")


@dataclass(frozen=True)
class InstanceVisibility:
    """How much of an instance one view shows.

    Attributes:
        visible_pixels: pixels whose rendered instance id is this instance.
        visible_fraction: ``visible_pixels`` over the pixels the instance would cover with
            nothing in front of it and an unbounded image (so both occlusion and truncation
            by the image border reduce it), in [0, 1].
    """

    visible_pixels: int
    visible_fraction: float

    def __post_init__(self) -> None:
        if isinstance(self.visible_pixels, bool) or int(self.visible_pixels) != self.visible_pixels or self.visible_pixels < 0:
            raise InvalidDataError(f"InstanceVisibility: visible_pixels must be an integer >= 0, got {self.visible_pixels!r}")
        frac = float(self.visible_fraction)
        if not (0.0 <= frac <= 1.0):
            raise InvalidDataError(f"InstanceVisibility: visible_fraction must be in [0, 1], got {self.visible_fraction!r}")
        object.__setattr__(self, "visible_pixels", int(self.visible_pixels))
        object.__setattr__(self, "visible_fraction", frac)

    def to_dict(self) -> dict[str, Any]:
        return {"visible_pixels": self.visible_pixels, "visible_fraction": self.visible_fraction}


@dataclass(frozen=True)
class Instance:
    """One annotated 3D object.

    Attributes:
        id: integer id, unique in the scene, ``>= 0``; Gaussians carry it in ``instance_ids``.
        label: category word used in questions ("chair").
        description: view-invariant description (colour, material, type; never "on the left"),
            a noun phrase without a leading article: one given with "a"/"an"/"the" is stripped
            once here (:func:`~spacedg.scene.language.strip_article`), so questions never say "the a …".
        box: oriented bounding box in world metres.
        images: names of views in which the source annotation saw the object (may be empty).
        visibility: view name → :class:`InstanceVisibility`, filled by ``spacedg.scene.visibility``.
        attributes: free-form extra facts (colour name, material, ...), JSON-serialisable.
    """

    id: int
    label: str
    description: str
    box: OrientedBox
    images: tuple[str, ...] = ()
    visibility: Mapping[str, InstanceVisibility] = field(default_factory=dict)
    attributes: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if isinstance(self.id, bool) or not isinstance(self.id, (int, np.integer)) or not 0 <= int(self.id) <= 2**31 - 1:
            raise InvalidDataError(f"Instance: id must be an integer in [0, 2**31 - 1] (int32), got {self.id!r}")
        object.__setattr__(self, "id", int(self.id))
        if not isinstance(self.label, str) or not self.label.strip():
            raise InvalidDataError(f"Instance {self.id}: label must be a non-empty string, got {self.label!r}")
        if not isinstance(self.description, str):
            raise InvalidDataError(f"Instance {self.id}: description must be a string, got {type(self.description).__name__}")
        stripped = strip_article(self.description)
        if stripped != self.description.strip():  # only a leading article changes the text
            object.__setattr__(self, "description", stripped)
        if not isinstance(self.box, OrientedBox):
            raise InvalidDataError(f"Instance {self.id}: box must be an OrientedBox, got {type(self.box).__name__}")
        object.__setattr__(self, "images", tuple(self.images))
        object.__setattr__(self, "visibility", dict(self.visibility))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "id": self.id,
            "label": self.label,
            "description": self.description,
            "box": self.box.to_dict(),
            "images": list(self.images),
        }
        if self.visibility:
            out["visibility"] = {view: vis.to_dict() for view, vis in self.visibility.items()}
        if self.attributes:
            out["attributes"] = dict(self.attributes)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Instance:
        missing = [k for k in ("id", "label", "box") if k not in data]
        if missing:
            raise InvalidDataError(f"Instance: missing key(s) {missing}")
        vis = {}
        for view, v in dict(data.get("visibility", {})).items():
            try:
                vis[view] = InstanceVisibility(int(v["visible_pixels"]), float(v["visible_fraction"]))
            except (KeyError, TypeError, ValueError) as err:
                raise InvalidDataError(
                    f"Instance {data.get('id')!r}: visibility of view {view!r} needs visible_pixels and visible_fraction, got {v!r}"
                ) from err
        return cls(
            id=data["id"],
            label=data["label"],
            description=data.get("description", ""),
            box=OrientedBox.from_dict(data["box"]),
            images=tuple(data.get("images", ())),
            visibility=vis,
            attributes=dict(data.get("attributes", {})),
        )


GaussiansSource = Gaussians | Callable[[], Gaussians]


def _load_transformed(loader: Callable[[], Gaussians], rotation: np.ndarray, translation: np.ndarray) -> Gaussians:
    return loader().transformed(rotation, translation)


@dataclass(frozen=True, eq=False)
class ViewCovisibility:
    """Pairwise view covisibility of a scene (computed by ``spacedg.scene.covisibility``).

    Attributes:
        names: view names, the order of the matrix rows and columns.
        matrix: (V, V) float32, **raw and asymmetric**: ``matrix[i, j]`` is the fraction of
            view i's valid depth pixels that reproject into view j with agreeing depth
            (MapAnything-style); diagonal 1.
    """

    names: tuple[str, ...]
    matrix: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        names = tuple(self.names)
        matrix = np.array(self.matrix, dtype=np.float32)
        if matrix.shape != (len(names), len(names)):
            raise InvalidDataError(f"ViewCovisibility: matrix shape {matrix.shape} does not match {len(names)} view names")
        if len(set(names)) != len(names):
            raise InvalidDataError("ViewCovisibility: view names repeat")
        if not np.isfinite(matrix).all() or (matrix < 0).any() or (matrix > 1).any():
            raise InvalidDataError("ViewCovisibility: scores must be finite and in [0, 1]")
        matrix.flags.writeable = False
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "matrix", matrix)
        object.__setattr__(self, "_index", {n: i for i, n in enumerate(names)})

    def index(self, view: str) -> int:
        """Row of ``view``; :class:`ParameterError` if the matrix does not cover it."""
        try:
            return self._index[view]  # type: ignore[attr-defined]
        except KeyError:
            raise ParameterError(f"covisibility has no view {view!r}; recompute it for the scene's current views") from None

    def between(self, a: str, b: str) -> float:
        """Symmetrised score of views ``a`` and ``b``: ``min(M[a, b], M[b, a])`` (both must see it)."""
        i, j = self.index(a), self.index(b)
        return float(min(self.matrix[i, j], self.matrix[j, i]))


class Scene:
    """Gaussians, named views and annotated instances of one place, in metres.

    Args:
        id: short identifier (letters, digits, ``_ . -``), used in file and record names.
        gaussians: the Gaussians, or a zero-argument picklable callable that loads them
            (e.g. ``functools.partial(read_ply, path)``); loaded on first access of
            :attr:`gaussians` and validated against the instances then.
        views: view name → camera.
        instances: annotated objects; ids unique.
        up: unit vector against gravity in world coordinates.
        vocabulary: category words that may appear in this kind of scene (used for negative
            existence questions); defaults to the instance labels.
        metadata: JSON-serialisable facts (source, licence, attribution, generator seed).
        covisibility: pairwise view covisibility (:class:`ViewCovisibility`), or ``None``
            until computed (``spacedg.scene.covisibility``); two-view question families read it.
    """

    units = "m"

    def __init__(
        self,
        id: str,
        gaussians: GaussiansSource,
        views: Mapping[str, Camera],
        instances: Iterable[Instance] = (),
        up: Iterable[float] = (0.0, 0.0, 1.0),
        vocabulary: Iterable[str] | None = None,
        metadata: Mapping[str, Any] | None = None,
        covisibility: ViewCovisibility | None = None,
    ) -> None:
        if not isinstance(id, str) or not _ID_PATTERN.match(id):
            raise InvalidDataError(f"Scene: id {id!r} must be letters, digits, '_', '.', '-' (and start with a letter or digit)")
        self.id = id
        self.views: dict[str, Camera] = dict(views)
        self.instances: tuple[Instance, ...] = tuple(instances)
        up_vec = np.asarray(list(up), dtype=np.float64)
        if up_vec.shape != (3,) or not np.isfinite(up_vec).all() or abs(np.linalg.norm(up_vec) - 1.0) > 1e-3:
            raise InvalidDataError(
                f"Scene {id}: up must be a unit 3-vector against gravity, got {up_vec.tolist()}; normalise it"
            )
        up_vec = up_vec / np.linalg.norm(up_vec)
        up_vec.flags.writeable = False
        self.up = up_vec
        self.vocabulary: tuple[str, ...] = tuple(vocabulary) if vocabulary is not None else tuple(
            sorted({inst.label for inst in self.instances})
        )
        self.metadata: dict[str, Any] = dict(metadata or {})
        if covisibility is not None:
            if not isinstance(covisibility, ViewCovisibility):
                raise InvalidDataError(f"Scene {id}: covisibility must be a ViewCovisibility, got {type(covisibility).__name__}")
            missing = sorted(set(self.views) - set(covisibility.names))
            if missing:
                raise InvalidDataError(f"Scene {id}: covisibility lacks view(s) {missing[:5]}; recompute it for these views")
        self.covisibility = covisibility
        if isinstance(gaussians, Gaussians):
            self._gaussians: Gaussians | None = gaussians
            self._loader: Callable[[], Gaussians] | None = None
        elif callable(gaussians):
            self._gaussians = None
            self._loader = gaussians
        else:
            raise InvalidDataError(f"Scene {id}: gaussians must be Gaussians or a callable returning them")
        self._validate()
        if self._gaussians is not None:
            self._check_instance_ids(self._gaussians)

    # --------------------------------------------------------------- checks
    def _validate(self) -> None:
        for name, cam in self.views.items():
            if not isinstance(name, str) or not name:
                raise InvalidDataError(f"Scene {self.id}: view names must be non-empty strings, got {name!r}")
            if not isinstance(cam, Camera):
                raise InvalidDataError(f"Scene {self.id}: view {name!r} is a {type(cam).__name__}, not a Camera")
        dup = [i for i, n in Counter(inst.id for inst in self.instances).items() if n > 1]
        if dup:
            raise InvalidDataError(f"Scene {self.id}: instance ids {sorted(dup)} are used more than once; ids must be unique")
        for inst in self.instances:
            unknown = [v for v in (*inst.images, *inst.visibility) if v not in self.views]
            if unknown:
                raise InvalidDataError(
                    f"Scene {self.id}: instance {inst.id} ({inst.label}) refers to view(s) {sorted(set(unknown))[:5]} "
                    f"that the scene does not have ({len(self.views)} views)"
                )

    def _check_instance_ids(self, gaussians: Gaussians) -> None:
        if gaussians.instance_ids is None:
            return
        known = np.array(sorted({-1, *(inst.id for inst in self.instances)}), dtype=np.int64)
        present = np.unique(gaussians.instance_ids)
        unknown = np.setdiff1d(present, known)
        if unknown.size:
            raise InvalidDataError(
                f"Scene {self.id}: Gaussians carry instance ids {unknown[:10].tolist()} that no instance has; "
                "add those instances or set the ids to -1"
            )

    # ------------------------------------------------------------ gaussians
    @property
    def gaussians(self) -> Gaussians:
        """The scene's Gaussians, loaded (and validated) on first access."""
        if self._gaussians is None:
            assert self._loader is not None
            loaded = self._loader()
            if not isinstance(loaded, Gaussians):
                raise InvalidDataError(f"Scene {self.id}: the gaussians loader returned {type(loaded).__name__}, not Gaussians")
            self._check_instance_ids(loaded)
            self._gaussians = loaded
        return self._gaussians

    @property
    def gaussians_loaded(self) -> bool:
        return self._gaussians is not None

    def release_gaussians(self) -> None:
        """Drop the loaded Gaussians if they can be reloaded (frees memory)."""
        if self._loader is not None:
            self._gaussians = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        if state["_loader"] is not None:
            state["_gaussians"] = None
        return state

    # -------------------------------------------------------------- queries
    def camera(self, view: str) -> Camera:
        """The camera of ``view``; :class:`ParameterError` with close names (or some views) otherwise."""
        camera = self.views.get(view) if isinstance(view, str) else None
        if camera is not None:
            return camera
        names = list(self.views)
        close = difflib.get_close_matches(str(view), names, n=3, cutoff=0.6)
        hint = f"did you mean {', '.join(map(repr, close))}?" if close else f"it has {len(names)} views ({', '.join(names[:5])}{', …' if len(names) > 5 else ''})"
        raise ParameterError(f"scene {self.id} has no view {view!r}; {hint}")

    def instance(self, instance_id: int) -> Instance:
        """The instance with ``instance_id``; raises ``KeyError`` naming the known ids."""
        for inst in self.instances:
            if inst.id == instance_id:
                return inst
        raise KeyError(f"scene {self.id} has no instance {instance_id} (ids: {[i.id for i in self.instances][:20]})")

    def instances_by_label(self) -> dict[str, list[Instance]]:
        """label → instances, labels sorted, instances in id order."""
        out: dict[str, list[Instance]] = {}
        for inst in sorted(self.instances, key=lambda i: i.id):
            out.setdefault(inst.label, []).append(inst)
        return dict(sorted(out.items()))

    def height(self, points: np.ndarray) -> np.ndarray:
        """Elevation of world points along :attr:`up`, metres (origin at the world origin)."""
        return np.asarray(points, dtype=np.float64).reshape(-1, 3) @ self.up

    def with_instances(self, instances: Iterable[Instance]) -> Scene:
        """A scene sharing Gaussians, views and covisibility, with other instances (e.g. visibility filled)."""
        return Scene(self.id, self._source(), self.views, instances, self.up, self.vocabulary, self.metadata, self.covisibility)

    def with_covisibility(self, covisibility: ViewCovisibility | None) -> Scene:
        """A scene sharing everything else, with ``covisibility`` attached."""
        return Scene(self.id, self._source(), self.views, self.instances, self.up, self.vocabulary, self.metadata, covisibility)

    def transformed(self, rotation: np.ndarray, translation: np.ndarray) -> Scene:
        """The same scene moved rigidly by ``x ↦ R x + t`` (Gaussians, camera poses, boxes, ``up``).

        Visibility and covisibility are kept: they do not change under a rigid motion of
        everything. Lazily loaded Gaussians stay lazy (transformed when loaded).
        """
        from dataclasses import replace

        rot = np.asarray(rotation, dtype=np.float64)
        require_rotation(rot, "rotation", f"Scene {self.id}.transformed")
        t = np.asarray(translation, dtype=np.float64).reshape(3)
        move = np.eye(4)
        move[:3, :3], move[:3, 3] = rot, t
        views = {name: cam.with_pose(move @ np.asarray(cam.cam_to_world, dtype=np.float64)) for name, cam in self.views.items()}
        instances = [replace(inst, box=inst.box.transformed(rot, t)) for inst in self.instances]
        source: GaussiansSource
        if self._gaussians is not None:
            source = self._gaussians.transformed(rot, t)
        else:
            source = functools.partial(_load_transformed, self._loader, rot, t)
        return Scene(self.id, source, views, instances, rot @ self.up, self.vocabulary, self.metadata, self.covisibility)

    def _source(self) -> GaussiansSource:
        return self._gaussians if self._gaussians is not None else self._loader  # type: ignore[return-value]

    def summary(self) -> dict[str, Any]:
        """Counts, bounds and instances per label (what ``spacedg scenes info`` prints)."""
        g = self.gaussians
        lo, hi = g.bounds()
        return {
            "id": self.id,
            "gaussians": len(g),
            "sh_degree": g.sh_degree,
            "views": len(self.views),
            "instances": len(self.instances),
            "labels": {label: len(items) for label, items in self.instances_by_label().items()},
            "bounds_min_m": [round(float(v), 4) for v in lo],
            "bounds_max_m": [round(float(v), 4) for v in hi],
            "up": [round(float(v), 6) for v in self.up],
            "image_size": sorted({(c.width, c.height) for c in self.views.values()}),
        }

    def __repr__(self) -> str:
        n = len(self._gaussians) if self._gaussians is not None else "not loaded"
        return f"Scene(id={self.id!r}, gaussians={n}, views={len(self.views)}, instances={len(self.instances)})"


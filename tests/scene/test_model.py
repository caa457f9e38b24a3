"""Scene model: validation of instances, views and ids; lazy Gaussians; pickling."""

from __future__ import annotations

import functools
import pickle

import numpy as np
import pytest

from spacedg.scene.box import OrientedBox
from spacedg.scene.model import Instance, InstanceVisibility, Scene
from spacedg.errors import InvalidDataError
from spacedg.render.camera import Camera, look_at
from spacedg.render.gaussians import Gaussians


def _gaussians(ids=(0, 0, 1, -1)) -> Gaussians:
    n = len(ids)
    return Gaussians.from_colors(
        np.arange(n * 3, dtype=float).reshape(n, 3), np.tile([1.0, 0, 0, 0], (n, 1)), np.full((n, 3), 0.05),
        np.full(n, 0.9), np.full((n, 3), 0.5), instance_ids=np.array(ids),
    )


def _views() -> dict[str, Camera]:
    return {"a": Camera(100, 100, 50, 50, 100, 100, look_at([0, 0, 1], [1, 0, 1], [0, 0, 1]))}


def _inst(i: int, label: str = "chair", **kw) -> Instance:
    return Instance(i, label, f"red {label}", OrientedBox([i, 0, 0], [1, 1, 1]), **kw)


def _load_counting(calls: list) -> Gaussians:
    calls.append(1)
    return _gaussians()


def test_scene_basics_and_summary():
    scene = Scene("s1", _gaussians(), _views(), [_inst(0), _inst(1, "table")], up=[0, 0, 1])
    assert scene.instances_by_label() == {"chair": [scene.instance(0)], "table": [scene.instance(1)]}
    summary = scene.summary()
    assert summary["gaussians"] == 4 and summary["labels"] == {"chair": 1, "table": 1}
    assert scene.vocabulary == ("chair", "table")
    with pytest.raises(KeyError, match="has no instance 5"):
        scene.instance(5)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(id="bad id"), "must be letters, digits"),
        (dict(up=[0, 0, 2]), "up must be a unit 3-vector"),
        (dict(up=[0, np.nan, 1]), "up must be a unit 3-vector"),
        (dict(instances=[_inst(0), _inst(0)]), r"instance ids \[0\] are used more than once"),
        (dict(instances=[_inst(0, images=("zz",))]), r"refers to view\(s\) \['zz'\]"),
        (dict(instances=[_inst(0, visibility={"b": InstanceVisibility(3, 0.5)})]), r"refers to view\(s\) \['b'\]"),
        (dict(instances=[_inst(0)]), r"Gaussians carry instance ids \[1\] that no instance has"),
    ],
)
def test_scene_validation(kwargs, message):
    args = dict(id="s1", gaussians=_gaussians(), views=_views(), instances=[_inst(0), _inst(1)], up=[0, 0, 1])
    args.update(kwargs)
    with pytest.raises(InvalidDataError, match=message):
        Scene(**args)


def test_visibility_and_instance_validation():
    with pytest.raises(InvalidDataError, match="visible_fraction must be in"):
        InstanceVisibility(10, 1.5)
    with pytest.raises(InvalidDataError, match="visible_pixels must be an integer"):
        InstanceVisibility(-1, 0.5)
    with pytest.raises(InvalidDataError, match="label must be a non-empty string"):
        Instance(0, " ", "", OrientedBox([0, 0, 0], [1, 1, 1]))
    inst = _inst(3, visibility={"a": InstanceVisibility(12, 0.25)}, attributes={"colour": "red"})
    assert Instance.from_dict(inst.to_dict()) == inst


def test_lazy_loading_and_pickle_without_gaussians():
    calls: list = []
    scene = Scene("s1", functools.partial(_load_counting, calls), _views(), [_inst(0), _inst(1)])
    assert not scene.gaussians_loaded and not calls
    assert len(scene.gaussians) == 4 and len(calls) == 1
    scene.gaussians  # cached
    assert len(calls) == 1
    clone = pickle.loads(pickle.dumps(scene))
    assert not clone.gaussians_loaded  # workers receive the recipe, not the arrays
    assert len(clone.gaussians) == 4


def test_lazy_loader_result_is_validated():
    scene = Scene("s1", lambda: _gaussians(ids=(0, 7)), _views(), [_inst(0)])
    with pytest.raises(InvalidDataError, match=r"instance ids \[7\]"):
        scene.gaussians


def test_covisibility_is_validated_kept_and_pickled():
    from spacedg.scene.model import ViewCovisibility
    from spacedg.errors import ParameterError

    views = {**_views(), "b": Camera(100, 100, 50, 50, 100, 100, look_at([0, 1, 1], [1, 0, 1], [0, 0, 1]))}
    names = tuple(views)
    cov = ViewCovisibility(names, np.eye(len(names)) * 0.5 + 0.25)
    scene = Scene("s", _gaussians(), views, [_inst(0), _inst(1, "table")], covisibility=cov)
    assert scene.with_instances(scene.instances).covisibility is cov
    assert pickle.loads(pickle.dumps(scene)).covisibility.between(names[0], names[-1]) == pytest.approx(0.25)
    with pytest.raises(ParameterError, match="no view 'zz'"):
        cov.index("zz")
    with pytest.raises(InvalidDataError, match="shape"):
        ViewCovisibility(names, np.ones((1, 1)))
    with pytest.raises(InvalidDataError, match=r"\[0, 1\]"):
        ViewCovisibility(names, np.full((len(names),) * 2, np.nan))
    with pytest.raises(InvalidDataError, match="lacks view"):
        Scene("s", _gaussians(), views, covisibility=ViewCovisibility(names[:1], np.ones((1, 1))))


def test_transformed_moves_everything_rigidly_and_stays_lazy():
    calls: list = []
    scene = Scene("s", functools.partial(_load_counting, calls), _views(), [_inst(0), _inst(1, "table")], up=(0, 0, 1))
    angle = np.radians(30)
    rot = np.array([[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]])
    moved = scene.transformed(rot, [1.0, 2.0, 3.0])
    assert calls == []  # Gaussians still not loaded
    assert np.allclose(moved.up, rot @ [0, 0, 1])
    name = next(iter(_views()))
    assert np.allclose(moved.views[name].cam_to_world[:3, 3], rot @ scene.views[name].cam_to_world[:3, 3] + [1, 2, 3])
    assert np.allclose(moved.instances[0].box.center, rot @ scene.instances[0].box.center + [1, 2, 3])
    assert np.allclose(moved.gaussians.means, scene.gaussians.means @ rot.T + [1, 2, 3], atol=1e-5)
    with pytest.raises(InvalidDataError):
        scene.transformed(np.diag([1.0, 1.0, -1.0]), [0, 0, 0])  # a reflection is not a rigid motion

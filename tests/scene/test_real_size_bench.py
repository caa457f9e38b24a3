"""The real-size benchmark's scene builder (``benchmarks/real_size.py``) on a tiny size: what it
promises (exact view count at the asked resolution, the Gaussian budget, tens of labelled objects,
the shared splat objects placed when present) and its sweep and slope helpers. No timing."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "real_size.py"


@pytest.fixture(scope="module")
def real_size():
    spec = importlib.util.spec_from_file_location("real_size_bench", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)


def test_scene_builder_tiny(real_size):
    scene = real_size.real_size_scene(12_000, 5, width=176, height=117, splats=None, objects=(8, 9))
    assert len(scene.views) == 5
    assert {(c.width, c.height) for c in scene.views.values()} == {(176, 117)}
    assert abs(len(scene.gaussians) - 12_000) < 0.1 * 12_000
    assert 8 <= len(scene.instances) <= 9
    ids = scene.gaussians.instance_ids
    assert set(np.unique(ids[ids >= 0])) == {inst.id for inst in scene.instances}
    # the views sweep re-films the same room: the layout does not depend on the view count
    again = real_size.real_size_scene(12_000, 3, width=176, height=117, splats=None, objects=(8, 9))
    assert np.array_equal(again.gaussians.means, scene.gaussians.means)


def test_splat_objects_are_placed(real_size, shared_splats):
    objects = real_size.splat_objects(shared_splats)
    assert {o.label for o in objects} == {label for _, label, _, _ in real_size.SPLAT_OBJECTS}
    scene = real_size.real_size_scene(20_000, 2, width=176, height=117, splats=shared_splats, objects=(8, 9))
    external = [inst for inst in scene.instances if inst.attributes.get("external")]
    assert {inst.label for inst in external} == {o.label for o in objects}
    assert all(inst.attributes.get("license") for inst in external)  # credits travel with the object


def test_sweeps_and_slope(real_size):
    by_views, by_gaussians = real_size.sizes(400, 2_000_000, [1, 0.25, 0.5])
    assert [s.views for s in by_views] == [100, 200, 400] and {s.gaussians for s in by_views} == {2_000_000}
    assert [s.gaussians for s in by_gaussians] == [500_000, 1_000_000, 2_000_000] and {s.views for s in by_gaussians} == {400}
    assert real_size.slope([100, 200, 400], [1.0, 4.0, 16.0]) == pytest.approx(2.0)
    assert math.isnan(real_size.slope([5, 5], [1.0, 2.0]))

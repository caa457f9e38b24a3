"""Units of imported captures (spacedg.scene.units): stated, estimated from the labelled boxes and
the camera height, refused when implausible, recorded in scene.json and shown by ``scenes info``.

Fixtures are written in the published layouts (INRIA output + COLMAP text model, a COLMAP project
with a Gaussians file, a ScanNet++ scene folder, Holi-Spatial instance JSON) by
``tests/scene/capture_layouts.py``, from a truth in metres scaled into file units by a factor the
importer is not told (:data:`MPU` metres per unit, as a COLMAP reconstruction would have it).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from spacedg.cli import main
from spacedg.scene.box import OrientedBox
from spacedg.scene.importer import import_scene
from spacedg.scene.io import load_scene
from spacedg.scene.model import Instance, Scene
from spacedg.scene.units import (
    MIN_OBJECTS,
    UnitsImplausibleError,
    decide_units,
    estimate_units,
    scene_units_line,
    units_lexicon,
)
from tests.scene import capture_layouts as cl
from tests.scene.unit_captures import MPU, in_file_units, tabletop, write_colmap_project


@pytest.fixture(scope="module")
def room() -> Scene:
    return cl.truth_room(seed=5, gaussians=10_000, views=8)


def _estimate_in(message: str) -> float:
    found = re.search(r"--metres-per-unit ([0-9.]+)", message)
    assert found, message
    return float(found.group(1))


# ----------------------------------------------------------------------------- the estimate
def test_estimate_of_a_scaled_room_from_objects_and_camera_height(room) -> None:
    est = estimate_units(in_file_units(room).instances, in_file_units(room).views, room.up)
    assert est.available and abs(est.metres_per_unit / MPU - 1) < 0.15
    assert est.spread is not None and 1.0 <= est.spread < 1.6 and est.agreeing >= 0.8 * len(est.objects)
    assert est.camera is not None and abs(est.camera.metres_per_unit / MPU - 1) < 0.2
    lo, hi = est.camera.bounds
    assert lo < MPU < hi
    # in metres the same room says ≈ 1 m per unit
    assert abs(estimate_units(room.instances).metres_per_unit - 1) < 0.15


def test_labels_without_a_typical_size_are_ignored() -> None:
    scene = tabletop()
    est = estimate_units(scene.instances, scene.views, scene.up)
    assert "doily" in est.ignored_labels and all(o.label != "doily" for o in est.objects)
    assert len(est.objects) == len(scene.instances) - 1
    # the card box (12.5 cm, a "box" is typically 45 cm) is an outlier the median does not follow
    assert abs(est.metres_per_unit - 1) < 0.15 and est.agreeing == len(est.objects) - 1
    assert est.camera is None, "one box on the floor (the table) is no floor"
    # unknown words fall back to their head noun; still unknown ones are ignored
    odd = [Instance(k, label, "", OrientedBox(np.zeros(3), np.array([0.9, 0.5, 0.5]), np.eye(3)))
           for k, label in enumerate(["wooden chair", "unicorn", "zzz"])]
    est = estimate_units(odd)
    assert [o.size_as for o in est.objects] == ["chair"] and set(est.ignored_labels) == {"unicorn", "zzz"}
    assert not est.available and "only 1 labelled object" in est.reason and "unicorn" in est.reason


def test_typical_sizes_cover_common_indoor_vocabularies() -> None:
    lex = units_lexicon()
    for label in ("couch", "office chair", "dresser", "nightstand", "computer tower", "ceiling light", "luggage", "kettle",
                  "trash bin", "washing machine", "tissue box", "shoe"):
        size = lex.typical_size(label)
        assert size is not None and 0.05 < size[0] < 3.0, label
    assert len(lex.sizes) >= 150


# ----------------------------------------------------------------------------- imports
def test_room_with_unknown_units_is_refused_then_accepted(tmp_path: Path, room) -> None:
    src = cl.write_inria_output(tmp_path, in_file_units(room))
    (tmp_path / "holi.json").write_text(json.dumps(cl.holi_spatial_json(in_file_units(room), {})))
    with pytest.raises(UnitsImplausibleError) as err:
        import_scene(src, tmp_path / "scene", instances=tmp_path / "holi.json", progress=False)
    message = str(err.value)
    assert abs(_estimate_in(message) / MPU - 1) < 0.15 and "--units metric" in message and "inria" in message
    assert "cameras" in message and not (tmp_path / "scene").exists()
    scene, report = import_scene(src, tmp_path / "scene", instances=tmp_path / "holi.json", metres_per_unit=MPU, progress=False)
    assert report.units.kind == "given" and report.metres_per_unit == MPU and report.frame.ok
    truth = {i.id: i.box.extents for i in room.instances}
    got = {i.id: i.box.extents for i in scene.instances}
    assert all(np.allclose(got[k], truth[k], rtol=1e-4) for k in truth), "boxes back in metres"
    record = load_scene(tmp_path / "scene").metadata["units"]
    assert record["kind"] == "given" and record["metres_per_unit"] == MPU and "given by the user" in record["how"]
    assert abs(record["estimate"]["metres_per_unit"] / MPU - 1) < 0.15 and record["estimate"]["objects"]
    assert "units        0.145 m per file unit" in report.text() and "spread" in report.text()


def test_tabletop_capture_via_the_command_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = write_colmap_project(tmp_path / "capture", in_file_units(tabletop()))
    out = tmp_path / "scene"
    assert main(["scenes", "import", str(src), "--out", str(out), "--instances", str(src / "instances.json")]) == 2
    err = capsys.readouterr().err
    assert main(["scenes", "import", str(src), "--out", str(out), "--instances", str(src / "instances.json"), "--units", "metric",
                 "--metres-per-unit", "0.5"]) == 2
    assert "contradict" in capsys.readouterr().err
    assert abs(_estimate_in(err) / MPU - 1) < 0.15 and "colmap" in err and " m (typically " in err
    assert not out.exists()
    given = _estimate_in(err)
    assert main(["scenes", "import", str(src), "--out", str(out), "--instances", str(src / "instances.json"),
                 "--metres-per-unit", str(given)]) == 0
    text = capsys.readouterr().out
    assert f"units        {given:g} m per file unit: given by the user" in text and "doily" in text
    assert main(["scenes", "info", str(out)]) == 0
    assert f"units: {given:g} m per file unit, given: given by the user" in capsys.readouterr().out
    card = next(i for i in load_scene(out).instances if i.label == "box")
    assert abs(card.box.extents.max() - 0.125) < 0.02, "the 12.5 cm card box is about 12.5 cm"


def test_units_metric_overrides_and_contradictions(tmp_path: Path) -> None:
    src = write_colmap_project(tmp_path / "capture", in_file_units(tabletop()))
    _, report = import_scene(src, None, instances=src / "instances.json", units="metric", progress=False)
    assert report.units.kind == "metric" and report.metres_per_unit == 1.0 and "--units metric" in report.units.how
    assert "WARNING" in report.text(), "a stated unit is applied, but the disagreeing estimate is shown"
    from spacedg.errors import ParameterError

    with pytest.raises(ParameterError, match="contradict"):
        import_scene(src, None, instances=src / "instances.json", units="metric", metres_per_unit=0.5, progress=False)
    with pytest.raises(ParameterError, match="--units 'feet'"):
        import_scene(src, None, instances=src / "instances.json", units="feet", progress=False)  # type: ignore[arg-type]


def test_metric_capture_with_unknown_units_is_accepted_and_says_why(tmp_path: Path) -> None:
    src = write_colmap_project(tmp_path / "capture", tabletop())
    _, report = import_scene(src, None, instances=src / "instances.json", progress=False)
    assert report.units.kind == "unknown" and report.metres_per_unit == 1.0
    assert "the labelled objects agree" in report.units.how and "WARNING" not in report.text()


def test_too_few_labelled_objects_say_the_estimate_is_unavailable(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = write_colmap_project(tmp_path / "capture", in_file_units(tabletop(labels=("cup", "doily"))))
    out = tmp_path / "scene"
    assert main(["scenes", "import", str(src), "--out", str(out), "--instances", str(src / "instances.json")]) == 0
    text = capsys.readouterr().out
    assert "estimate unavailable: only 2 labelled object(s)" in text and f"need {MIN_OBJECTS}" in text
    assert "NOT VERIFIED: pass --metres-per-unit X" in text and "--units metric" in text
    record = load_scene(out).metadata["units"]
    assert record["kind"] == "unknown" and record["estimate"]["metres_per_unit"] is None and "not verified" in record["how"]
    assert "estimate unavailable" in scene_units_line(load_scene(out))


def test_scannetpp_is_metric_by_construction_and_not_second_guessed(tmp_path: Path, room) -> None:
    odd = in_file_units(room, 0.5)  # a ScanNet++ folder whose boxes are twice too large: stated metric, still imported
    scene_dir = cl.write_scannetpp_dslr(tmp_path / "0a5c013435", odd)  # as ScanNet++ publishes it
    cl.write_inria_output(scene_dir / "gs", odd.transformed(cl.SCANNETPP_JSON[:3, :3], np.zeros(3)), with_colmap=False)
    _, report = import_scene(scene_dir, tmp_path / "scene", progress=False)
    assert report.units.kind == "metric" and report.metres_per_unit == 1.0 and "ScanNet++" in report.units.how
    assert abs(report.units.estimate.metres_per_unit / 0.5 - 1) < 0.15 and "WARNING" in report.text()
    assert "metric" in scene_units_line(load_scene(tmp_path / "scene"))


def test_decisions_without_files() -> None:
    scene = in_file_units(tabletop())
    es = decide_units("colmap", scene.instances, scene.views, scene.up, instances_format="embodiedscan")
    assert es.kind == "metric" and not es.implausible() and "EmbodiedScan" in es.how
    unknown = decide_units("nerfstudio", scene.instances, scene.views, scene.up)
    assert unknown.implausible() and abs(unknown.ratio / MPU - 1) < 0.15
    assert not decide_units("gaussians", scene.instances, metres_per_unit=MPU).implausible()
    assert scene_units_line(tabletop()) == "metres (no import record: a scene made by spacedg)"
    before = tabletop()
    before.metadata["scale_to_metres"] = 0.2  # imported before units were decided
    assert "0.2 m per file unit (imported before units were checked: not verified" in scene_units_line(before)


def test_weak_or_overruled_evidence_warns_without_refusing() -> None:
    def inst(k: int, label: str, size: float) -> Instance:
        return Instance(k, label, "", OrientedBox(np.array([3.0 * k, 0, size / 2]), np.array([size, size / 2, size / 2]), np.eye(3)))

    # four objects, two say ×0.1 and two say ×1: no majority agrees, so no refusal, but a warning
    split = [inst(0, "chair", 9.0), inst(1, "table", 14.0), inst(2, "cup", 0.12), inst(3, "bowl", 0.22)]
    d = decide_units("colmap", split)
    assert d.estimate.available and not d.estimate.confident and not d.implausible()
    # a unit the user gives is applied even against clear evidence, with the evidence shown
    clear = [inst(0, "chair", 9.0), inst(1, "table", 14.0), inst(2, "cup", 1.2), inst(3, "bowl", 2.2)]
    d = decide_units("colmap", clear, metres_per_unit=1.0)
    assert d.kind == "given" and not d.implausible() and d.disagrees() and "WARNING: the objects suggest 0.1 m/unit" in d.text()
    assert decide_units("colmap", clear).implausible()

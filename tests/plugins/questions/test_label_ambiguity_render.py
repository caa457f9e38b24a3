"""Nothing visible is unnamed: every label-only question is checked against what its view shows.

A synthetic room with a bookshelf full of (unannotated) books, books of their own, chairs, an
armchair, a desk and a monitor is rendered at the views' own size; for every counting record
and every existence "no", the labels of all instances with at least one pixel in the view are
read from the instance-id map and compared with a table written here, independent of
``spacedg.scene.lexicon``: what a person asked about a label may also take for it. None may be
in view. An instance counts as shown from :data:`MIN_PIXELS` pixels: the families read
visibility from a half-size render, between whose samples a sliver of up to 3 pixels can fall
(1–2-pixel slivers of a shelf edge were seen), and nobody identifies an object from 3 pixels.
"""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.qa.build import prepare_scene
from spacedg.qa.index import QABuildConfig
from spacedg.plugins.questions import object_counting, object_existence_estimation
from spacedg.render import render
from spacedg.scene.synthetic import CaptureConfig, RoomConfig, generate_room

#: Pixels (at the view's own size) from which an instance counts as shown.
MIN_PIXELS = 4

#: Asked label → labels a person may take for it (or that show it: a bookshelf shows books).
TAKEN_FOR: dict[str, set[str]] = {
    "chair": {"armchair", "stool", "office chair"},
    "armchair": {"chair", "sofa"},
    "stool": {"chair"},
    "sofa": {"armchair", "couch"},
    "table": {"desk", "coffee table", "side table"},
    "desk": {"table"},
    "coffee table": {"table"},
    "monitor": {"tv"},
    "tv": {"monitor"},
    "lamp": {"floor lamp"},
    "floor lamp": {"lamp"},
    "book": {"bookshelf"},
    "plant": {"small plant"},
    "cabinet": {"wardrobe", "bookshelf"},
    "wardrobe": {"cabinet"},
    "cup": {"bowl", "vase"},
}


@pytest.fixture(scope="module", params=[6, 10])
def room(request):
    scene = generate_room(request.param, RoomConfig(gaussians=30_000, capture=CaptureConfig(320, 240, 24, 28), row_probability=0.0))
    labels = {inst.label for inst in scene.instances}
    assert {"bookshelf", "book", "chair", "armchair", "desk"} <= labels  # the cases worth checking
    return prepare_scene(scene, None, QABuildConfig(), backend="cpu", progress=False)


def test_label_only_questions_never_ask_about_what_a_view_shows_unnamed(room) -> None:
    counting = object_counting.make_family(counts=None)  # every valid count, not only the balanced ones
    records = list(counting.generate(room, np.random.default_rng(0)))
    records += [r for r in object_existence_estimation.FAMILY.generate(room, np.random.default_rng(0)) if r.answer == "no"]
    assert len(records) > 50
    labels = {inst.id: inst.label for inst in room.instances}
    shown: dict[str, set[str]] = {}
    checked = {"book": 0, "chair": 0}
    for r in records:
        view = r.views[0]
        if view not in shown:
            ids = render(room.gaussians, room.views[view], outputs="instance_ids", backend="cpu").instance_ids
            found, pixels = np.unique(ids, return_counts=True)
            shown[view] = {labels[int(i)] for i, n in zip(found, pixels) if int(i) in labels and n >= MIN_PIXELS}
        asked = str(r.geometry["label"]).lower()
        clash = TAKEN_FOR.get(asked, set()) & shown[view]
        assert not clash, f"{r.question_type} {r.question!r} (answer {r.answer}) in {view}, which shows {sorted(clash)}"
        if asked in checked:
            checked[asked] += 1
    assert all(checked.values()), checked  # books and chairs were asked about, and never beside a shelf or an armchair

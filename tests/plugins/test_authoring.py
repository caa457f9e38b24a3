"""The public authoring API (spacedg.plugins.authoring): re-exports, documented, and enough for a family."""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from spacedg.plugins import authoring
from tests.conftest import EXAMPLES, FAMILY_EXAMPLE
from tests.qa_scenes import build, camera, obj

#: The modules the API re-exports from (nothing is defined in authoring itself).
HOMES = (
    "spacedg.plugins.answers", "spacedg.plugins.candidates", "spacedg.plugins.hookspecs", "spacedg.plugins.qa_record", "spacedg.plugins.question_family",
    "spacedg.plugins.questions.geometry", "spacedg.plugins.questions.language", "spacedg.plugins.questions.records",
    "spacedg.plugins.questions.view_sampling", "spacedg.plugins.specs", "spacedg.scene.model", "spacedg.scene.visibility_classes",
)
EXAMPLE_MODULE = EXAMPLES / FAMILY_EXAMPLE / "spacedg_nearest_object.py"
#: The documentation page of plugin authors (the README's tour shows its degradation module too).
PLUGIN_PAGE = Path(__file__).resolve().parents[2] / "docs" / "plugins.md"


def test_every_name_is_a_documented_re_export() -> None:
    homes = [importlib.import_module(m) for m in HOMES]
    assert len(set(authoring.__all__)) == len(authoring.__all__)
    doc = authoring.__doc__ or ""
    for name in authoring.__all__:
        value = getattr(authoring, name)
        assert any(getattr(home, name, None) is value for home in homes), f"{name} is not re-exported from its home module"
        assert any(f":{role}:`{name}`" in doc for role in ("func", "class", "data")), f"{name} has no line in the module docstring"
    namespace: dict[str, object] = {}
    exec("from spacedg.plugins.authoring import *", namespace)  # noqa: S102 - the star import authors may use
    assert set(authoring.__all__) <= set(namespace)


def test_example_family_imports_only_the_public_api() -> None:
    """The example package is written against spacedg.plugins.authoring alone (no internals)."""
    tree = ast.parse(EXAMPLE_MODULE.read_text(encoding="utf-8"))
    spacedg_imports = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "spacedg":
            spacedg_imports.add(node.module)
        elif isinstance(node, ast.Import):
            spacedg_imports.update(a.name for a in node.names if a.name.split(".")[0] == "spacedg")
    assert spacedg_imports == {"spacedg.plugins.authoring"}


def test_a_family_from_the_api_alone_generates_checked_records() -> None:
    """A minimal family written in a few lines of the API: registered shape, seeded, validated records."""
    A = authoring

    def stream(scene, index, view, rng):
        for inst in A.seeded_order([index.instance(i) for i in A.referable_ids(index, view)], rng):
            yield A.make_record(
                scene, "tiny_count", "any", A.TaskGroup.OBJECT_CENTRIC, A.AnswerType.YN, (view,), {"object": inst.id},
                question=f"Is there {A.with_articles('a ' + A.phrase(inst))} in the image?", answer="yes",
                geometry={"object": A.object_entry(inst), "visibility": A.visibility_entry(index, (view,), (inst.id,))},
            )

    family = A.QuestionFamily(
        name="tiny_count", task_group=A.TaskGroup.OBJECT_CENTRIC, answer_types={A.AnswerType.YN}, sub_question_types=("any",),
        num_views=(1,), needs={"visibility"},
        generate=lambda scene, rng: A.round_robin_views(scene, A.VisibilityIndex(scene), rng, stream),
    )
    scene = build([obj(1, "chair", (3, 0, 0.4)), obj(2, "apple", (4, 1, 0.4), description="red apple")],
                  {"v0": camera((0, 0, 1)), "v1": camera((0, 0.5, 1))})
    first = list(family.generate(scene, np.random.default_rng(5)))
    again = list(family.generate(scene, np.random.default_rng(5)))
    assert first == again and len(first) == 4
    assert {r.question for r in first} == {"Is there a chair in the image?", "Is there a red apple in the image?"}
    assert all(r.geometry["visibility"][0]["class"] == A.VisibilityClass.VISIBLE for r in first)


def _readme_modules(tmp_path: Path) -> Path:
    """The Python blocks of docs/plugins.md ("Writing a plugin") that start with ``# <module>.py``, written as modules."""
    section = PLUGIN_PAGE.read_text(encoding="utf-8")
    written = set()
    for block in re.findall(r"```python\n(.*?)```", section, flags=re.S):
        first = block.splitlines()[0]
        if first.startswith("# ") and first.endswith(".py"):
            (tmp_path / first[2:]).write_text(block, encoding="utf-8")
            written.add(first[2:])
    assert written == {"spacedg_desaturate.py", "spacedg_closer.py"}
    return tmp_path


def test_readme_plugin_examples_load_and_run(clean_env, tmp_path) -> None:
    from spacedg.data.pipeline import degrade_image
    from spacedg.plugins import get_degradation, get_question_family, get_registry

    folder = _readme_modules(tmp_path)
    clean_env.syspath_prepend(str(folder))
    clean_env.setenv("SPACEDG_PLUGINS", "spacedg_desaturate,spacedg_closer")
    assert get_registry().broken == []
    assert get_degradation("desaturate").stage.value == "display"
    photo = np.random.default_rng(0).integers(0, 256, (12, 16, 3), dtype=np.uint8)
    faded, provenance = degrade_image(photo, "desaturate:5", seed=1)
    assert faded.dtype == np.uint8 and provenance[0]["name"] == "desaturate" and faded.std(axis=2).mean() < photo.std(axis=2).mean()

    family = get_question_family("closer_of_two")
    scene = build([obj(1, "chair", (3, 0, 0.4)), obj(2, "table", (4, 1, 0.4)), obj(3, "lamp", (5, -1, 0.4))], {"v0": camera((0, 0, 1))})
    records = list(family.generate(scene, np.random.default_rng(2)))
    assert len(records) == 3 and sorted(r.answer for r in records).count("yes") in (1, 2)
    for r in records:
        first, second = r.geometry["distances_m"]
        assert r.answer == ("yes" if first < second else "no")
    run = subprocess.run([sys.executable, str(folder / "spacedg_closer.py")], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert len(run.stdout.splitlines()) == 3 and all(line.endswith((" yes", " no")) for line in run.stdout.splitlines())

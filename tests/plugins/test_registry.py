"""Plugin system: entry-point discovery, broken and clashing plugins, environment switches,
the ``spacedg plugins`` command, unknown-name suggestions and spec validation.

The example third-party packages in ``tests/plugins/`` are pip-installed the normal way
(a wheel built by setuptools) into temporary target directories once per session:
``spacedg-vignetting`` + ``spacedg-broken`` in one, ``spacedg-clash`` in another.
"""

from __future__ import annotations

import importlib
import json
import os
import pickle
import subprocess
import sys
import textwrap
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spacedg.errors import DuplicatePluginError, ParameterError, PluginError, PluginWarning, UnknownPluginError
from spacedg.plugins import (
    AUTOLOAD_ENV,
    PLUGINS_ENV,
    AnswerType,
    Category,
    DegradationSpec,
    ParamRange,
    ParamSpec,
    QuestionFamily,
    Registry,
    Stage,
    TaskGroup,
    degradation_names,
    get_degradation,
    get_question_family,
    get_registry,
    hookimpl,
    list_degradations,
    list_question_families,
    reset_registry,
)

from tests.conftest import REPO_ROOT, Installed
SPACEDG_SCRIPT = Path(sys.executable).parent / "spacedg"
BUILTIN_DEGRADATIONS = {
    "defocus", "distortion", "motion_blur", "haze", "water_droplets", "low_light", "over_exposure", "jpeg_compression", "low_res",
}
BUILTIN_FAMILIES = {
    "camera_translation", "camera_rotation", "camera_object_distance_estimation", "camera_object_relative_direction",
    "cross_view_cardinal_direction", "inter_object_distance", "object_proxy_cardinal_direction", "object_size_comparison",
    "object_bounding_size_estimation", "object_existence_estimation", "object_counting",
}
BUILTINS = BUILTIN_DEGRADATIONS | BUILTIN_FAMILIES


def _subprocess_env(**extra: str) -> dict[str, str]:
    """The environment of a ``spacedg`` child process: no plugin switches, and ``PYTHONPATH`` =
    the folders in ``extra`` followed by the checkout under test, so the child runs this code (not
    whatever copy of spacedg the interpreter has installed)."""
    env = {k: v for k, v in os.environ.items() if k not in (AUTOLOAD_ENV, PLUGINS_ENV, "PYTHONPATH")}
    paths = [extra.pop("PYTHONPATH")] if "PYTHONPATH" in extra else []
    env.update(extra)
    env["PYTHONPATH"] = os.pathsep.join([*paths, str(REPO_ROOT)])
    return env


def _by_name(doc_entries: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    return {e["name"]: e for e in doc_entries}


# ------------------------------------------------------------- discovery
def test_builtins_found_via_entry_points(clean_env) -> None:
    registry = get_registry()
    origins = {r.origin.name: r.origin for r in registry.plugins}
    assert BUILTINS <= set(origins)
    for name in BUILTINS:
        origin = origins[name]
        assert origin.distribution == "spacedg" and origin.builtin and origin.source == "entry_point"
        assert origin.version
    assert get_degradation("jpeg_compression").origin.distribution == "spacedg"
    assert get_question_family("object_counting").origin.name == "object_counting"
    assert "jpeg_compression" in [d.name for d in list_degradations()]
    assert "object_counting" in [f.name for f in list_question_families()]
    assert registry.broken == []


def test_cli_json_lists_third_party_and_broken(installed: Installed) -> None:
    result = subprocess.run(
        [str(SPACEDG_SCRIPT), "plugins", "--json"],
        capture_output=True, text=True, timeout=120, env=_subprocess_env(PYTHONPATH=str(installed.main)),
    )
    assert result.returncode == 0, result.stderr
    doc = json.loads(result.stdout)
    plugins = _by_name(doc["plugins"])
    assert doc["autoload"] is True
    for name in BUILTINS:
        assert plugins[name]["distribution"] == "spacedg" and plugins[name]["builtin"] is True
    vig = plugins["vignetting"]
    assert (vig["distribution"], vig["version"], vig["builtin"]) == ("spacedg-vignetting", "0.3.1", False)
    (deg,) = vig["degradations"]
    assert (deg["name"], deg["stage"], deg["category"]) == ("vignetting", "linear", "photometric")
    assert set(deg["presets"]) == {"bench", "1", "2", "3", "4", "5"}
    fam = plugins["object_counting"]["question_families"][0]
    assert (fam["task_group"], fam["answer_types"], fam["num_views"]) == ("object_centric", ["COUNT"], [1])
    broken = _by_name(doc["broken"])
    assert broken["broken_example"]["distribution"] == "spacedg-broken"
    assert broken["broken_example"]["error_type"] == "ModuleNotFoundError"
    assert "spacedg_this_dependency_does_not_exist" in broken["broken_example"]["message"]


def test_cli_text_and_autoload_switch(installed: Installed) -> None:
    text = subprocess.run(
        [str(SPACEDG_SCRIPT), "plugins"],
        capture_output=True, text=True, timeout=120, env=_subprocess_env(PYTHONPATH=str(installed.main)),
    )
    assert text.returncode == 0, text.stderr
    assert "spacedg-vignetting 0.3.1, third-party" in text.stdout
    assert "Broken plugins" in text.stdout and "ModuleNotFoundError" in text.stdout
    hermetic = subprocess.run(
        [str(SPACEDG_SCRIPT), "plugins", "--json"],
        capture_output=True, text=True, timeout=120,
        env=_subprocess_env(PYTHONPATH=str(installed.main), **{AUTOLOAD_ENV: "1"}),
    )
    assert hermetic.returncode == 0, hermetic.stderr
    doc = json.loads(hermetic.stdout)
    assert doc["autoload"] is False
    assert {p["name"] for p in doc["plugins"]} == BUILTINS
    assert doc["broken"] == []
    assert {s["name"] for s in doc["skipped"]} == {"vignetting", "broken_example"}


def test_cli_plugins_lists_a_clash(installed: Installed) -> None:
    """`spacedg plugins` is the diagnosis tool: with a clash installed it still lists everything,
    the clash included (both sources and the fix), and exits 0."""
    path = os.pathsep.join([str(installed.main), str(installed.clash)])
    result = subprocess.run([str(SPACEDG_SCRIPT), "plugins"], capture_output=True, text=True, timeout=120,
                            env=_subprocess_env(PYTHONPATH=path))
    assert result.returncode == 0, result.stderr
    assert "1 name clash" in result.stdout and "Name clashes" in result.stdout
    clash_lines = result.stdout.split("Name clashes", 1)[1]
    assert "degradation 'vignetting'" in clash_lines
    assert "spacedg-vignetting 0.3.1" in clash_lines and "spacedg-clash 1.0.0" in clash_lines
    assert "pip uninstall" in clash_lines
    assert "Traceback" not in result.stderr
    doc = json.loads(subprocess.run([str(SPACEDG_SCRIPT), "plugins", "--json"], capture_output=True, text=True, timeout=120,
                                    env=_subprocess_env(PYTHONPATH=path)).stdout)
    (clash,) = doc["clashes"]
    assert (clash["kind"], clash["name"]) == ("degradation", "vignetting")
    assert sorted(s["distribution"] for s in clash["sources"]) == ["spacedg-clash", "spacedg-vignetting"]


def test_cli_other_commands_warn_about_a_clash_and_run_on(installed: Installed, tmp_path: Path) -> None:
    """A command that does not use the clashing name warns once (one line) and works; one that
    uses it fails with one line naming both sources."""
    path = os.pathsep.join([str(installed.main), str(installed.clash)])
    scenes = tmp_path / "scenes"
    ok = subprocess.run([str(SPACEDG_SCRIPT), "scenes", "synth", "--n", "1", "--out", str(scenes), "--gaussians", "10000",
                         "--width", "64", "--height", "48", "--min-views", "4", "--max-views", "6"],
                        capture_output=True, text=True, timeout=300, env=_subprocess_env(PYTHONPATH=path))
    assert ok.returncode == 0, ok.stderr
    run = [str(SPACEDG_SCRIPT), "gallery", str(scenes / "room-000000"), "--thumb-width", "64"]
    fine = subprocess.run([*run, "--out", str(tmp_path / "g.png"), "--degradations", "haze"],
                          capture_output=True, text=True, timeout=300, env=_subprocess_env(PYTHONPATH=path))
    assert fine.returncode == 0, fine.stderr
    warnings = [line for line in fine.stderr.splitlines() if line.startswith("spacedg: warning:")]
    assert len(warnings) == 1 and "'vignetting'" in warnings[0] and "spacedg-clash 1.0.0" in warnings[0], fine.stderr
    assert "Traceback" not in fine.stderr
    clash = subprocess.run([*run, "--out", str(tmp_path / "v.png"), "--degradations", "vignetting"],
                           capture_output=True, text=True, timeout=300, env=_subprocess_env(PYTHONPATH=path))
    assert clash.returncode == 2
    (error,) = [line for line in clash.stderr.splitlines() if line.startswith("spacedg: error:")]
    assert "spacedg-vignetting 0.3.1" in error and "spacedg-clash 1.0.0" in error and "Traceback" not in clash.stderr


def test_third_party_degradation_in_process(third_party) -> None:
    spec = get_degradation("vignetting")
    assert spec.origin is not None
    assert (spec.origin.distribution, spec.origin.version, spec.origin.builtin) == ("spacedg-vignetting", "0.3.1", False)
    assert spec.origin.name == "vignetting" and spec.origin.source == "entry_point"
    assert spec.stage is Stage.LINEAR and spec.category is Category.PHOTOMETRIC
    params = spec.sample_params("bench", np.random.default_rng(0))
    assert 0.8 <= params["half_fov"] <= 0.9 and params["strength"] == 1.0
    rgb = np.full((48, 64, 3), 0.5, dtype=np.float32)
    out = spec.apply(rgb, {}, params, np.random.default_rng(0))
    assert out.dtype == np.float32 and out.shape == rgb.shape
    assert np.array_equal(rgb, np.full((48, 64, 3), 0.5, dtype=np.float32)), "input modified in place"
    centre, corner = out[24, 32, 0], out[0, 0, 0]
    assert centre == pytest.approx(0.5, abs=1e-3)
    expected_corner = 0.5 * np.cos(params["half_fov"]) ** 4  # cos⁴ law at (almost) the corner angle
    assert corner == pytest.approx(expected_corner, rel=0.05)
    identity = spec.apply(rgb, {}, {"half_fov": 0.0, "strength": 1.0}, np.random.default_rng(0))
    assert np.array_equal(identity, rgb)
    # harsher severities darken the corners more
    corners = []
    for level in ("1", "2", "3", "4", "5"):
        p = spec.sample_params(level, np.random.default_rng(1))
        corners.append(float(spec.apply(rgb, {}, p, np.random.default_rng(1))[0, 0, 0]))
    assert corners == sorted(corners, reverse=True)


def test_broken_plugin_recorded_others_load(third_party) -> None:
    registry = get_registry()
    (broken,) = [b for b in registry.broken if b.origin.name == "broken_example"]
    assert broken.origin.distribution == "spacedg-broken" and broken.origin.version == "0.0.1"
    assert broken.phase == "import" and broken.error_type == "ModuleNotFoundError"
    assert "spacedg_this_dependency_does_not_exist" in broken.message
    assert "spacedg_broken.py" in broken.traceback
    assert {"jpeg_compression", "vignetting"} <= {d.name for d in registry.list_degradations()}
    with pytest.raises(UnknownPluginError, match=r"broken_example.*failed to load.*ModuleNotFoundError"):
        registry.get_degradation("broken_example")


def test_duplicate_names_are_withheld_naming_both(installed: Installed, third_party) -> None:
    """A clash is recorded and warned about; the clashing name raises naming both, every other
    name (built-ins included) still works, and names-only listings never raise."""
    third_party.syspath_prepend(str(installed.clash))
    importlib.invalidate_caches()
    reset_registry()
    with pytest.warns(PluginWarning, match=r"'vignetting' is registered by 2 plugins.*spacedg-clash 1\.0\.0.*spacedg-vignetting 0\.3\.1"):
        registry = get_registry()
    (clash,) = registry.clashes
    assert (clash.kind, clash.name) == ("degradation", "vignetting")
    assert sorted(o.distribution for o in clash.sources) == ["spacedg-clash", "spacedg-vignetting"]
    for call in (lambda: get_degradation("vignetting"), list_degradations):
        with pytest.raises(DuplicatePluginError) as info:
            call()
        message = str(info.value)
        for needle in ("'vignetting'", "spacedg-vignetting 0.3.1", "spacedg-clash 1.0.0", "clash_vignetting", AUTOLOAD_ENV,
                       PLUGINS_ENV, "uninstall"):
            assert needle in message, (needle, message)
    assert get_degradation("haze").origin.builtin
    assert {f.name for f in list_question_families()} == BUILTIN_FAMILIES
    assert "vignetting" in degradation_names() and BUILTIN_DEGRADATIONS <= set(degradation_names())
    assert registry.describe()["clashes"][0]["name"] == "vignetting"


def test_clash_with_a_builtin_keeps_the_builtin_usable_elsewhere(clean_env, tmp_path: Path) -> None:
    """A third-party `haze` (an SPACEDG_PLUGINS module here) withholds `haze` only: its other
    names load, the built-ins load, and the error on `haze` names both sources."""
    (tmp_path / "my_haze_plugin.py").write_text(textwrap.dedent(
        """
        import numpy as np
        from spacedg.plugins import Category, DegradationSpec, ParamSpec, Stage, hookimpl

        def apply(rgb, aux, params, rng):
            return rgb.copy()

        PRESETS = {k: {"x": (0.1, 0.1 * (int(k) if k != "bench" else 1))} for k in ("bench", "1", "2", "3", "4", "5")}

        def spec(name):
            return DegradationSpec(name, Category.PHOTOMETRIC, Stage.LINEAR, (ParamSpec("x", "1", "amount", 0.0, 1.0),), PRESETS, apply)

        @hookimpl
        def spacedg_register_degradations(register):
            register(spec("haze"))
            register(spec("my_fog"))
        """
    ))
    clean_env.syspath_prepend(str(tmp_path))
    clean_env.setenv(PLUGINS_ENV, "my_haze_plugin")
    reset_registry()
    with pytest.warns(PluginWarning, match="'haze'"):
        registry = get_registry()
    assert get_degradation("my_fog").origin.source == "env"
    assert get_degradation("defocus").origin.builtin
    with pytest.raises(DuplicatePluginError, match=r"'haze'.*distribution spacedg .*my_haze_plugin.*built-in cannot be replaced"):
        get_degradation("haze")
    (record,) = [r for r in registry.plugins if r.origin.name == "my_haze_plugin"]
    assert record.degradations == ("my_fog",)


def test_duplicate_resolved_by_documented_fix(installed: Installed, third_party) -> None:
    third_party.syspath_prepend(str(installed.clash))
    third_party.setenv(AUTOLOAD_ENV, "1")
    third_party.setenv(PLUGINS_ENV, "spacedg_vignetting")
    importlib.invalidate_caches()
    reset_registry()
    spec = get_degradation("vignetting")
    assert spec.origin.source == "env" and spec.origin.distribution == "spacedg-vignetting"


def test_autoload_disabled_hides_third_party(third_party) -> None:
    third_party.setenv(AUTOLOAD_ENV, "1")
    reset_registry()
    registry = get_registry()
    assert {d.name for d in registry.list_degradations()} == BUILTIN_DEGRADATIONS
    assert {r.origin.name for r in registry.plugins} == BUILTINS
    assert registry.broken == []
    with pytest.raises(UnknownPluginError) as info:
        get_degradation("vignetting")
    message = str(info.value)
    assert "autoloading is disabled" in message and "spacedg-vignetting" in message


def test_explicit_modules_load_with_autoload_disabled(third_party, tmp_path: Path) -> None:
    (tmp_path / "my_local_plugin.py").write_text(textwrap.dedent(
        """
        import numpy as np
        from spacedg.plugins import Category, DegradationSpec, ParamSpec, Stage, hookimpl

        def apply(image, params, rng):
            return (255 - image).astype(np.uint8) if params["on"] else image.copy()

        PRESETS = {k: {"on": (1, 1)} for k in ("bench", "1", "2", "3", "4", "5")}
        SPEC = DegradationSpec("invert", Category.DIGITAL, Stage.DISPLAY,
                               (ParamSpec("on", "1", "1 = invert", low=0, high=1, integer=True),), PRESETS, apply)

        @hookimpl
        def spacedg_register_degradations(register):
            register(SPEC)
        """
    ))
    (tmp_path / "my_raising_plugin.py").write_text(textwrap.dedent(
        """
        from spacedg.plugins import hookimpl

        @hookimpl
        def spacedg_register_question_families(register):
            raise RuntimeError("database unavailable")
        """
    ))
    third_party.syspath_prepend(str(tmp_path))
    third_party.setenv(AUTOLOAD_ENV, "1")
    third_party.setenv(PLUGINS_ENV, " spacedg_vignetting, my_local_plugin,my_raising_plugin, no_such_module_xyz ,")
    reset_registry()
    registry = get_registry()
    names = {d.name for d in registry.list_degradations()}
    assert names == BUILTIN_DEGRADATIONS | {"vignetting", "invert"}
    assert get_degradation("invert").origin.source == "env"
    assert get_degradation("invert").origin.distribution is None
    broken = {b.origin.name: b for b in registry.broken}
    assert broken["my_raising_plugin"].phase == "hook" and "database unavailable" in broken["my_raising_plugin"].message
    assert broken["no_such_module_xyz"].phase == "import"
    assert registry.explicit_modules == ("spacedg_vignetting", "my_local_plugin", "my_raising_plugin", "no_such_module_xyz")


def test_explicit_module_already_loaded_is_not_a_duplicate(third_party) -> None:
    third_party.setenv(PLUGINS_ENV, "spacedg_vignetting,spacedg.plugins.degradations.jpeg_compression")
    reset_registry()
    registry = get_registry()
    assert get_degradation("vignetting").origin.source == "entry_point"
    assert sum(r.degradations.count("jpeg_compression") for r in registry.plugins) == 1


def test_bad_environment_values(clean_env) -> None:
    clean_env.setenv(AUTOLOAD_ENV, "maybe")
    with pytest.raises(PluginError, match=f"{AUTOLOAD_ENV}='maybe'.*1 .*0"):
        get_registry()
    clean_env.setenv(AUTOLOAD_ENV, "0")
    clean_env.setenv(PLUGINS_ENV, "good.module, bad module!")
    with pytest.raises(PluginError, match="not module paths"):
        Registry.from_environment()


def test_unknown_names_suggest(clean_env) -> None:
    with pytest.raises(UnknownPluginError) as info:
        get_degradation("jpeg_compresion")
    message = str(info.value)
    assert "Did you mean 'jpeg_compression'" in message
    assert "Available degradations: " + ", ".join(sorted(BUILTIN_DEGRADATIONS)) in message
    with pytest.raises(UnknownPluginError, match="Did you mean 'object_counting'.*Available question families: " + ", ".join(sorted(BUILTIN_FAMILIES))):
        get_question_family("object_count")
    with pytest.raises(UnknownPluginError, match="unknown degradation 'zzz'"):
        get_degradation("zzz")
    assert isinstance(UnknownPluginError("x"), LookupError)


def test_registry_is_a_thread_safe_singleton(clean_env) -> None:
    results: list[Registry] = []
    threads = [threading.Thread(target=lambda: results.append(get_registry())) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(results) == 8 and all(r is results[0] for r in results)
    reset_registry()
    assert get_registry() is not results[0]


def test_registered_specs_pickle(clean_env) -> None:
    for obj in (get_degradation("jpeg_compression"), get_question_family("object_counting")):
        clone = pickle.loads(pickle.dumps(obj))
        assert clone.name == obj.name and clone.origin == obj.origin


# ------------------------------------------------------- in-process API
def _display_spec(name: str = "solarize") -> DegradationSpec:
    def apply(image: np.ndarray, params: dict, rng: np.random.Generator) -> np.ndarray:
        return np.where(image > params["threshold"], 255 - image, image).astype(np.uint8)

    presets = {"bench": {"threshold": (100, 120)}, **{str(i): {"threshold": (250 - 40 * i, 250 - 40 * i)} for i in range(1, 6)}}
    return DegradationSpec(name, "digital", "display", (ParamSpec("threshold", "1", "8-bit level", 0, 255, integer=True, harsher="lower"),), presets, apply)


class _Plugin:
    def __init__(self, *specs: DegradationSpec) -> None:
        self.specs = specs

    @hookimpl
    def spacedg_register_degradations(self, register) -> None:
        for spec in self.specs:
            register(spec)


def test_register_plugin_programmatic() -> None:
    registry = Registry()
    record = registry.register_plugin(_Plugin(_display_spec()), "my_plugin", distribution="my-dist", version="2.0")
    assert record.degradations == ("solarize",)
    spec = registry.get_degradation("solarize")
    assert spec.origin.source == "programmatic" and spec.origin.distribution == "my-dist"
    image = np.arange(256, dtype=np.uint8).reshape(16, 16, 1).repeat(3, axis=2)
    out = spec.apply(image, spec.sample_params("5", np.random.default_rng(0)), np.random.default_rng(0))
    assert out.dtype == np.uint8 and out.shape == image.shape

    with pytest.raises(DuplicatePluginError, match=r"'solarize'.*my-dist 2\.0.*other"):
        registry.register_plugin(_Plugin(_display_spec()), "other")
    assert [r.origin.name for r in registry.plugins] == ["my_plugin"]  # the clashing plugin was rolled back
    with pytest.raises(DuplicatePluginError, match="registered twice"):
        registry.register_plugin(_Plugin(_display_spec("twice"), _display_spec("twice")), "twice")
    with pytest.raises(UnknownPluginError):
        registry.get_degradation("twice")  # nothing of a failed plugin stays


def test_register_plugin_failures_raise() -> None:
    registry = Registry()

    class NoHooks:
        pass

    class Raising:
        @hookimpl
        def spacedg_register_question_families(self, register):
            raise ValueError("boom")

    class WrongType:
        @hookimpl
        def spacedg_register_degradations(self, register):
            register({"name": "not a spec"})

    class Misspelled:
        @hookimpl
        def spacedg_register_degradation(self, register):  # missing "s"
            pass

    with pytest.raises(PluginError, match="implements no spacedg hook"):
        registry.register_plugin(NoHooks(), "none")
    with pytest.raises(PluginError, match="boom") as info:
        registry.register_plugin(Raising(), "raising")
    assert isinstance(info.value.__cause__, ValueError)
    with pytest.raises(PluginError, match="expects a DegradationSpec, got dict"):
        registry.register_plugin(WrongType(), "wrong")
    with pytest.raises(PluginError, match="spacedg_register_degradation"):
        registry.register_plugin(Misspelled(), "misspelled")
    assert registry.plugins == [] and registry.list_degradations() == []


# ------------------------------------------------------ spec validation
def _ok_presets(low: float = 0.1, high: float = 0.2) -> dict[str, dict[str, tuple[float, float]]]:
    return {name: {"x": (low, high)} for name in ("bench", "1", "2", "3", "4", "5")}


def _linear_apply(rgb, aux, params, rng):
    return rgb.copy()


def _spec(**changes: Any) -> DegradationSpec:
    kwargs: dict[str, Any] = dict(
        name="demo", category=Category.PHOTOMETRIC, stage=Stage.LINEAR,
        params=(ParamSpec("x", "1", "amount", 0.0, 1.0, harsher="higher"),),
        presets=_ok_presets(), apply=_linear_apply,
    )
    kwargs.update(changes)
    return DegradationSpec(**kwargs)


@pytest.mark.parametrize(
    ("changes", "pattern"),
    [
        ({"name": "Bad-Name"}, r"not a valid name.*\^\[a-z\]"),
        ({"category": "photometrc"}, r"category 'photometrc' is not one of.*Did you mean 'photometric'"),
        ({"stage": "post"}, r"stage 'post' is not one of: raster, linear, display"),
        ({"apply": 3}, "apply must be callable"),
        ({"needs": {"depht"}}, r"needs \['depht'\] are not render outputs"),
        ({"stage": Stage.DISPLAY, "needs": {"depth"}}, "display-stage degradation receives no render outputs"),
        ({"presets": {**_ok_presets(), "1": {"y": (0.1, 0.2)}}}, r"preset '1' names unknown parameter\(s\) \['y'\]"),
        ({"presets": {**_ok_presets(), "2": {}}}, r"preset '2' does not give a range for \['x'\]"),
        ({"presets": {**_ok_presets(), "bench": {"x": (0.5, 1.5)}}}, r"outside its hard limits \[0, 1\]"),
        ({"presets": {k: v for k, v in _ok_presets().items() if k != "bench"}}, r"missing preset\(s\) \['bench'\]"),
        ({"presets": {**_ok_presets(), "5": {"x": (0.0, 0.05)}}}, "must get harsher from '1' to '5'"),
        ({"presets": {**_ok_presets(), "Bench!": {"x": 0.1}}}, "preset name 'Bench!'"),
        ({"params": (ParamSpec("x", "1", ""), ParamSpec("x", "1", ""))}, r"parameter\(s\) \['x'\] declared more than once"),
        ({"order": float("nan")}, "order must be a finite number"),
    ],
)
def test_degradation_spec_validation(changes: dict[str, Any], pattern: str) -> None:
    with pytest.raises(PluginError, match=pattern):
        _spec(**changes)


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"name": "x", "unit": ""}, "unit must be a non-empty string"),
        ({"name": "x", "unit": "1", "low": 2, "high": 1}, "low=2.0 > high=1.0"),
        ({"name": "x", "unit": "1", "low": 0.5, "integer": True}, "is integer, but its hard limit low is 0.5"),
        ({"name": "x", "unit": "1", "harsher": "up"}, "harsher must be"),
        ({"name": "2x", "unit": "1"}, "parameter name '2x' is not a valid name"),
    ],
)
def test_param_spec_validation(kwargs: dict[str, Any], pattern: str) -> None:
    kwargs.setdefault("description", "")
    with pytest.raises(PluginError, match=pattern):
        ParamSpec(**kwargs)


def test_param_range() -> None:
    with pytest.raises(PluginError, match="low=2.0 > high=1.0"):
        ParamRange(2.0, 1.0)
    with pytest.raises(PluginError, match="finite"):
        ParamRange(0.0, float("inf"))
    assert ParamRange.of(3) == ParamRange(3, 3) and ParamRange.of((1, 2)).to_list() == [1, 2]
    rng = np.random.default_rng(0)
    ints = [ParamRange(2, 5).sample(rng, integer=True) for _ in range(2000)]
    assert set(ints) == {2, 3, 4, 5} and all(isinstance(v, int) for v in ints)
    counts = np.bincount(ints)[2:]
    assert counts.min() > 400  # uniform, inclusive ends
    floats = [ParamRange(0.5, 0.75).sample(rng) for _ in range(500)]
    assert min(floats) >= 0.5 and max(floats) <= 0.75
    assert ParamRange(0.3, 0.3).sample(np.random.default_rng(1)) == 0.3
    # a fixed range still consumes exactly one draw, so other parameters' draws do not shift
    a, b = np.random.default_rng(5), np.random.default_rng(5)
    ParamRange(0.3, 0.3).sample(a)
    b.random()
    assert a.random() == b.random()


def test_validate_and_sample_params() -> None:
    spec = _spec(params=(ParamSpec("x", "1", "amount", 0.0, 1.0, harsher="higher"), ParamSpec("steps", "1", "n", 1, 100, integer=True)),
                 presets={name: {"x": (0.1, 0.2), "steps": (8, 8)} for name in ("bench", "1", "2", "3", "4", "5")})
    assert spec.validate_params({"x": 1, "steps": 3.0}) == {"x": 1.0, "steps": 3}
    assert isinstance(spec.validate_params({"x": 1, "steps": 3.0})["steps"], int)
    with pytest.raises(ParameterError, match=r"unknown parameter 'stpes'.*Did you mean 'steps'"):
        spec.validate_params({"x": 0.5, "stpes": 3})
    with pytest.raises(ParameterError, match=r"'x' = 1.5 is outside its hard limits \[0, 1\]"):
        spec.validate_params({"x": 1.5, "steps": 3})
    with pytest.raises(ParameterError, match="must be an integer"):
        spec.validate_params({"x": 0.5, "steps": 3.5})
    with pytest.raises(ParameterError, match="finite number"):
        spec.validate_params({"x": float("nan"), "steps": 3})
    with pytest.raises(ParameterError, match=r"missing parameter\(s\) \['steps'\]"):
        spec.validate_params({"x": 0.5})
    assert spec.validate_params({"x": 0.5}, partial=True) == {"x": 0.5}
    first = spec.sample_params("3", np.random.default_rng(9))
    assert first == spec.sample_params(3, np.random.default_rng(9))  # severities may be ints
    assert 0.1 <= first["x"] <= 0.2 and first["steps"] == 8
    with pytest.raises(ParameterError, match=r"unknown preset 'bnech'.*Did you mean 'bench'"):
        spec.sample_params("bnech", np.random.default_rng(0))
    assert spec.preset_names == ["bench", "1", "2", "3", "4", "5"]
    assert spec.sort_key == (1, 50.0, "demo")


def test_question_family_validation() -> None:
    def gen(scene, rng):
        return iter(())

    base: dict[str, Any] = dict(name="demo_family", task_group=TaskGroup.OBJECT_CENTRIC, answer_types={AnswerType.COUNT},
                                sub_question_types=("count",), num_views=(1,), generate=gen)
    family = QuestionFamily(**base)
    assert family.generate.__wrapped__ is gen and family.num_views == (1,)
    assert family.describe()["metric_only"] is False and QuestionFamily(**base, metric_only=True).describe()["metric_only"] is True
    assert family.describe()["plain_rounds"] is False and QuestionFamily(**base, plain_rounds=True).describe()["plain_rounds"] is True
    assert QuestionFamily(**{**base, "sub_question_types": ("yaw+pitch_dual",)}).sub_question_types == ("yaw+pitch_dual",)
    assert QuestionFamily(**{**base, "sub_question_types": ("relpos_A_facing_B",)}).sub_question_types == ("relpos_A_facing_B",)
    for changes, pattern in [
        ({"task_group": "objects"}, "task_group 'objects' is not one of"),
        ({"answer_types": {"COUNTS"}}, r"answer type 'COUNTS'.*Did you mean 'COUNT'"),
        ({"answer_types": set()}, "at least one answer type"),
        ({"sub_question_types": ("Bad",)}, "sub_question_type 'Bad'"),
        ({"num_views": (0,)}, "num_views must be positive integers"),
        ({"needs": {"visibilty"}}, r"needs \['visibilty'\] unknown"),
        ({"generate": None}, "generate must be callable"),
        ({"metric_only": 1}, "metric_only must be True or False"),
        ({"plain_rounds": "yes"}, "plain_rounds must be True or False"),
        ({"metric_only": True, "plain_rounds": True}, "metric_only and plain_rounds exclude each other"),
    ]:
        with pytest.raises(PluginError, match=pattern):
            QuestionFamily(**{**base, **changes})


def test_generated_records_are_checked_against_the_declaration() -> None:
    from spacedg.plugins.qa_record import QARecord
    from spacedg.scene.model import Scene
    from spacedg.render.gaussians import Gaussians

    def record(**changes: Any) -> QARecord:
        kwargs: dict[str, Any] = dict(id="s/demo_family/count/x", scene_id="s", question_type="demo_family", sub_question_type="count",
                                      task_group="object_centric", answer_type="COUNT", views=("v0",), question="How many?", answer=1)
        kwargs.update(changes)
        return QARecord(**kwargs)

    def family_yielding(*records: Any) -> QuestionFamily:
        return QuestionFamily("demo_family", "object_centric", {"COUNT"}, ("count",), (1,), lambda scene, rng: iter(records))

    scene = Scene("s", Gaussians.empty(), {})
    rng = np.random.default_rng(0)
    assert list(family_yielding(record()).generate(scene, rng)) == [record()]
    for bad, pattern in [
        (record(question_type="other"), "question_type is 'other'"),
        (record(task_group="camera_centric"), "task_group is 'camera_centric'"),
        (record(answer_type="NA", answer=1.0), "answer_type 'NA' is not declared"),
        (record(sub_question_type="total"), "sub_question_type 'total' is not declared"),
        (record(views=("v0", "v1")), r"uses 2 view\(s\), declared \[1\]"),
        (record(scene_id="elsewhere"), "scene_id is 'elsewhere'"),
        ({"not": "a record"}, "yielded a dict, not a QARecord"),
    ]:
        with pytest.raises(PluginError, match=pattern):
            list(family_yielding(bad).generate(scene, rng))

"""Plugins that misbehave at run time or at import: a raising ``apply`` / ``generate`` is named
(plugin and distribution), a ``KeyboardInterrupt`` raised by a plugin marks it broken, a real
Ctrl+C during a plugin import exits 130 naming it, a slow import is announced while it runs."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from spacedg.errors import PluginImportInterrupted, PluginRuntimeError, PluginWarning
from spacedg.plugins import (
    AUTOLOAD_ENV,
    PLUGINS_ENV,
    Category,
    DegradationSpec,
    ParamSpec,
    QuestionFamily,
    Registry,
    Stage,
    TaskGroup,
    get_registry,
    hookimpl,
    registry as registry_module,
    reset_registry,
)
from tests.conftest import REPO_ROOT, ctrl_c_reaches_child

SPACEDG_SCRIPT = Path(sys.executable).parent / "spacedg"
PRESETS = {k: {"x": (0.1, 0.1)} for k in ("bench", "1", "2", "3", "4", "5")}


def _env(plugin_dir: Path, modules: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in (AUTOLOAD_ENV, PLUGINS_ENV, "PYTHONPATH")}
    env.update({"PYTHONPATH": os.pathsep.join([str(plugin_dir), str(REPO_ROOT)]), AUTOLOAD_ENV: "1", PLUGINS_ENV: modules})
    return env


def _exploding_linear(rgb, aux, params, rng):  # noqa: ANN001, ANN202 - a plugin's apply
    return rgb / 0 if params["x"] > 1 else {}["no such key"]


class _Plugin:
    def __init__(self, *specs: object, families: tuple[QuestionFamily, ...] = ()) -> None:
        self.specs, self.families = specs, families

    @hookimpl
    def spacedg_register_degradations(self, register) -> None:  # noqa: ANN001
        for spec in self.specs:
            register(spec)

    @hookimpl
    def spacedg_register_question_families(self, register) -> None:  # noqa: ANN001
        for family in self.families:
            register(family)


@pytest.fixture
def boom_registry(clean_env, monkeypatch: pytest.MonkeyPatch) -> Registry:
    """The process registry (built-ins) plus a programmatic plugin of distribution spacedg-boom 1.2."""
    clean_env.setenv(AUTOLOAD_ENV, "1")
    registry = Registry.from_environment()

    def generate(scene, rng):  # noqa: ANN001, ANN202
        yield from ()
        raise RuntimeError("the family's database is gone")

    family = QuestionFamily("boom_family", TaskGroup.OBJECT_CENTRIC, {"COUNT"}, ("count",), (1,), generate)
    spec = DegradationSpec("boom", Category.PHOTOMETRIC, Stage.LINEAR, (ParamSpec("x", "1", "amount", 0.0, 1.0),), PRESETS,
                           _exploding_linear)
    registry.register_plugin(_Plugin(spec, families=(family,)), "boom_plugin", distribution="spacedg-boom", version="1.2")
    monkeypatch.setattr(registry_module, "_REGISTRY", registry)
    return registry


def test_apply_error_names_plugin_and_distribution(boom_registry: Registry) -> None:
    from spacedg.data.pipeline import degrade_image

    photo = np.random.default_rng(0).integers(0, 256, (20, 24, 3), dtype=np.uint8)
    with pytest.raises(PluginRuntimeError) as info:
        degrade_image(photo, "boom", seed=1)
    err = info.value
    assert (err.plugin, err.distribution) == ("boom", "spacedg-boom")
    assert isinstance(err.__cause__, KeyError)
    message = str(err)
    for needle in ("degradation 'boom'", "spacedg-boom 1.2", "raised KeyError in apply", "test_plugin_failures.py:",
                   "pip uninstall spacedg-boom"):
        assert needle in message, (needle, message)
    assert "\n" not in message
    # built-ins still work beside it, and spacedg's own errors pass through unchanged
    out, _ = degrade_image(photo, "low_res:1", seed=1)
    assert out.shape == photo.shape


def test_generate_error_names_family_and_distribution(boom_registry: Registry) -> None:
    from spacedg.qa.build import generate_records
    from spacedg.qa.index import QABuildConfig
    from spacedg.render.gaussians import Gaussians
    from spacedg.scene.model import Scene

    with pytest.raises(PluginRuntimeError) as info:
        generate_records(Scene("s", Gaussians.empty(), {}), QABuildConfig(families=("boom_family",)))
    assert (info.value.plugin, info.value.distribution) == ("boom_family", "spacedg-boom")
    assert isinstance(info.value.__cause__, RuntimeError)
    assert "question family 'boom_family'" in str(info.value) and "raised RuntimeError in generate" in str(info.value)
    assert "the family's database is gone" in str(info.value)


def test_plugin_runtime_error_pickles_and_rebuilds_from_a_message() -> None:
    import pickle

    err = PluginRuntimeError("degradation 'x' raised", plugin="x", distribution="d")
    clone = pickle.loads(pickle.dumps(err))
    assert (str(clone), clone.plugin, clone.distribution) == (str(err), "x", "d")
    assert str(PluginRuntimeError("from a DataLoader worker")) == "from a DataLoader worker"  # torch re-raises with one message


def test_cli_apply_error_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "boom_cli_plugin.py").write_text(textwrap.dedent(
        """
        from spacedg.plugins import Category, DegradationSpec, ParamSpec, Stage, hookimpl

        def apply(image, params, rng):
            raise ZeroDivisionError("division by zero")

        PRESETS = {k: {"x": (0.1, 0.1)} for k in ("bench", "1", "2", "3", "4", "5")}

        @hookimpl
        def spacedg_register_degradations(register):
            register(DegradationSpec("boom_cli", Category.DIGITAL, Stage.DISPLAY,
                                     (ParamSpec("x", "1", "amount", 0.0, 1.0),), PRESETS, apply))
        """
    ))
    scenes = tmp_path / "scenes"
    env = _env(tmp_path, "boom_cli_plugin")
    made = subprocess.run([str(SPACEDG_SCRIPT), "scenes", "synth", "--n", "1", "--out", str(scenes), "--gaussians", "10000",
                           "--width", "64", "--height", "48", "--min-views", "4", "--max-views", "6"],
                          capture_output=True, text=True, timeout=300, env=env)
    assert made.returncode == 0, made.stderr
    result = subprocess.run([str(SPACEDG_SCRIPT), "gallery", str(scenes / "room-000000"), "--out", str(tmp_path / "g.png"),
                             "--degradations", "boom_cli", "--thumb-width", "64"], capture_output=True, text=True, timeout=300, env=env)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    (line,) = [line for line in result.stderr.splitlines() if line.startswith("spacedg: error:")]
    assert "degradation 'boom_cli'" in line and "boom_cli_plugin" in line and "ZeroDivisionError" in line


# ------------------------------------------------------------------ import time
def test_plugin_raising_keyboard_interrupt_is_broken_not_fatal(tmp_path: Path) -> None:
    (tmp_path / "ctrl_c_plugin.py").write_text("raise KeyboardInterrupt\n")
    result = subprocess.run([str(SPACEDG_SCRIPT), "plugins"], capture_output=True, text=True, timeout=120,
                            env=_env(tmp_path, "ctrl_c_plugin"))
    assert result.returncode == 0, result.stderr
    assert "Broken plugins" in result.stdout and "ctrl_c_plugin" in result.stdout and "KeyboardInterrupt" in result.stdout


def test_keyboard_interrupt_raised_by_a_plugin_in_process(clean_env, tmp_path: Path) -> None:
    (tmp_path / "ctrl_c_plugin2.py").write_text("raise KeyboardInterrupt('plugin code')\n")
    clean_env.syspath_prepend(str(tmp_path))
    clean_env.setenv(AUTOLOAD_ENV, "1")
    clean_env.setenv(PLUGINS_ENV, "ctrl_c_plugin2")
    registry = get_registry()
    (broken,) = registry.broken
    assert broken.origin.name == "ctrl_c_plugin2" and broken.error_type == "KeyboardInterrupt"


def test_ctrl_c_during_a_plugin_import_exits_130_naming_it(tmp_path: Path) -> None:
    """A real SIGINT while a (slow) plugin imports: the slow note names it, then one line and exit 130."""
    (tmp_path / "sleepy_plugin.py").write_text("import time\ntime.sleep(60)\n")
    process = subprocess.Popen([str(SPACEDG_SCRIPT), "plugins"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=_env(tmp_path, "sleepy_plugin"), preexec_fn=ctrl_c_reaches_child)
    try:
        first = process.stderr.readline()  # blocks until the slow-import note (after 2 s)
        assert first.startswith("spacedg: warning: importing plugin module 'sleepy_plugin'"), first
        assert "still running" in first and f"{AUTOLOAD_ENV}=1" in first
        process.send_signal(signal.SIGINT)
        _, rest = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, rest
    assert rest.strip() == "spacedg: interrupted while importing plugin module 'sleepy_plugin' from SPACEDG_PLUGINS", rest


def test_ctrl_c_in_process_raises_plugin_import_interrupted(clean_env, ctrl_c_handler, tmp_path: Path) -> None:
    (tmp_path / "sigint_plugin.py").write_text("import os, signal, time\nos.kill(os.getpid(), signal.SIGINT)\ntime.sleep(5)\n")
    clean_env.syspath_prepend(str(tmp_path))
    clean_env.setenv(AUTOLOAD_ENV, "1")
    clean_env.setenv(PLUGINS_ENV, "sigint_plugin")
    with pytest.raises(PluginImportInterrupted, match="interrupted while importing plugin module 'sigint_plugin'"):
        get_registry()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the watch handler is gone again
    reset_registry()


def test_slow_import_is_announced_while_it_runs(clean_env, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from spacedg.commands.plugins import format_text

    (tmp_path / "slowish_plugin.py").write_text(textwrap.dedent(
        """
        import time
        time.sleep(0.6)
        from spacedg.plugins import hookimpl

        @hookimpl
        def spacedg_register_degradations(register):
            pass
        """
    ))
    monkeypatch.setattr(registry_module, "SLOW_IMPORT_SECONDS", 0.2)
    monkeypatch.setattr("spacedg.commands.plugins.SLOW_IMPORT_SECONDS", 0.2)
    clean_env.syspath_prepend(str(tmp_path))
    clean_env.setenv(AUTOLOAD_ENV, "1")
    clean_env.setenv(PLUGINS_ENV, "slowish_plugin")
    started = time.perf_counter()
    with pytest.warns(PluginWarning) as caught:
        registry = get_registry()
    notes = [str(w.message) for w in caught if "slowish_plugin" in str(w.message)]
    assert len(notes) == 1, notes
    assert "has taken over 0.2 s and is still running" in notes[0] and f"{AUTOLOAD_ENV}=1" in notes[0]
    (record,) = [r for r in registry.plugins if r.origin.name == "slowish_plugin"]
    assert 0.6 <= registry.import_seconds(record.origin) <= time.perf_counter() - started
    (line,) = [line for line in format_text(registry).splitlines() if line.startswith("slowish_plugin")]
    assert re.search(r"\(slow import: \d\.\d s\)$", line), line

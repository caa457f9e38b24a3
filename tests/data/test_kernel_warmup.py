"""``spacedg kernels``: the warm-up compiles the signatures the real paths call, so they compile nothing after it."""

from __future__ import annotations

import itertools
import sys

import pytest

from spacedg.cli import main
from spacedg.data.kernel_warmup import GROUPS, warm
from spacedg.data.pipeline import PipelineOptions, degrade_variants
from spacedg.errors import ParameterError
from spacedg.render.threads import serial_kernels


def _spacedg_dispatchers() -> list[object]:
    """Every numba dispatcher of spacedg's loaded modules (the parallel kernels' and their serial twins'
    dispatchers, and the compositor's specialisations)."""
    from numba.core.dispatcher import Dispatcher

    from spacedg.render import raster_cpu
    from spacedg.render.threads import ForkSafeKernel

    found: dict[int, object] = {}
    candidates = list(raster_cpu._COMPOSITE_KERNELS.values())
    for name, module in list(sys.modules.items()):
        if name.startswith("spacedg.") and module is not None:
            candidates.extend(vars(module).values())
    for value in candidates:
        for dispatcher in ((value.parallel, value._serial) if isinstance(value, ForkSafeKernel) else (value,)):
            if isinstance(dispatcher, Dispatcher):
                found[id(dispatcher)] = dispatcher
    return list(found.values())


def _signatures() -> dict[int, set[object]]:
    return {id(d): set(d.overloads) for d in _spacedg_dispatchers()}  # type: ignore[attr-defined]


def test_after_the_warm_up_the_dataset_paths_compile_nothing(small_room, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every kernel signature a dataset item's render and degradations call (the nine at their bench
    presets, clean, a wide defocus, each compositor output; a clean item's serial twins) was compiled (or loaded)
    by the groups: a kernel the
    warm-up calls with other types than the real path would compile again in every process. The render
    group reaches the compositor specialisations the images group leaves it: a change of the render
    paths' outputs would leave one to no group, or give one to both at once."""
    from spacedg.data.chain import BENCH_DEGRADATIONS
    from spacedg.data.kernel_warmup import _RENDERED_OUTPUTS
    from spacedg.render import raster_cpu
    from spacedg.render.composite import composite_view
    from spacedg.render.settings import RasterSettings

    monkeypatch.setattr(raster_cpu, "_COMPOSITE_KERNELS", {})  # what this process's warm-ups reach, alone
    warm("render")
    assert repr(sorted(raster_cpu._COMPOSITE_KERNELS)) == repr(sorted(_RENDERED_OUTPUTS))
    warm("images")
    warm("serial")
    before = _signatures()
    views = list(small_room.views)[:2]
    wide_blur = {"name": "defocus", "params": {"aperture": 12.0, "depth": 0.5}}  # tiles composited every 2 px
    degrade_variants(small_room, views, ["clean", *BENCH_DEGRADATIONS, wide_blur], options=PipelineOptions(image_size=(96, 72), backend="cpu"))
    with serial_kernels():  # a worker forked after its parent rendered: a clean item's serial twins
        degrade_variants(small_room, views, ["clean"], options=PipelineOptions(image_size=(80, 60), backend="cpu"))
    camera = small_room.camera(views[0]).resized(48, 36)
    for flags in itertools.product((False, True), repeat=3):
        outputs = frozenset(name for name, on in zip(("rgb", "depth", "instance_ids"), flags) if on)
        composite_view(small_room.gaussians, camera, outputs, "cpu", None, RasterSettings(), None)
    after = _signatures()
    new = {key: after[key] - before.get(key, set()) for key in after}
    compiled = {
        d.py_func.__qualname__: sorted(map(str, new[id(d)]))  # type: ignore[attr-defined]
        for d in _spacedg_dispatchers() if new.get(id(d))
    }
    assert not compiled, f"signatures the warm-up does not compile: {compiled}"


def test_unknown_group_is_one_clear_error() -> None:
    with pytest.raises(ParameterError, match="unknown group 'nope'; choose from render, images, serial"):
        warm("nope")


def test_cli_runs_every_group_in_processes_of_their_own(capfd: pytest.CaptureFixture[str]) -> None:
    """One group at a time here (``--jobs 1``): each in its own interpreter, then the total."""
    assert main(["kernels", "--jobs", "1"]) == 0
    lines = capfd.readouterr().out.splitlines()
    assert [line.split(" in ")[0] for line in lines] == [f"spacedg kernels: {group}" for group in GROUPS] + [f"spacedg kernels: {len(GROUPS)} groups"]
    assert lines[-1].endswith("(1 at a time)")

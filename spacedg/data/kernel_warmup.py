"""Compile spacedg's CPU kernels into numba's on-disk cache by running them once on tiny inputs.

Why: numba compiles a kernel on its first call in a process that finds no cache entry for it, and
spacedg's are large. Measured alone in one process with an empty cache (``NUMBA_CACHE_DIR``, this
machine): the projection 9–11 s (its block body ~8–9 s, which its serial twin shares: the twin then
takes 0.6 s; 27.4 + 11.2 s before that body was compiled once, outside the parallel loop:
:data:`~spacedg.render.project_cpu.MIN_PROJECT_BLOCK`), each of the compositor's eight output
specialisations 4.1–7.9 s, the sensor 11.1 s, the motion warp 8 s (gather 3.0, doubling 1.8, field 2.5,
source 0.7). On a
fresh install every process that starts before the cache holds them compiles them again, at the
same time: DataLoader workers, the jobs of an array, the two lanes of the test suite (2–3 minutes
of a fresh clone's run, the same kernels in both; ``docs/command-line.md`` has the times). :func:`warm`
runs the kernels of one group (:data:`GROUPS`) through the code paths that use them, at the
signatures those paths call them with, so a later process loads them from the cache;
``spacedg kernels`` runs the groups in parallel processes. Apart from a few small kernels (the
binning, the encoder: about 3 s) the groups compile different kernels (a test holds the render group
to :data:`_RENDERED_OUTPUTS`); the projection's block body, which ``render`` and ``serial`` both call, is
compiled by ``render`` first (``serial`` starts after ``images`` on two cores and loads it; run with
more jobs than cores, both may compile it, ~8 s).

- ``render``: a tiny synthetic room (10k Gaussians, the smallest, at 256 × 192) written and read
  back as a scene folder; its visibility and covisibility; two views clean, defocused and under a long
  shake (the keyframe warp with its doubling passes), at the dataset's outputs: the projection, the
  binning, five of the compositor's specialisations, defocus, warp and keyframe-count kernels.
- ``images``: the compositor's three other specialisations (with ids and colour or depth; on an empty
  projection: the types decide the compiled code, not the data), and every built-in linear-light
  and display degradation at its bench preset on a synthetic 64 × 48 image with its depth (the
  sensor, its exposed signal and the photosites' one-pass kernel, haze, the drops and their summed-area
  table, the encoder).
- ``serial``: the serial twins (:mod:`spacedg.render.threads`) of a clean view's kernels (the
  projection, the compositor's colour output, the sRGB encoder and decoder), which a DataLoader worker
  forked after its parent rendered runs (a user looks at ``dataset[0]``, then iterates a loader):
  without them each such worker compiled them itself, the workers at once (9 s of a test's
  13 s alone on this machine). Then, parallel again, two views defocused widely (the per-tile sampled
  composite) and through the fisheye lens (the lens and its inverse, for the coverage share). On two
  cores it runs after ``images``, beside ``render``, which takes longest: with these two paths in
  ``render`` the other core waited for it (on a fresh cache, 98.4 s against 66.3 + 13.6).

A kernel another signature calls (a test's float64 input) still compiles on its first use, as do
the serial twins of the degradations' kernels (a forked worker asked for a degraded item).
"""

from __future__ import annotations

import contextlib
import itertools
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from spacedg.scene.model import Scene

__all__ = ["GROUPS", "warm"]

#: Side of the images the groups render and degrade (pixels): small, within every size policy.
_WIDTH, _HEIGHT = 64, 48
#: The compositor specialisations (colour, depth, ids) the ``render`` group's paths compile (the views'
#: colour, colour and depth; visibility's ids, covisibility's depth, alpha alone): ``images`` compiles the rest.
_RENDERED_OUTPUTS = {(True, False, False), (True, True, False), (False, False, True), (False, True, False), (False, False, False)}


@contextlib.contextmanager
def _tiny_room(prepare: bool) -> Iterator[tuple[Scene, list[str]]]:
    """A tiny synthetic room (10k Gaussians, the smallest, at 256 × 192) written and read back as a scene
    folder, and two of its views; with ``prepare``, its visibility and covisibility computed too."""
    from spacedg.qa.build import prepare_scene
    from spacedg.scene.io import load_scene, save_scene
    from spacedg.scene.synthetic import CaptureConfig, RoomConfig, generate_room

    with tempfile.TemporaryDirectory(prefix="spacedg-kernels-") as tmp:
        folder = Path(tmp) / "room"
        config = RoomConfig(gaussians=10_000, capture=CaptureConfig(4 * _WIDTH, 4 * _HEIGHT, 3, 3))
        save_scene(generate_room(0, config, scene_id="kernels"), folder)
        scene = load_scene(folder)
        if prepare:
            scene = prepare_scene(scene, folder / "cache", progress=False, backend="cpu")
        yield scene, list(scene.views)[:2]


def _render_group() -> None:
    """The ``render`` group (module docstring)."""
    from spacedg.data.pipeline import PipelineOptions, degrade_variants

    with _tiny_room(prepare=True) as (scene, views):
        # a long shake: paths past the warp's doubling passes (24 px and more)
        shake = {"name": "motion_blur", "params": {"trans": 1.0, "rot": 0.3, "sub_steps": 80}}
        degrade_variants(scene, views, ["clean", "defocus", shake], options=PipelineOptions(backend="cpu"))


#: A wide blur: tiles whose every Gaussian is blurred, composited every 2 px (the bench aperture, scaled to
#: the tiny room's size, leaves none).
_WIDE_DEFOCUS = {"name": "defocus", "params": {"aperture": 12.0, "depth": 0.5}}


def _serial_group() -> None:
    """The ``serial`` group (module docstring)."""
    from spacedg.data.pipeline import PipelineOptions, degrade_variants
    from spacedg.render.threads import serial_kernels

    options = PipelineOptions(backend="cpu")
    with _tiny_room(prepare=False) as (scene, views):
        with serial_kernels():
            degrade_variants(scene, views, ["clean"], options=options)
        # the parallel kernels only these two paths call (by then ``render`` has cached the ones they share with it)
        degrade_variants(scene, views, [_WIDE_DEFOCUS, "distortion"], options=options)


def _images_group() -> None:
    """The ``images`` group (module docstring)."""
    from spacedg.data.chain import BENCH_DEGRADATIONS, Chain
    from spacedg.plugins.specs import Stage
    from spacedg.render import raster_cpu
    from spacedg.render.colour_cpu import encode_srgb_u8
    from spacedg.render.project_cpu import PACKED
    from spacedg.render.settings import RasterSettings

    settings = RasterSettings()
    empty = (np.zeros((0, PACKED), np.float32), np.zeros((0, 4), np.int32), np.zeros(0, np.int32))
    for flags in itertools.product((True, False), repeat=3):
        if flags not in _RENDERED_OUTPUTS:
            raster_cpu.rasterize(*empty, _WIDTH, _HEIGHT, settings.alpha_max, *flags, settings.tight_tiles and settings.opacity_extent)
    # read-only, as the pipeline hands its render to a linear chain (the kernels' wrappers freeze their inputs anyway)
    rgb = np.random.default_rng(0).random((_HEIGHT, _WIDTH, 3), dtype=np.float32)
    aux = {"depth": np.full((_HEIGHT, _WIDTH), 2.5, np.float32), "alpha": np.ones((_HEIGHT, _WIDTH), np.float32)}
    for image in (rgb, *aux.values()):
        image.flags.writeable = False
    aux["far_depth"] = 4.0
    encoded = encode_srgb_u8(rgb)
    for name in BENCH_DEGRADATIONS:
        for step in Chain.parse(name).resolve(0, image_size=(_WIDTH, _HEIGHT)):
            if step.spec.stage is Stage.LINEAR:
                step.spec.apply(rgb, aux, step.params, np.random.default_rng(0))
            elif step.spec.stage is Stage.DISPLAY:
                step.spec.apply(encoded, step.params, np.random.default_rng(0))


#: The groups :func:`warm` runs, by name (module docstring), in the order ``spacedg kernels`` starts them.
GROUPS: dict[str, Callable[[], None]] = {"render": _render_group, "images": _images_group, "serial": _serial_group}


def warm(group: str) -> float:
    """Run the kernels of ``group`` (a key of :data:`GROUPS`) once, compiling into numba's cache what it
    does not hold; returns the seconds it took."""
    if group not in GROUPS:
        from spacedg.errors import ParameterError

        raise ParameterError(f"kernel warm-up: unknown group {group!r}; choose from {', '.join(GROUPS)}")
    t0 = time.perf_counter()
    GROUPS[group]()
    return time.perf_counter() - t0

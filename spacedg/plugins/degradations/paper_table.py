"""The paper's parameter table, encoded (not a plugin: no entry point).

SpaceDG's appendix, Table "Parameter ranges for each degradation setting in SpaceDG-Bench"
(``tab:param_ranges``): the ranges the bench was rendered from. The ``bench`` preset of every
built-in degradation must stay inside these ranges, as written, at the reference scene depth
(:data:`~spacedg.plugins.specs.REFERENCE_DEPTH_M`) and the reference image size
(:data:`~spacedg.plugins.specs.REFERENCE_IMAGE_SIZE`, a 1752 × 1168 ScanNet++ DSLR frame),
where scale-aware ranges resolve to their written values. Parameters the table does not name
(haze's airlight, the sensor's constants, …) are this project's documented choices.
:func:`outside_paper_table` lists any preset range that leaves it (tested on every built-in).
"""

from __future__ import annotations

from collections.abc import Mapping

from spacedg.plugins.specs import DegradationSpec

__all__ = ["PAPER_PARAMETER_TABLE", "outside_paper_table"]

#: degradation → parameter → ``(low, high)`` (a fixed value ``v`` is ``(v, v)``), as printed.
PAPER_PARAMETER_TABLE: Mapping[str, Mapping[str, tuple[float, float]]] = {
    "defocus": {"aperture": (10.0, 15.0), "depth": (1.0, 8.0)},
    "distortion": {"k1": (-0.24, -0.23), "k2": (0.0001, 0.0003), "k3": (0.0001, 0.0002), "k4": (0.0, 0.0001), "max_theta": (1.5, 1.5)},
    "haze": {"density": (3.5, 6.0)},
    "jpeg_compression": {"quality": (2.0, 5.0)},
    "low_light": {"exposure": (0.003, 0.005)},
    "low_res": {"scale": (0.02, 0.05)},
    "motion_blur": {"trans": (0.2, 0.35), "rot": (0.06, 0.12), "sub_steps": (80.0, 80.0)},
    "over_exposure": {"exposure": (7.0, 10.0)},
    "water_droplets": {"scale": (2.5, 4.0), "radius": (0.25, 0.75), "strength": (0.3, 0.5), "blur_sigma": (2.0, 2.5), "blur_kernel": (9.0, 9.0)},
}


def outside_paper_table(spec: DegradationSpec, preset: str = "bench") -> list[str]:
    """What of ``spec``'s ``preset`` leaves the paper's table: one line per parameter of the
    table whose range is missing or not inside the paper's (an empty list = inside)."""
    table = PAPER_PARAMETER_TABLE.get(spec.name, {})
    ranges = spec.presets.get(preset, {})
    problems = []
    for param, (low, high) in table.items():
        span = ranges.get(param)
        if span is None:
            problems.append(f"{spec.name}.{param}: the preset {preset!r} has no such parameter (the paper's range is [{low:g}, {high:g}])")
        elif not low <= span.low <= span.high <= high:
            problems.append(f"{spec.name}.{param}: {preset!r} gives [{span.low:g}, {span.high:g}], outside the paper's [{low:g}, {high:g}]")
    return problems

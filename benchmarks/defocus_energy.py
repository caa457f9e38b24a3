"""Does defocus keep a view's light? Mean linear radiance and alpha coverage against the sharp render.

Two scenes, apertures from the bench range up to the hard limit (1000 px):

- **wall**: an opaque, uniformly coloured plane of splats far wider than the blurred footprint
  (so light enters the frame from outside as much as leaves it), fronto-parallel at 3 m,
  focus 1.5 m (r = aperture / 2 px); compared over the whole frame;
- **room**: built-in room 0 at 640×480, three views, focus 1.5 / 3 / 5 m, apertures up to 50 px
  (wider blurs fill a 640×480 frame with light from the whole room and take minutes); compared
  over the frame without a 48 px border.

For each aperture it prints ``radiance ratio / coverage ratio`` (blurred ÷ sharp) and the render
time. Runs on any revision that has ``spacedg.render`` and ``spacedg.Defocus`` (the numbers in
the closing notes of issue 20 compare the revision before the two-pass model with the one after):

    .venv/bin/python benchmarks/defocus_energy.py [--backend cpu|torch] [--quick]
"""

from __future__ import annotations

import argparse
import time
import sys
from pathlib import Path

import numpy as np

import spacedg
from spacedg.render import Camera, Defocus, Gaussians, render

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.render_helpers import uniform_wall  # noqa: E402 - the wall the energy tests use

APERTURES = (2.0, 5.0, 10.0, 15.0, 50.0, 200.0, 1000.0)


def ratios(gaussians: Gaussians, camera: Camera, defocus: Defocus, backend: str, margin: int) -> tuple[float, float, float]:
    sharp = render(gaussians, camera, backend=backend)
    start = time.perf_counter()
    blurred = render(gaussians, camera, defocus=defocus, backend=backend)
    seconds = time.perf_counter() - start
    crop = (slice(margin, camera.height - margin), slice(margin, camera.width - margin))
    return (float(blurred.rgb[crop].mean() / sharp.rgb[crop].mean()),
            float(blurred.alpha[crop].mean() / sharp.alpha[crop].mean()), seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--backend", default="cpu", choices=("cpu", "torch"))
    parser.add_argument("--quick", action="store_true", help="apertures up to 200 px only")
    args = parser.parse_args()
    apertures = [a for a in APERTURES if not args.quick or a <= 200]
    print(f"backend {args.backend}; cells: radiance ratio / coverage ratio (blurred ÷ sharp), render seconds")
    camera = Camera(40.0, 40.0, 32.0, 24.0, 64, 48, np.eye(4))
    for aperture in apertures:
        r = aperture / 2.0
        g = uniform_wall(32.0 + 2.6 * r + 16.0)
        rad, cov, sec = ratios(g, camera, Defocus(aperture, 1.5), args.backend, 0)
        print(f"wall  aperture {aperture:6.0f} px (r {r:5.0f} px, {len(g):7,} splats): {rad:.3f} / {cov:.3f}  {sec:6.2f} s", flush=True)
    room = spacedg.generate_room(seed=0)
    names = sorted(room.views)
    for view in (names[len(names) // 5], names[len(names) // 2], names[4 * len(names) // 5]):
        cam = room.views[view]
        for focus in (1.5, 3.0, 5.0):
            cells = []
            for aperture in (a for a in apertures if a <= 50):
                rad, cov, sec = ratios(room.gaussians, cam, Defocus(aperture, focus), args.backend, 48)
                cells.append(f"{aperture:.0f}: {rad:.3f}/{cov:.3f} ({sec:.1f}s)")
            print(f"room {view} focus {focus} m  " + "  ".join(cells), flush=True)


if __name__ == "__main__":
    main()

"""The device-path tables of ``benchmarks/render.py --device`` and ``benchmarks/dataset.py --device``.

Not a script: imported by those two (run from the repository root, ``benchmarks/`` is on the path).

Render table (640×480, pinhole, no degradation, the same random Gaussians and camera for every
column; SH degree 1):

- ``ours gsplat``: ``render(backend="gsplat", device=D)`` — our projection, gsplat's tile
  intersection and compositor (on CUDA its kernels; elsewhere its torch stand-ins), rgb + alpha,
  copied to the host as a :class:`~spacedg.render.Frame` (the copy is in the time);
- ``gsplat own``: ``gsplat.rasterization()`` on the same Gaussians and camera (its own projection,
  SH evaluation and compositor, classic mode, 0.01 m near plane), output left on the device
  (CUDA only: it has no CPU path);
- ``ours torch``: ``render(backend="torch", device=D)``;
- ``ours cpu``: the compiled numba path (``backend="cpu"``).

Times are medians of ``runs`` after one warm-up, ``torch.cuda.synchronize()`` around every timed
call on CUDA. The ratio column is ``ours gsplat / gsplat own`` (goal on an H100: ≤ 1.2). The
error columns compare our gsplat backend with our CPU path (linear rgb, max and mean |Δ|) and
with gsplat's own render (sRGB-encoded rgb, mean |Δ|; the two differ by design: alpha cap 0.99
vs 0.999, opacity-aware footprints).
"""

from __future__ import annotations

import math
import time
from typing import Any, Callable

import numpy as np

WIDTH, HEIGHT, FOCAL = 640, 480, 500.0


def print_table_head(*lines: str, columns: str) -> None:
    """Print a benchmark table's explanation ``lines``, its ``columns`` header and a rule of its width."""
    for line in lines:
        print(line)
    print(columns)
    print("-" * len(columns))


def device_ready(device: str) -> bool:
    """False (with a clear message) when ``device`` is a CUDA device and there is none."""
    import torch

    dev = torch.device(device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        built = torch.version.cuda or "none (CPU-only build)"
        print(f"no CUDA device: torch.cuda.is_available() is False (torch {torch.__version__}, CUDA build {built}); "
              "nothing measured. Run with --device cpu to exercise the same code paths on the CPU "
              "(gsplat's CUDA calls replaced by their torch stand-ins; slow, not a GPU number).")
        return False
    return True


def device_line(device: str) -> str:
    import torch

    from spacedg.render.gsplat_backend import gsplat_cuda_available

    dev = torch.device(device)
    name = torch.cuda.get_device_name(dev) if dev.type == "cuda" else "CPU"
    return (f"device {device}: {name}; torch {torch.__version__}; gsplat CUDA extension "
            f"{'loaded' if gsplat_cuda_available() else 'not available (torch stand-ins)'}")


def _sync(device: str) -> None:
    import torch

    if torch.device(device).type == "cuda":
        torch.cuda.synchronize()


def timed(fn: Callable[[], Any], device: str, runs: int) -> tuple[float, Any]:
    """Median seconds of ``runs`` calls after one warm-up, and the last result."""
    out = fn()
    times = []
    for _ in range(runs):
        _sync(device)
        start = time.perf_counter()
        out = fn()
        _sync(device)
        times.append(time.perf_counter() - start)
    return float(np.median(times)), out


def random_scene(n: int, seed: int, degree: int = 1):  # type: ignore[no-untyped-def]
    """``n`` Gaussians 2–6 m in front of an identity camera, filling its 640×480 view."""
    from spacedg.render.camera import Camera
    from spacedg.render.gaussians import Gaussians

    rng = np.random.default_rng(seed)
    half_w, half_h = 4.0 * (WIDTH / 2) / FOCAL, 4.0 * (HEIGHT / 2) / FOCAL
    means = np.column_stack([rng.uniform(-half_w, half_w, n), rng.uniform(-half_h, half_h, n), rng.uniform(2.0, 6.0, n)])
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    scales = np.exp(rng.uniform(math.log(0.005), math.log(0.05), (n, 3)))
    opacities = rng.uniform(0.05, 1.0, n)
    sh = rng.normal(0.0, 0.3, (n, (degree + 1) ** 2, 3))
    camera = Camera(FOCAL, FOCAL, WIDTH / 2, HEIGHT / 2, WIDTH, HEIGHT, np.eye(4))
    return Gaussians(means, quats, scales, opacities, sh), camera


def gsplat_own(gaussians, camera, device: str) -> Callable[[], Any]:  # type: ignore[no-untyped-def]
    """A closure rendering with ``gsplat.rasterization`` (tensors moved to the device once)."""
    import torch
    from gsplat import rasterization

    dev = torch.device(device)

    def put(a: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).to(dev)

    means, quats, scales, opac, sh = (put(a) for a in (gaussians.means, gaussians.quats, gaussians.scales, gaussians.opacities, gaussians.sh))
    viewmat = put(camera.world_to_cam)[None]
    ks = put(np.array([[camera.fx, 0, camera.cx], [0, camera.fy, camera.cy], [0, 0, 1]]))[None]
    degree = int(round(math.sqrt(sh.shape[1]))) - 1

    def run() -> Any:
        with torch.no_grad():
            colors, alphas, _ = rasterization(means, quats, scales, opac, sh, viewmat, ks, camera.width, camera.height,
                                              sh_degree=degree, near_plane=0.01, packed=False)
        return colors[0], alphas[0]

    return run


def attempt(measure: Callable[[], tuple[float, Any]], width: int) -> str:
    """``measure()``'s milliseconds right-aligned in ``width``, or the failure's type (out of memory on a
    large scene, say: one column fails, the table goes on; the error is printed below the row)."""
    try:
        return f"{measure()[0] * 1e3:>{width}.1f}"
    except Exception as err:  # noqa: BLE001 - any failure of one column is reported, not fatal
        print(f"   ({type(err).__name__}: {str(err).splitlines()[0][:200] if str(err) else ''})", flush=True)
        return f"{type(err).__name__[:width]:>{width}}"


def render_table(device: str, sizes: list[int], runs: int) -> None:
    """The side-by-side render table (module docstring)."""
    import torch

    from spacedg.render import render
    from spacedg.render.colour import linear_to_srgb

    on_cuda = torch.device(device).type == "cuda"
    print(f"\nDevice path, {WIDTH}x{HEIGHT} pinhole, no degradation; {device_line(device)}")
    print(f"   ms per frame, median of {runs} after 1 warm-up; ratio = ours gsplat / gsplat own (goal on an H100: <= 1.2)")
    print("   |Δ| cpu: ours gsplat vs our compiled CPU path, linear rgb (max / mean); |Δ| own: vs gsplat.rasterization, "
          "encoded rgb (mean)")
    print_table_head(
        columns=(f"{'scene':<14} {'visible':>8} {'ours gsplat':>11} {'gsplat own':>10} {'ratio':>6} {'ours torch':>10} "
                 f"{'ours cpu':>9} {'|Δ| cpu max':>11} {'|Δ| cpu mean':>12} {'|Δ| own':>8}"),
    )
    for n in sizes:
        g, cam = random_scene(n, seed=n)
        t_ours, f_ours = timed(lambda: render(g, cam, outputs="rgb,alpha", backend="gsplat", device=device), device, runs)
        if on_cuda:
            t_own, (own_rgb, _) = timed(gsplat_own(g, cam, device), device, runs)
            own_s, ratio = f"{t_own * 1e3:10.1f}", f"{t_ours / t_own:6.2f}"
            d_own = f"{np.abs(np.clip(linear_to_srgb(f_ours.rgb.astype(np.float64)), 0, None) - own_rgb.cpu().numpy()).mean():8.1e}"
        else:
            own_s, ratio, d_own = f"{'n/a':>10}", f"{'-':>6}", f"{'-':>8}"
        torch_runs = runs if on_cuda else 1
        torch_s = attempt(lambda: timed(lambda: render(g, cam, outputs="rgb,alpha", backend="torch", device=device), device, torch_runs), 10)
        t_cpu, f_cpu = timed(lambda: render(g, cam, outputs="rgb,alpha", backend="cpu"), "cpu", runs)
        diff = np.abs(f_ours.rgb.astype(np.float64) - f_cpu.rgb)
        print(f"{f'random {n // 1000}k':<14} {int(f_ours.stats['visible']):>8} {t_ours * 1e3:>11.1f} {own_s} {ratio} "
              f"{torch_s} {t_cpu * 1e3:>9.1f} {diff.max():>11.2e} {diff.mean():>12.2e} {d_own}", flush=True)
    if not on_cuda:
        print("   (gsplat own: n/a, gsplat.rasterization needs CUDA; ours gsplat ran gsplat's torch stand-ins: not a GPU number)")


def bench_question_table(dataset_factory: Callable[..., Any], device: str, questions: int) -> None:
    """ms per bench question (clean + the nine degradations = 10 items, rendered in this process)
    on ``device`` and on the CPU path, with the share of render / linear / encode / display."""
    from spacedg.render.renderer import resolve_backend

    print(f"\nBench items per question (clean + nine degradations), rendered in this process; {device_line(device)}; "
          f"renders: backend auto -> {resolve_backend('auto', device)[0]} on {device}, degradations as torch tensors there")
    print("   ms per question = sum over its 10 items of dataset[i] (median over questions after 1 warm-up question); "
          "goal on an H100: <= 30 ms")
    print_table_head(
        columns=f"{'path':<28} {'ms / question':>13} {'render %':>8} {'linear %':>8} {'encode %':>8} {'display %':>9}",
    )
    for label, kwargs in ((f"device {device}", {"device": device}), ("cpu (compiled + numpy)", {})):
        ds = dataset_factory(**kwargs)
        per_item = len(ds.chains) + 1
        count = min(questions + 1, len(ds) // per_item)
        totals, shares = [], np.zeros(4)
        for q in range(count):
            _sync(device)
            start = time.perf_counter()
            items = [ds[q * per_item + k] for k in range(per_item)]
            _sync(device)
            if q == 0:
                continue  # warm-up: kernels, scene load
            totals.append(time.perf_counter() - start)
            for item in items:
                s = item["stats"]
                shares += [s.get("render_ms", 0.0), s.get("linear_ms", 0.0), s.get("encode_ms", 0.0), s.get("display_ms", 0.0)]
        if not totals:
            print(f"{label:<28} (not enough bench questions)")
            continue
        pct = 100 * shares / max(shares.sum(), 1e-9)
        print(f"{label:<28} {np.median(totals) * 1e3:>13.1f} {pct[0]:>8.0f} {pct[1]:>8.0f} {pct[2]:>8.0f} {pct[3]:>9.0f}", flush=True)

"""Build gsplat 1.5.3's CUDA extension ahead, for a lent GPU machine (torch 2.11.0 / CUDA 13.0, sm_90).

Run with a Python 3.12 whose torch is the device's (``torch==2.11.0`` from PyPI is the CUDA 13.0
build, the same as the device's ``2.11.0+cu130``), gsplat's sources importable (its PyPI wheel),
``nvcc`` 13.0 and ninja on the PATH; no GPU needed::

    TORCH_CUDA_ARCH_LIST=9.0 MAX_JOBS=2 python benchmarks/gpu_build_gsplat.py OUT_DIR

It compiles what gsplat's own JIT loader (``gsplat/cuda/_backend.py``) compiles, with its flags
(``-O3``, ``-use_fast_math``, gsplat's include dirs and glm), but as the module ``csrc``: gsplat's
loader imports ``gsplat.csrc`` first and only JIT-compiles when that import fails. The result is
``OUT_DIR/csrc.so``; ``benchmarks/gpu_check.sh`` copies it into the installed gsplat package.
"""

from __future__ import annotations

import glob
import os
import sys
import time
from pathlib import Path


def main() -> None:
    out = Path(sys.argv[1]).resolve()
    out.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("TORCH_CUDA_ARCH_LIST", "9.0")
    import gsplat  # noqa: F401 - its sources; its _backend is not imported (no JIT here)
    from torch.utils.cpp_extension import load

    root = Path(gsplat.__file__).parent / "cuda"
    sources = sorted(glob.glob(str(root / "csrc" / "*.cu"))) + sorted(glob.glob(str(root / "csrc" / "*.cpp")))
    sources.append(str(root / "ext.cpp"))
    includes = [str(root / "include"), str(root / "csrc" / "third_party" / "glm")]
    start = time.perf_counter()
    load("csrc", sources, extra_cflags=["-O3", "-Wno-attributes"], extra_cuda_cflags=["-O3", "-use_fast_math"],
         extra_include_paths=includes, build_directory=str(out), verbose=True, is_python_module=False)
    print(f"built {out / 'csrc.so'} in {time.perf_counter() - start:.0f} s ({len(sources)} sources, "
          f"arch {os.environ['TORCH_CUDA_ARCH_LIST']})")


if __name__ == "__main__":
    main()

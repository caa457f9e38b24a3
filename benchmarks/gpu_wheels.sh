#!/usr/bin/env bash
# The Python 3.12 wheels that a lent GPU machine lacks for spacedg's CUDA paths, into ./.whl/
# (git-ignored through .git/info/exclude; carried to the machine by the device tool's `carry`).
#
#     bash benchmarks/gpu_wheels.sh              # from the repository root, on a machine with network
#     bash benchmarks/gpu_wheels.sh --csrc PATH  # also copy a prebuilt gsplat extension (see below)
#
# The lent machine's image (Python 3.12 at /opt/torch/.venv, torch 2.11.0+cu130) already holds
# torch, numpy, numba, pluggy, transformers, accelerate, peft, opencv-python-headless, pillow,
# matplotlib, tqdm, scipy, pytest, hypothesis, ninja, rich, jaxtyping and nvcc 13.0. What the CUDA
# paths import on top of that (pyproject.toml's dependencies, traced through the code they run):
#
#   kornia, kornia_rs                 spacedg.plugins.degradations.device (resize, JPEG on the GPU)
#   hydra-core, omegaconf, antlr4     spacedg.sft (the FSDP launch) and tests/sft
#   gsplat (1.5.3, pinned in [test])  backend="gsplat" and benchmarks/render.py's gsplat column
#   transformers 5.24.0               the image has 5.17, whose processor apply_chat_template refuses
#                                     images in processor_kwargs (spacedg.vlm.encode_chats) and computes
#                                     assistant masks off by the left padding (fixed in 5.24): the SFT
#                                     steps need the version this repository is tested with
#
# Not carried: pycolmap (COLMAP import only), openpyxl (eval .xlsx only), plyfile / playwright /
# import-linter (tests not run there). antlr4-python3-runtime 4.9.3 is published as a source
# archive only: it is built here into a pure-Python wheel.
#
# gsplat's PyPI wheel compiles its CUDA extension at first import (ninja + nvcc, minutes). A
# prebuilt extension (`--csrc PATH`, made by benchmarks/gpu_build_gsplat.py against torch 2.11.0 /
# CUDA 13.0 for sm_90) is copied to .whl/gsplat_csrc_sm90.so; benchmarks/gpu_check.sh installs it
# as gsplat/csrc.so and falls back to the JIT build when it does not import.
set -euo pipefail

PY=${PY:-python3}
DEST=${DEST:-.whl}
CSRC=""
if [ "${1:-}" = "--csrc" ]; then CSRC=$2; fi

# name==version, one line each; versions are the ones this repository's .venv runs (Python 3.11 here)
BINARY=(
  "kornia==0.9.0"
  "kornia_rs==0.2.0"
  "hydra-core==1.3.8"
  "omegaconf==2.3.1"
  "gsplat==1.5.3"
  "transformers==5.24.0"
)
SOURCE_ONLY=(
  "antlr4-python3-runtime==4.9.3"
)

mkdir -p "$DEST"
PLATFORMS=()
for p in manylinux_2_28_x86_64 manylinux_2_27_x86_64 manylinux_2_17_x86_64 manylinux2014_x86_64 manylinux1_x86_64; do
  PLATFORMS+=(--platform "$p")
done
"$PY" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  "${PLATFORMS[@]}" -d "$DEST" "${BINARY[@]}"
for spec in "${SOURCE_ONLY[@]}"; do
  name=${spec%%==*}
  if ! ls "$DEST"/"${name//-/_}"-*.whl >/dev/null 2>&1; then
    "$PY" -m pip wheel -q --no-deps -w "$DEST" "$spec"
  fi
done
if [ -n "$CSRC" ]; then
  cp "$CSRC" "$DEST/gsplat_csrc_sm90.so"
fi
echo "wheels in $DEST:"
ls -l "$DEST"
du -sh "$DEST"

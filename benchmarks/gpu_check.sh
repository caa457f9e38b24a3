#!/usr/bin/env bash
# Every CUDA-only path of spacedg once, on a lent GPU machine, in one bounded run (issue 32).
#
#     bash benchmarks/gpu_check.sh              # on the GPU machine, from the repository root
#     bash benchmarks/gpu_check.sh --dry-run    # here, on a CPU: the same steps with --device cpu
#
# Before: `bash benchmarks/gpu_wheels.sh` here fills .whl/ (git-ignored), which the device tool
# carries (`carry: [".whl"]`). This script installs those wheels into $SITE (/tmp/site), writes
# spacedg's dist-info there (benchmarks/gpu_dist_info.py: the built-in plugins' entry points; the
# code runs from the checkout, PYTHONPATH=$SITE:$REPO), and on the GPU gsplat's CUDA extension:
# the prebuilt .whl/gsplat_csrc_sm90.so when it imports, else gsplat's own JIT build (ninja + nvcc,
# sm_90, MAX_JOBS=16; timed).
#
# Then the steps, each independent (one failing does not stop the others), each under `timeout`,
# all under one deadline (BUDGET_S, default 400 s; a step that would start with under 20 s left is
# skipped). Logs: $OUT/gpu_check.log (all output), $OUT/logs.tgz (one log per step),
# $OUT/summary.txt (the table printed at the end, with the README GPU table's numbers).
# ONLY="fsdp export" runs those steps alone (with setup, gsplat_ext and rooms, which they need).
#
#   setup        versions, nvidia-smi, wheels, spacedg, gsplat extension
#   render       benchmarks/render.py --device cuda: ours (gsplat) vs gsplat.rasterization vs ours torch vs CPU, 100k and 1M
#   rooms        four 30k-Gaussian rooms, 24-32 views each (benchmarks/gpu_rooms.py; dataset.py --small reads them)
#   qa_build     spacedg qa build ROOMS --device cuda
#   dataset      benchmarks/dataset.py --device cuda --small --size 640x480: ms per bench question (clean + nine)
#   test_render  pytest tests/render/test_cuda.py (gsplat kernels and torch backend on CUDA vs the compiled path)
#   test_degrade pytest tests/plugins/degradations/test_device_cuda.py (device-vs-CPU tolerances on CUDA tensors)
#   fsdp         torchrun --nproc_per_node 1 -m spacedg.sft +experiment=tiny train=fsdp, 2 steps (NCCL)
#   export       spacedg export --split bench --device cuda
#   defer        SpaceDGDataset(device="cuda", defer_render=True): 2 DataLoader workers plan, this process renders
#   sft_render   python -m spacedg.sft +experiment=tiny data.render_device=cuda, 2 steps
set -u

DRY=0
if [ "${1:-}" = "--dry-run" ]; then DRY=1; fi
REPO=$(pwd)
PY=${PY:-python3}
OUT=${OUT:-$REPO/runs/gpu-check/out}
WORK=${WORK:-/tmp/spacedg-gpu-check}
BUDGET_S=${BUDGET_S:-400}
SITE=${SITE:-/tmp/site}   # the carried wheels and spacedg's dist-info (PYTHONPATH)
mkdir -p "$OUT" "$WORK/logs"
rm -f "$WORK"/logs/*.log
LOG=$OUT/gpu_check.log
SUMMARY=$OUT/summary.txt
: > "$LOG"
: > "$WORK/steps.tsv"
START=$(date +%s)

if [ $DRY = 1 ]; then
  DEV=cpu; SIZES=10000; RUNS=1; QUESTIONS=1; BENCH_SIZE=160x120
else
  DEV=cuda; SIZES=100000,1000000; RUNS=5; QUESTIONS=8; BENCH_SIZE=640x480
fi
ROOMS=$WORK/bench/small   # benchmarks/dataset.py --small --root $WORK/bench reads these
export PYTHONUNBUFFERED=1 TOKENIZERS_PARALLELISM=false HF_HUB_OFFLINE=1 TRANSFORMERS_OFFLINE=1
export SPACEDG_HOME=$WORK/home TORCH_CUDA_ARCH_LIST=${TORCH_CUDA_ARCH_LIST:-9.0} MAX_JOBS=${MAX_JOBS:-16}

say() { echo "$@" | tee -a "$LOG"; }
left() { echo $(( BUDGET_S - ($(date +%s) - START) )); }

# step NAME CAP_S 'shell command': run it under timeout (CAP_S, or what is left of the budget),
# its output to $WORK/logs/NAME.log and the main log; the last TAIL lines shown.
TAIL=${TAIL:-12}
step() {
  local name=$1 cap=$2 cmd=$3 rest t0 rc secs limit
  case " setup gsplat_ext rooms ${ONLY:-$name} " in
    *" $name "*) ;;
    *) say "=== $name: not in ONLY"; return ;;
  esac
  rest=$(left)
  limit=$(( cap < rest - 5 ? cap : rest - 5 ))
  if [ "$limit" -lt 20 ]; then
    say "=== $name: SKIPPED (${rest} s of the budget left)"
    printf '%s\tskipped\t-\t0\t%s\n' "$name" "$cap" >> "$WORK/steps.tsv"
    return
  fi
  say "=== $name (timeout ${limit} s): ${SHOW:-$cmd}"
  t0=$(date +%s)
  timeout -k 10 "$limit" bash -c "$cmd" > "$WORK/logs/$name.log" 2>&1
  rc=$?
  secs=$(( $(date +%s) - t0 ))
  cat "$WORK/logs/$name.log" >> "$LOG"
  tail -n "$TAIL" "$WORK/logs/$name.log"
  local status=ok
  if [ $rc = 124 ] || [ $rc = 137 ]; then status=TIMEOUT; elif [ $rc != 0 ]; then status=FAILED; fi
  say "=== $name: $status (rc $rc, ${secs} s)"
  printf '%s\t%s\t%s\t%s\t%s\n' "$name" "$status" "$rc" "$secs" "$limit" >> "$WORK/steps.tsv"
}

# ------------------------------------------------------------------ setup
setup() {
  set -e
  if [ "$DRY" = 0 ]; then nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.max.sm --format=csv; fi
  "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" .whl/*.whl
  # spacedg runs from the checkout (PYTHONPATH); its dist-info registers the built-in plugins' entry points
  "$PY" benchmarks/gpu_dist_info.py "$SITE"
  "$PY" - <<'EOF'
import importlib, platform, sys
import torch
print(f"python {platform.python_version()} ({sys.executable}), torch {torch.__version__}, CUDA build {torch.version.cuda}, "
      f"cuda available {torch.cuda.is_available()}"
      + (f", {torch.cuda.get_device_name(0)}, {torch.cuda.get_device_properties(0).total_memory / 2**30:.0f} GiB" if torch.cuda.is_available() else ""))
for name in ("numpy", "numba", "gsplat", "kornia", "transformers", "accelerate", "peft", "hydra", "omegaconf", "cv2", "pluggy", "spacedg"):
    try:
        module = importlib.import_module(name)
        print(f"  {name} {getattr(module, '__version__', '?')} ({module.__file__})")
    except Exception as err:  # noqa: BLE001
        print(f"  {name}: NOT IMPORTABLE ({type(err).__name__}: {err})")
from spacedg.plugins.registry import get_registry
registry = get_registry()
print(f"  spacedg plugins: {len(registry.degradation_names())} degradations, {len(registry.question_family_names())} families; "
      f"broken: {[b.to_dict() for b in registry.broken]}")
EOF
  nvcc --version | tail -1 || true
}

gsplat_ext() {
  set -e
  if [ -f .whl/gsplat_csrc_sm90.so ]; then
    cp .whl/gsplat_csrc_sm90.so "$SITE/gsplat/csrc.so"
    if "$PY" -c "from gsplat import csrc; print('prebuilt gsplat extension imports:', csrc.__file__)"; then
      :
    else
      echo "prebuilt gsplat extension does not import: removed, JIT-compiling instead"
      rm -f "$SITE/gsplat/csrc.so"
    fi
  fi
  "$PY" - <<'EOF'
import time
t0 = time.perf_counter()
from gsplat.cuda._backend import _C
print(f"gsplat extension: {_C!r}; ready in {time.perf_counter() - t0:.1f} s (JIT compile when not prebuilt; "
      "TORCH_CUDA_ARCH_LIST and MAX_JOBS from the environment)")
assert _C is not None, "gsplat's CUDA extension did not load"
from spacedg.render.gsplat_backend import gsplat_cuda_available
assert gsplat_cuda_available(), "spacedg does not see gsplat's CUDA extension"
EOF
}

# ------------------------------------------------------------------ the steps
RENDER_CMD="$PY benchmarks/render.py --device $DEV --sizes $SIZES --runs $RUNS"
ROOMS_CMD="$PY benchmarks/gpu_rooms.py $ROOMS ${ROOM_GAUSSIANS:-30000}"
QA_CMD="$PY -m spacedg qa build $ROOMS --device $DEV"
DATASET_CMD="$PY benchmarks/dataset.py --device $DEV --small --root $WORK/bench --per-sub-type 25 --size $BENCH_SIZE --questions $QUESTIONS"
TEST_RENDER_CMD="$PY -m pytest -q -p no:cacheprovider tests/render/test_cuda.py"
TEST_DEGRADE_CMD="$PY -m pytest -q -s -p no:cacheprovider tests/plugins/degradations/test_device_cuda.py"
SFT_FAST="train.max_steps=2 train.save_steps=2 train.eval_steps=2 data.val.samples=2 data.max_questions=16"
FSDP_CMD="$PY -m torch.distributed.run --nproc_per_node 1 --master_port 29517 -m spacedg.sft +experiment=tiny train=fsdp 'data.scenes=[$ROOMS]' output_dir=$WORK/sft-fsdp hydra.run.dir=$WORK/sft-fsdp/hydra $SFT_FAST && $PY -c \"import json; s = json.load(open('$WORK/sft-fsdp/train_summary.json')); print('fsdp summary:', {k: s.get(k) for k in ('global_step', 'losses', 'distributed')})\""
EXPORT_CMD="$PY -m spacedg export --split bench --scenes $ROOMS --out $WORK/bench-export --image-size 320x240 --max-questions 12 --device $DEV && head -c 1500 $WORK/bench-export/summary.json; echo"
DEFER_CMD="$PY benchmarks/gpu_defer.py $ROOMS $DEV"
SFT_RENDER_CMD="$PY -m spacedg.sft +experiment=tiny 'data.scenes=[$ROOMS]' data.render_device=$DEV output_dir=$WORK/sft-render hydra.run.dir=$WORK/sft-render/hydra $SFT_FAST"

say "spacedg GPU check: $(date -u +%FT%TZ), device $DEV, budget ${BUDGET_S} s, repo $REPO ($(git rev-parse --short HEAD 2>/dev/null || echo '?'))"
export DRY PY SITE PYTHONPATH=$SITE:$REPO${PYTHONPATH:+:$PYTHONPATH}
SHOW="install .whl into $SITE, spacedg's dist-info, versions" TAIL=40 step setup 120 "$(declare -f setup); setup"
if [ $DRY = 0 ]; then
  SHOW="prebuilt .whl/gsplat_csrc_sm90.so, else gsplat's JIT build" TAIL=6 step gsplat_ext 300 "$(declare -f gsplat_ext); gsplat_ext"
fi
TAIL=14 step render 150 "$RENDER_CMD"
TAIL=3 step rooms 90 "$ROOMS_CMD"
TAIL=6 step qa_build 120 "$QA_CMD"
TAIL=10 step dataset 150 "$DATASET_CMD"
TAIL=14 step test_render 150 "$TEST_RENDER_CMD"
TAIL=22 step test_degrade 150 "$TEST_DEGRADE_CMD"
TAIL=8 step fsdp 150 "$FSDP_CMD"
TAIL=6 step export 90 "$EXPORT_CMD"
TAIL=8 step defer 90 "$DEFER_CMD"
TAIL=6 step sft_render 90 "$SFT_RENDER_CMD"

# ------------------------------------------------------------------ summary
(cd "$WORK/logs" && tar czf "$OUT/logs.tgz" ./*.log)
"$PY" benchmarks/gpu_summary.py "$WORK/steps.tsv" "$WORK/logs" "$(( $(date +%s) - START ))" | tee "$SUMMARY" | tee -a "$LOG"

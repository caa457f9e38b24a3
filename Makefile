# Two entry points, both self-installing on a fresh machine (see README):
#   make demo   set up, then build the built-in synthetic scenes, export a small bench and its gallery,
#               answer it with a tiny VLM and write the evaluation report
#   make test   set up, then run the test suite (what CI runs through .ci/run)
PYTHON ?= python3
VENV ?= .venv
# torch goes in first and pinned: on a CPU-only machine a loose torch requirement
# would pull several GB of CUDA wheels. Override for a CUDA box, e.g.
#   make demo TORCH_SPEC="torch==2.13.0 --index-url https://download.pytorch.org/whl/cu128"
TORCH_SPEC ?= torch==2.13.0
BIN := $(VENV)/bin
# bytecode caches written even where the environment says not to (PYTHONDONTWRITEBYTECODE): the
# packages are installed without them (--no-compile), so every process would compile torch again
PYCACHE_ON := PYTHONDONTWRITEBYTECODE=
STAMP := $(VENV)/.spacedg-installed
DEMO_DIR ?= runs/demo
# the browser the review page's end-to-end tests drive (Debian's package; playwright's own
# browser downloads are not used)
CHROMIUM ?= /usr/bin/chromium

.PHONY: setup demo test clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	@# --no-compile: pip would byte-compile every file of every package (about a minute, torch's
	@# thousands of modules most of it); the modules spacedg imports are compiled once, below
	$(BIN)/python -c "import torch" 2>/dev/null || $(BIN)/python -m pip install --quiet --no-compile $(TORCH_SPEC)
	$(BIN)/python -m pip install --quiet --no-compile -e '.[test]'
	$(PYCACHE_ON) $(BIN)/python -c "import spacedg.cli, spacedg.sft.app, spacedg.data.dataset, spacedg.eval.predict, spacedg.render.renderer"
	@# the browser tests (tests/review/test_browser.py) drive Debian's chromium through playwright
	@command -v $(CHROMIUM) >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ]; then SUDO=; elif command -v sudo >/dev/null 2>&1; then SUDO="sudo -n"; else SUDO=none; fi; \
	  if [ "$$SUDO" != none ] && $$SUDO apt-get update -qq && \
	     $$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; then \
	    echo "installed chromium for the browser tests"; \
	  else \
	    echo "NOTE: could not install chromium (needs root or sudo and apt-get); the browser tests will" \
	         "fail in CI and skip elsewhere: run 'sudo apt-get install chromium' and 'make setup' again"; \
	  fi; }
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/spacedg scenes synth --n 4 --out $(DEMO_DIR)/scenes
	$(BIN)/spacedg scenes info $(DEMO_DIR)/scenes
	$(BIN)/spacedg scenes preview $(DEMO_DIR)/scenes --out $(DEMO_DIR)/floorplans.png
	$(BIN)/spacedg gallery $(DEMO_DIR)/scenes/room-000000 --view frame_0000 --out $(DEMO_DIR)/gallery.png
	$(BIN)/spacedg qa build $(DEMO_DIR)/scenes
	$(BIN)/spacedg qa stats $(DEMO_DIR)/scenes
	$(BIN)/spacedg export --split bench --scenes $(DEMO_DIR)/scenes --out $(DEMO_DIR)/bench --image-size 320x240 --max-questions 44
	$(BIN)/spacedg qa preview $(DEMO_DIR)/scenes/room-000000 --out $(DEMO_DIR)/questions.png
	# evaluation pipeline end to end with a tiny random VLM built in code (its answers are noise)
	$(BIN)/python -c "from spacedg.vlm import save_tiny_vlm; save_tiny_vlm('$(DEMO_DIR)/tiny-vlm')"
	$(BIN)/spacedg predict --model $(DEMO_DIR)/tiny-vlm --bench $(DEMO_DIR)/bench --out $(DEMO_DIR)/preds/tiny.jsonl --name tiny-vlm
	$(BIN)/spacedg predict --model $(DEMO_DIR)/tiny-vlm --bench $(DEMO_DIR)/bench --out $(DEMO_DIR)/preds/tiny-blind.jsonl --name tiny-vlm --no-image
	$(BIN)/spacedg eval $(DEMO_DIR)/preds/tiny.jsonl $(DEMO_DIR)/preds/tiny-blind.jsonl --bench $(DEMO_DIR)/bench --out $(DEMO_DIR)/report
	# fine-tuning smoke run (tiny VLM, online degraded samples, 4 steps with a checkpoint and an evaluation)
	$(BIN)/python -m spacedg.sft +experiment=tiny 'data.scenes=[$(DEMO_DIR)/scenes]' output_dir=$(DEMO_DIR)/sft-tiny
	$(BIN)/spacedg plugins

# The suite in two lanes on the machine's two cores: $(BACK_LANE) (torchrun launches, an installed
# wheel; the dataset, evaluation and tiny-VLM tests and the fresh-cache numba test, to balance the
# lanes: ~6½–7 min each) in the background, the rest in front (beside it, tests/test_readme.py's
# runner); the background lane's output follows the front's, and both must pass.
# An interrupted run stops the background lane and removes its log (the EXIT trap).
# First `spacedg kernels` compiles the CPU kernels into numba's cache, a process per group (at most the cores): on a
# fresh clone each lane compiled them itself, often the same ones at once (the times: docs/command-line.md;
# spacedg/data/kernel_warmup.py). Only a speed-up: a failed
# warm-up leaves the lanes to compile, and to report what is wrong.
BACK_LANE := tests/sft tests/data tests/eval tests/vlm tests/render/test_numba_cache_determinism.py
test: $(STAMP)
	@log=$$(mktemp) || exit 1; lane=; \
	trap 'if [ -n "$$lane" ]; then kill $$lane 2>/dev/null; fi; rm -f "$$log"' EXIT; trap 'exit 130' INT TERM; \
	$(PYCACHE_ON) $(BIN)/spacedg kernels || echo "NOTE: the kernel warm-up failed (above); each lane compiles the kernels itself" >&2; \
	$(PYCACHE_ON) $(BIN)/python -m pytest -q -p no:cacheprovider $(BACK_LANE) > "$$log" 2>&1 & lane=$$!; \
	$(PYCACHE_ON) $(BIN)/python -m pytest -q $(addprefix --ignore=,$(BACK_LANE)); front=$$?; \
	wait $$lane; back=$$?; lane=; \
	echo "---- $(BACK_LANE) (the second lane) ----"; cat "$$log"; \
	test $$front -eq 0 && test $$back -eq 0

clean:
	rm -rf $(VENV) runs .pytest_cache

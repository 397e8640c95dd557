# Two entry points from a fresh clone (only Python 3.11 needed):
#   make demo   - create .venv, install the package, run the main demo (video + JSON + plots in out/)
#   make test   - create .venv, install with the [rl,marl,rl-analysis,dev,scip,tether,ray] extras, run the default (fast) test suite
# Further targets: make test-slow (long checks), make fuzz (10 minutes of property-based fuzzing),
#   make bench (benchmarks), make bench-ray (local processes vs Ray, RLlib vs SB3 sampling), make lint,
#   make typecheck (mypy over impact_env, planners and baselines; its options in setup.cfg [mypy]),
#   make wheel-check (sdist + wheel, smoke test of the wheel in a fresh venv), make docs (the documentation
#   site, warnings as errors), make docs-check (its links and a headless-Chromium look at an environment page),
#   make docs-media (re-make the GIFs and figures the site shows),
#   make results (retrain the RL baselines and rerun the expert-vs-learned benchmark: ~3 h).
# Benchmarks run as modules from the repository root (python -m benchmarks.X); the ones that keep cells
# write them to results/ (results/README.md).

PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
OUT := out

.PHONY: demo test test-slow fuzz bench bench-expert bench-ir bench-ray results lint typecheck clean wheel-check docs docs-check \
	docs-media

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# The base install: what the simulator, planner and expert need. The editable install compiles the three C
# helpers in place (setup.py; a change to their sources rebuilds them here).
$(VENV)/.base-installed: $(BIN)/python setup.cfg pyproject.toml setup.py impact_env/transport/_substeps.c \
		impact_env/tether/_substeps.c impact_env/stl/_cmonitor.c
	$(BIN)/pip install --quiet -e .
	touch $@

# The dev install: torch pinned to the CPU build first (an unpinned torch pulls several GB of CUDA
# wheels), then stable-baselines3, supersuit, SCIP (so the tests cover that planner backend too), z3 (the
# tether planners' thesis pipeline), Ray and RLlib (their tests start a local Ray instance and a simulated
# two-node cluster themselves; RLlib pins gymnasium==1.2.2, so the suite runs with that version) and the
# test tools. torch is pinned again on the line that pulls RLlib.
$(VENV)/.dev-installed: $(VENV)/.base-installed
	$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet torch==2.13.0 -e '.[rl,marl,rl-analysis,dev,scip,tether,ray]'
	touch $@

# The main demo: plan the corridor (MILP, HiGHS), fly it with the expert (replanner + MPC) in the
# simulator, write the plan, the video, the plots and the JSON summary.
demo: $(VENV)/.base-installed
	mkdir -p $(OUT)
	$(BIN)/impact-env show corridor --plot $(OUT)/corridor_setup.png
	$(BIN)/impact-env plan corridor --json $(OUT)/corridor_plan.json --plot $(OUT)/corridor_plan.png
	$(BIN)/impact-env run corridor --controller expert --plan $(OUT)/corridor_plan.json --seed 0 \
		--video $(OUT)/corridor_expert.mp4 --json $(OUT)/corridor_expert.json --plot $(OUT)/corridor_expert.png
	@echo "demo outputs in $(OUT)/"

# --dist loadgroup: the tests marked xdist_group("ray") share one worker, so at most one Ray instance runs
test: $(VENV)/.dev-installed
	$(BIN)/python -m pytest -q -n 2 --dist loadgroup --durations=15

test-slow: $(VENV)/.dev-installed
	$(BIN)/python -m pytest -q -n 2 --dist loadgroup -m slow --timeout 3600 --durations=25

# The fuzzers of tests/fuzz/ drawing fresh inputs for FUZZ_SECONDS per fuzzer (17 fuzzers on 2 processes:
# 60 s each is about 10 minutes), then a table of the inputs tried.
FUZZ_SECONDS ?= 60
fuzz: $(VENV)/.dev-installed
	mkdir -p $(OUT)
	rm -f $(OUT)/fuzz_report.jsonl
	IMPACT_ENV_FUZZ_SECONDS=$(FUZZ_SECONDS) IMPACT_ENV_FUZZ_REPORT=$(OUT)/fuzz_report.jsonl \
		$(BIN)/python -m pytest -q -n 2 -m slow tests/fuzz --timeout 3600

bench-expert: $(VENV)/.base-installed
	$(BIN)/python -m benchmarks.expert --episodes 50

# the expert flying spatially robust against impact-robust plans under impact noise and restitution offsets
# (results/impact_robust: cells.jsonl, resumable, and table.md; with long_throw_trim about 1.7 h with 2 workers
# on an idle machine, by python -m benchmarks.impact_robust --estimate)
bench-ir: $(VENV)/.base-installed
	$(BIN)/python -m benchmarks.impact_robust --workers 2

# the same bench on local processes and on Ray, and RLlib's sampling against SB3's SubprocVecEnv (docs/ray.md)
bench-ray: $(VENV)/.dev-installed
	$(BIN)/python -m benchmarks.ray_overhead

bench: $(VENV)/.base-installed
	$(BIN)/python -m benchmarks.env_throughput
	$(BIN)/python -m benchmarks.tether_throughput
	$(BIN)/python -m benchmarks.planner
	$(BIN)/python -m benchmarks.planner_stage2
	$(BIN)/python -m benchmarks.mpc

# results/baselines/: PPO, SAC and behaviour cloning against the expert on all three scenarios
results: $(VENV)/.dev-installed
	bash baselines/reproduce.sh

# the docs tools on top of the dev install (torch stays the pinned CPU build installed above)
$(VENV)/.docs-installed: $(VENV)/.dev-installed
	$(BIN)/pip install --quiet torch==2.13.0 -e '.[rl,marl,rl-analysis,dev,scip,tether,ray,docs]'
	touch $@

wheel-check: $(VENV)/.dev-installed
	bash .ci/wheel_check.sh $(BIN)/python

# the site in site/; the tutorial notebook runs at TUTORIAL_SIZE (small: seconds of PPO; full: the real run)
TUTORIAL_SIZE ?= small
docs: $(VENV)/.docs-installed
	rm -rf .cache/mkdocs-jupyter  # the notebook runs on every build
	TUTORIAL_SIZE=$(TUTORIAL_SIZE) NO_MKDOCS_2_WARNING=1 SDL_VIDEODRIVER=dummy MPLBACKEND=Agg $(BIN)/mkdocs build --strict

docs-check: docs
	$(BIN)/python -m pytest -q -p no:cacheprovider tests/docs/docs_site_check.py

docs-media: $(VENV)/.base-installed
	SDL_VIDEODRIVER=dummy MPLBACKEND=Agg $(BIN)/python scripts/make_docs_media.py

lint: $(VENV)/.dev-installed
	$(BIN)/ruff check impact_env planners baselines tests benchmarks

# the packages' annotations checked (setup.cfg [mypy]: the files, the options and why each exception)
typecheck: $(VENV)/.dev-installed
	$(BIN)/mypy

clean:
	rm -rf $(VENV) $(OUT) *.egg-info site build
	find impact_env -name "_*.so" -delete

# marl_vertiport: every command a user needs. `make help` lists them.
# `make test` and `make train` set up .venv by themselves on a fresh machine.

PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
PIP    := $(VENV)/bin/pip
STAMP  := $(VENV)/.installed
CLI    := $(VENV)/bin/marl-vertiport
CONFIG ?= paper

.DEFAULT_GOAL := help
AGENTS   ?= random fcfs dispatcher
EPISODES ?= 50
# Whether EPISODES was given (make evaluate SUITE=... EPISODES=N: the first N of the suite's days).
EPISODES_GIVEN = $(filter command line environment environment override,$(origin EPISODES))
CONFIGS  ?= paper paper_uncertain
OUT      ?= runs/eval
# make evaluate renders each controller's worst day with its decision log (0: it does not).
WORST_DAY ?= 1
AGENT    ?= dispatcher
SWEEP    ?= wind
CURVES   ?= scratch
SEEDS    ?= 3
ITERATIONS ?=
# The layouts `make safety` plays (paper_uncertain and paper_uncertain_10 are paper with
# uncertainty, which it sets itself).
SAFETY_LAYOUTS ?= paper small twin wide mid large fleet40_overloaded
# The test days per case `make bar` plays: the first BAR_DAYS of the 200 of docs/results.md
# (lookahead looks ahead on every contested decision: 10 to 80 s a day on one core).
BAR_DAYS ?= 100

# Where `evaluate`, `sweep` and `train` run their tasks: BACKEND=ray (Ray reads RAY_ADDRESS,
# e.g. RAY_ADDRESS=auto to join a cluster started with `ray start --head`; docs/scaling.md).
BACKEND  ?= local
RUN_ON    = --backend $(BACKEND)

.PHONY: help venv test test-fast check-results fuzz soak train check-train check-train-margin curves evaluate sweep results bar safety render bench bench-ecosystem bench-compare env-demo clean

help:  ## list the targets
	@awk 'BEGIN {FS = ":.*## "} /^[a-zA-Z_-]+:.*## / {printf "  make %-18s %s\n", $$1, $$2}' $(MAKEFILE_LIST)

$(PY):
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found; marl_vertiport needs CPython 3.11 (pybullet 3.2.7 has a wheel for 3.11 only). Set PYTHON=/path/to/python3.11"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip

# torch first, pinned to the CPU build, so nothing later pulls a CUDA build. The ray extra
# (the ray backend) and the torchrl, rllib and sb3 extras (agents/interop/) are installed too,
# so that `make test` runs their tests.
$(STAMP): $(PY) pyproject.toml
	$(PIP) install --quiet torch==2.13.0
	$(PIP) install --quiet -e '.[test,ray,torchrl,rllib,sb3]'
	@touch $(STAMP)

venv: $(STAMP)  ## create .venv and install the project with pinned dependencies

test: $(STAMP)  ## run the whole test suite (API checks, parity, physics, reward, invariants) but the replay of the shipped results
	$(PY) -m pytest -q -m "not replay"

test-fast: $(STAMP)  ## the test suite without the full-episode tests
	$(PY) -m pytest -q -m "not slow and not replay"

check-results: $(STAMP)  ## the shipped results name the shipped checkpoint, and the first 2 days of every row replay exactly (8 minutes on an idle 2-core AMD EPYC)
	$(PY) -m pytest -q -m replay tests/tools/test_shipped_results.py

soak: $(STAMP)  ## many days with every uncertainty high on six layouts: invariants after every step, memory (under a minute on an idle 2-core AMD EPYC)
	$(CLI) soak --days 40

fuzz: $(STAMP)  ## the property-based tests on many more examples (HYPOTHESIS_PROFILE=long, under a minute on an idle 2-core AMD EPYC)
	HYPOTHESIS_PROFILE=long $(PY) -m pytest -q tests/sim/test_properties.py

# CONFIG names an env config elsewhere; for `train` it names a train config when given.
TRAIN_CONFIG = $(if $(filter command line,$(origin CONFIG)),$(CONFIG),default)

train: $(STAMP)  ## train the GCN policy (CONFIG=default|scratch|expert_iteration|expert_iteration_prior|path, RESUME=runs/train/<run>, with ROUNDS=N its warm start taken on to N DAgger rounds, WORKERS=1 for one process; 13 minutes on an idle 2-core AMD EPYC without AVX-512, docs/training.md)
	$(CLI) train $(if $(RESUME),--resume $(RESUME) $(if $(ROUNDS),--rounds $(ROUNDS)),--config $(TRAIN_CONFIG)) $(if $(WORKERS),--workers $(WORKERS)) $(RUN_ON)

check-train: $(STAMP)  ## train as make train does (or CHECKPOINT=path), then pair it with the shipped checkpoint on 200 validation days: M, every safety metric and a verdict (training as long as make train, then the 400 days)
	$(CLI) check-train $(if $(CHECKPOINT),--checkpoint $(CHECKPOINT)) $(if $(WORKERS),--workers $(WORKERS)) $(RUN_ON)

check-train-margin: $(STAMP)  ## measure M of check-train: train seeds 0, 1 and 2 of the default config, play them on the check's days (22 minutes on an idle 2-core Intel Xeon)
	for seed in 0 1 2; do $(CLI) train --config default --seed $$seed --no-eval --run-dir runs/check-train-margin/seed$$seed $(RUN_ON) || exit 1; done
	$(CLI) check-train --margin runs/check-train-margin/seed0 runs/check-train-margin/seed1 runs/check-train-margin/seed2 --out runs/check-train-margin/margin $(RUN_ON)

curves: $(STAMP)  ## learning curves: SEEDS training seeds (3) of each train config in CURVES (scratch), ITERATIONS to override their budget, RESUME=1 to go on with the runs already in runs/curves/ (a long budget over several sittings), 95 % intervals over seeds, baselines as lines (runs/curves/; two seeds run at a time; one seed of scratch, 540 iterations, took 18 minutes on a 2-core Intel Xeon beside one other job; 3 100 iterations took 2.4 CPU-hours a seed on a 2-core AMD EPYC)
	$(CLI) curves --configs $(CURVES) --seeds $(SEEDS) $(if $(ITERATIONS),--iterations $(ITERATIONS)) $(if $(RESUME),--resume) $(RUN_ON)

evaluate: $(STAMP)  ## evaluate AGENTS on CONFIGS (default: both cases), EPISODES per case, into OUT (runs/eval); SUITE=transfer: a suite of configs/suites/ with its report (EPISODES=N: its first N days); then each controller's worst day rendered with its decision log into OUT/worst_day (WORST_DAY=0: not)
ifdef SUITE
	$(CLI) evaluate --suite $(SUITE) $(if $(EPISODES_GIVEN),--episodes $(EPISODES)) --out $(OUT)/$(notdir $(basename $(SUITE))) --report $(OUT)/$(notdir $(basename $(SUITE)))/report.md $(RUN_ON)
	$(if $(filter 0,$(WORST_DAY)),,$(CLI) worst-day $(OUT)/$(notdir $(basename $(SUITE))) --no-progress)
else
	$(CLI) evaluate --agents $(AGENTS) --configs $(CONFIGS) --episodes $(EPISODES) --out $(OUT) $(RUN_ON)
	$(if $(filter 0,$(WORST_DAY)),,$(CLI) worst-day $(OUT) --no-progress)
endif

sweep: $(STAMP)  ## run the sweep SWEEP of configs/sweeps/ (default wind) into runs/sweeps/SWEEP: tidy CSV, figure with CIs (BACKEND=ray to use a cluster)
	$(CLI) sweep $(SWEEP) --out runs/sweeps/$(notdir $(basename $(SWEEP))) $(RUN_ON)

results: $(STAMP)  ## regenerate every shipped result of the shipped policy but the bar's: docs/results.md (200 test days per uncertainty level, the planner included), docs/results/transfer.md and docs/results/scaling.md (the suites), docs/results/sweeps/wind (the wind sweep)
	$(CLI) evaluate --agents random fcfs dispatcher planner gcn --configs paper paper_uncertain paper_uncertain_10 --episodes 200 --out docs/results --report docs/results.md $(RUN_ON)
	$(CLI) evaluate --suite transfer --out docs/results/transfer --report docs/results/transfer.md $(RUN_ON)
	$(CLI) evaluate --suite scaling --out docs/results/scaling --report docs/results/scaling.md $(RUN_ON)
	$(CLI) sweep wind --out docs/results/sweeps/wind $(RUN_ON)
	$(CLI) paper-claims --out docs/results/paper_claims.md > /dev/null

bar: $(STAMP)  ## the learned ATC against the bar: lookahead on the first $(BAR_DAYS) of docs/results.md's test days per case (docs/results/bar.md), paired day by day with the dispatcher, gcn and the planner, unforced losses against the dispatcher and the planner (docs/results/bar_paired.md; 55 minutes on a 2-core Intel Xeon)
	$(CLI) evaluate --agents lookahead --configs paper paper_uncertain paper_uncertain_10 --episodes $(BAR_DAYS) --out docs/results/bar --report docs/results/bar.md $(RUN_ON)
	for base in dispatcher gcn planner; do $(PY) -m agents.evaluate.paired docs/results/episodes.csv docs/results/bar/episodes.csv --pair $$base lookahead --csv docs/results/bar/paired_$$base.csv || exit 1; echo; done > docs/results/bar_paired.md

# One set of make safety: $(call SAFETY_SET,name,probability of gusts, charger and take-off
# failures; empty: the configs' own).
SAFETY_SET = $(CLI) evaluate --agents random fcfs dispatcher gcn --configs $(SAFETY_LAYOUTS) --episodes 50 $(if $(2),--set uncertainty.wind_gust_prob=$(2) --set uncertainty.charger_failure_prob=$(2) --set uncertainty.takeoff_failure_prob=$(2)) --out docs/results/safety/$(1) --report docs/results/safety/$(1).md $(RUN_ON)

safety: $(STAMP)  ## every controller but the planner on every shipped layout at 0, 5 and 10 % uncertainty (gusts, charger and take-off failures), 50 test days a cell: losses of separation, contacts, minimum separation (docs/results/safety/; about 15 minutes on an idle 2-core AMD EPYC)
	$(call SAFETY_SET,u00,)
	$(call SAFETY_SET,u05,0.05)
	$(call SAFETY_SET,u10,0.1)

# `make render` writes into runs/render/ unless OUT is given on the command line.
RENDER_DIR = $(if $(filter command line environment,$(origin OUT)),$(OUT),runs/render)

render: $(STAMP)  ## write an animated GIF of one episode of AGENT on CONFIG, with its decision log, into OUT (runs/render/)
	$(CLI) render --agent '$(AGENT)' --config $(CONFIG) --out $(RENDER_DIR)/$(subst /,_,$(subst :,_,$(AGENT)))_$(CONFIG).gif

bench: $(STAMP)  ## measure env, physics, vector, inference and training speed (docs/performance.md)
	$(CLI) bench --out runs/bench --report docs/performance.md

bench-ecosystem: $(STAMP)  ## the env's speed through each library of docs/ecosystem.md (PettingZoo AEC and Parallel, Gymnasium, SuperSuit, TorchRL, SB3, RLlib): steps per second, one process (runs/bench/ecosystem.json; about 4 minutes)
	$(PY) -m agents.bench.ecosystem --out runs/bench

bench-compare: $(STAMP)  ## the env under the dispatcher's traffic here and in the checkout BASE=path (a git worktree of another commit): medians of 5 interleaved replays and their ratio
	@test -n "$(BASE)" || { echo "make bench-compare: give BASE=path, a checkout of the commit to compare with (git worktree add /tmp/base <commit>)" >&2; exit 2; }
	$(PY) -m agents.bench.compare --base $(BASE)

env-demo: $(STAMP)  ## run one day of the env with random legal actions and print its metrics
	$(CLI) demo --config $(CONFIG)

clean:  ## remove the virtual environment and caches
	rm -rf $(VENV) .pytest_cache build *.egg-info

# Every target creates .venv with python3 if it is missing and installs the project into it with the extras the
# scripts and tests need (the core install, `pip install .`, is numpy, numba, gymnasium and scipy only).
# No script writes into results/ unless told to: their default outputs are under runs/; the targets below name
# the committed folders.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
SUMO_STAMP := $(VENV)/.sumo
EXTRAS := dev,train,render,docs
RUN := MPLBACKEND=Agg $(PY) -m
TRAIN_BACKEND ?= --backend serial  # make train's seeds side by side: TRAIN_BACKEND="--backend ray --address auto"
SEEDS := $(RUN) train.train_seeds --seeds 0 1 2 3 4 $(TRAIN_BACKEND)
REAL := --env-config "$$(cat hyperparams/real_traffic.json)" --curve-freq 0  # issue 39's training traffic

.PHONY: install demo test benchmark reproduce train recipes bench typecheck package clients sumo clean

install: $(STAMP)

$(STAMP): pyproject.toml
	@echo "==> Setting up $(VENV) with timegap_env and its dependencies (1-2 minutes, once; pip's progress follows)"
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install -e '.[$(EXTRAS)]' | grep -E '^(Collecting|Successfully)'; test $${PIPESTATUS[0]} -eq 0
	touch $(STAMP)
	@echo "==> $(VENV) is ready"

$(SUMO_STAMP): $(STAMP)
	$(PY) -m pip install -e '.[$(EXTRAS),sumo]' | grep -E '^(Collecting|Successfully)'; test $${PIPESTATUS[0]} -eq 0
	touch $(SUMO_STAMP)

demo: $(STAMP)  # the paper's scenario and the default mix's leaderboard from the committed policies (runs/demo)
	$(RUN) train.demo --out runs/demo
	$(RUN) train.benchmark --groups default --episodes 500 --out runs/demo/benchmark --force --backend processes --workers 2

test: $(STAMP)
	MPLBACKEND=Agg $(PY) -m pytest -q

benchmark: $(SUMO_STAMP)  # the whole benchmark -> results/benchmark (README: how long; cached in runs/benchmark-cache)
	$(RUN) train.benchmark --out results/benchmark --force --backend processes --workers 2
	$(RUN) train.results_index --out results/README.md

reproduce: $(SUMO_STAMP)  # every committed result of the core venv, then the benchmark (hours; make train: the models)
	$(RUN) train.demo --out results
	$(RUN) train.reproduce_paper --out results/paper
	$(RUN) train.field_validation --out results/field
	$(RUN) train.calibrate_openacc --out results/field
	$(RUN) train.choose_degradation_mix --out results/degradation
	$(RUN) train.value_of_information --out results/degradation
	$(RUN) train.detection_benchmark --out results/monitoring
	$(RUN) train.choose_window --out results/monitor_window.md
	$(RUN) train.tune_rule --env-id TimeGapMonitor-v0 --out results/v0/rule
	$(RUN) train.tune_rule --out results/rule
	$(RUN) train.task_map --out results/task
	$(RUN) train.render_frame --out results/env_frame.png
	$(RUN) train.sweep train/sweeps/example.yml --out results/sweep/example
	$(RUN) train.compare_curves results/ppo_v1 results/ppo_v1_nomonitor results/ppo_v1_rawgap results/recipes/ppo_* --out results/recipes/curves
	bash .ci/sumo
	$(RUN) train.sumo_report --chart-step-tuning results/rule/tuning.csv --backend processes --out results/sumo
	$(MAKE) benchmark
	$(RUN) train.bench --out results/bench.md

train: $(STAMP)  # the committed models: PPO on the default task and its two monitor ablations, 5 training seeds each; v0's PPO; issue 39: ppo_real, its two ablations, ppo_real_fast, ppo_real_start and ppo_real_safe, 5 seeds each
	$(PY) -m train.train_ppo --env-id TimeGapMonitor-v0 --out results/v0/ppo
	$(PY) -m train.train_ppo --out results/ppo_v1
	$(PY) -m train.train_ppo --hide-features monitor --out results/ppo_v1_nomonitor
	$(PY) -m train.train_ppo --env-config '{"monitor": {"estimator": "raw_gap"}}' --out results/ppo_v1_rawgap
	for seed in 1 2 3 4; do \
	  $(PY) -m train.train_ppo --seed $$seed --out results/recipes/ppo_seed$$seed && \
	  $(PY) -m train.train_ppo --seed $$seed --hide-features monitor --out results/recipes/ppo_nomonitor_seed$$seed && \
	  $(PY) -m train.train_ppo --seed $$seed --env-config '{"monitor": {"estimator": "raw_gap"}}' --out results/recipes/ppo_rawgap_seed$$seed || exit 1; \
	done
	$(SEEDS) --out 'results/recipes/ppo_real_seed{seed}' -- $(REAL)
	$(SEEDS) --out 'results/recipes/ppo_real_nomonitor_seed{seed}' -- $(REAL) --hide-features monitor
	$(SEEDS) --out 'results/recipes/ppo_real_rawgap_seed{seed}' -- $(REAL) --env-config '{"monitor": {"estimator": "raw_gap"}}'
	$(SEEDS) --out 'results/recipes/ppo_real_fast_seed{seed}' -- $(REAL) --hyperparams hyperparams/ppo_fast.yml --timesteps 8000000
	$(SEEDS) --out 'results/recipes/ppo_real_start_seed{seed}' -- $(REAL) --env-config '{"random_initial_setting": false}'
	$(SEEDS) --out 'results/recipes/ppo_real_safe_seed{seed}' -- $(REAL) --collision-budget 0.005 --lagrange-rate 10

recipes: $(STAMP)  # the other recipes tried (issue 25), one seed each (~1 h); issue 39's learner choice (~1.5 h), recipe choice among 5 recipes and behaviour (~30 min)
	$(PY) -m train.train_ppo --timesteps 6000000 --out results/recipes/ppo_6m
	$(PY) -m train.train_ppo --env-config '{"action_mode": "platoon"}' --out results/recipes/ppo_absolute
	$(PY) -m train.train_ppo --frame-stack 4 --out results/recipes/ppo_stack4
	$(PY) -m train.train_ppo --algo ppo_lstm --out results/recipes/ppo_lstm
	$(PY) -m train.train_ppo --cost-budget 0.05 --out results/recipes/ppo_lagrange_0.05
	$(PY) -m train.train_ppo --cost-budget 0.1 --out results/recipes/ppo_lagrange_0.1
	$(RUN) train.choose_learner --out results/learner --force
	$(RUN) train.choose_recipe --out results/recipe_choice --force  # the recipes: choose_recipe's DEFAULT_RECIPES
	$(RUN) train.policy_behaviour --out results/policy_behaviour --force

bench: $(STAMP)  # speed, as ratios to references run in the same process
	$(RUN) train.bench --out runs/bench.md

typecheck: $(STAMP)  # mypy over the modules pyproject's [tool.mypy] lists
	$(PY) -m mypy

package: $(STAMP)  # pip install . / the wheel / the sdist, core only, in a throwaway venv: the env steps without torch
	bash .ci/package

clients:  # the env through SB3, sb3-contrib, rl-zoo3, RLlib, TorchRL, Tianshou, MORL, gymnasium's wrappers (own venv)
	bash .ci/clients

sumo: $(STAMP)  # SUMO as a second simulator: the sumo extra and the tests marked sumo (~10 min)
	bash .ci/sumo

clean:
	rm -rf $(VENV) build dist *.egg-info .pytest_cache .mypy_cache

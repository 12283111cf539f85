# Every target creates .venv with python3 if it is missing and installs the project into it with the extras the
# scripts and tests need (the core install, `pip install .`, is numpy, numba, gymnasium and scipy only).
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
EXTRAS := dev,train,render,docs

.PHONY: install demo test typecheck package clients sumo morl train recipes group-idm bench calibrate map degradation clean

install: $(STAMP)

$(STAMP): pyproject.toml
	@echo "==> Setting up $(VENV) with timegap_env and its dependencies (1-2 minutes, once; pip's progress follows)"
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install -e '.[$(EXTRAS)]' | grep -E '^(Collecting|Successfully)'; test $${PIPESTATUS[0]} -eq 0
	touch $(STAMP)
	@echo "==> $(VENV) is ready"

demo: $(STAMP)
	MPLBACKEND=Agg $(PY) -m train.demo
	MPLBACKEND=Agg $(PY) -m train.reproduce_paper
	MPLBACKEND=Agg $(PY) -m train.field_validation
	MPLBACKEND=Agg $(PY) -m train.value_of_information
	MPLBACKEND=Agg $(PY) -m train.detection_benchmark
	MPLBACKEND=Agg $(PY) -m train.tune_rule
	MPLBACKEND=Agg $(PY) -m train.tune_rule --env-id TimeGapMonitor-v1 --out results/rule
	MPLBACKEND=Agg $(PY) -m train.evaluate
	MPLBACKEND=Agg $(PY) -m train.task_map
	MPLBACKEND=Agg $(PY) -m train.evaluate_task --chart-step-tuning results/rule/tuning.csv --model results/ppo_v1 results/ppo_v1_nomonitor results/ppo_v1_rawgap
	MPLBACKEND=Agg $(PY) -m train.evaluate_task --policies rule_platoon --model results/ppo_v1 results/ppo_v1_nomonitor results/ppo_v1_rawgap --baseline ppo_v1 --groups v1 regimes --out results/task/ablation
	MPLBACKEND=Agg $(PY) -m train.evaluate_task --chart-step-tuning results/rule/tuning.csv --model results/ppo_v1 results/ppo_v1_nomonitor results/ppo_v1_rawgap --groups larger_degradations regimes ngsim_in_band openacc stop_and_go emergency_braking --out results/task/groups

test: $(STAMP)
	MPLBACKEND=Agg $(PY) -m pytest -q

typecheck: $(STAMP)  # mypy over the modules pyproject's [tool.mypy] lists
	$(PY) -m mypy

package: $(STAMP)  # pip install . / the wheel / the sdist, core only, in a throwaway venv: the env steps without torch
	bash .ci/package

clients:  # the env through SB3, sb3-contrib, rl-zoo3, RLlib, TorchRL, Tianshou, gymnasium's wrappers (own venv)
	bash .ci/clients

group-idm: $(STAMP)  # v1's policies behind highway-env's IDM driver (issue 25's IDM group; ~40 min: slow leaders)
	MPLBACKEND=Agg $(PY) -m train.evaluate_task --chart-step-tuning results/rule/tuning.csv --model results/ppo_v1 results/ppo_v1_nomonitor results/ppo_v1_rawgap --groups idm --out results/task/idm

sumo: $(STAMP)  # SUMO as a second simulator (issue 26): the sumo extra, the tests marked sumo, results/sumo (~10 min)
	bash .ci/sumo
	MPLBACKEND=Agg $(PY) -m train.sumo_report --chart-step-tuning results/rule/tuning.csv --backend processes

morl:  # MORL-Baselines' Envelope on mo-TimeGapMonitor-v1 -> results/morl (in .venv-clients: make clients makes it)
	MPLBACKEND=Agg .venv-clients/bin/python -m train.train_morl

train: $(STAMP)  # the committed runs: v0's PPO; v1's PPO and its two monitor ablations (same seed and budget)
	$(PY) -m train.train_ppo
	$(PY) -m train.train_ppo --env-id TimeGapMonitor-v1 --out results/ppo_v1
	$(PY) -m train.train_ppo --env-id TimeGapMonitor-v1 --hide-features monitor --out results/ppo_v1_nomonitor
	$(PY) -m train.train_ppo --env-id TimeGapMonitor-v1 --env-config '{"monitor": {"estimator": "raw_gap"}}' --out results/ppo_v1_rawgap

recipes: $(STAMP)  # every other recipe tried on v1 (issue 25) and the chosen one and its ablations with two more seeds: curves, selection and held-out numbers (~1 h)
	$(PY) -m train.train_ppo --env-id TimeGapMonitor-v1 --timesteps 6000000 --out results/recipes/ppo_6m
	$(PY) -m train.train_ppo --env-id TimeGapMonitor-v1 --env-config '{"action_mode": "platoon"}' --out results/recipes/ppo_absolute
	$(PY) -m train.train_ppo --env-id TimeGapMonitor-v1 --frame-stack 4 --out results/recipes/ppo_stack4
	$(PY) -m train.train_ppo --env-id TimeGapMonitor-v1 --algo ppo_lstm --out results/recipes/ppo_lstm
	$(PY) -m train.train_ppo --env-id TimeGapMonitor-v1 --cost-budget 0.05 --out results/recipes/ppo_lagrange_0.05
	$(PY) -m train.train_ppo --env-id TimeGapMonitor-v1 --cost-budget 0.1 --out results/recipes/ppo_lagrange_0.1
	for seed in 1 2; do \
	  $(PY) -m train.train_ppo --env-id TimeGapMonitor-v1 --seed $$seed --out results/recipes/ppo_seed$$seed && \
	  $(PY) -m train.train_ppo --env-id TimeGapMonitor-v1 --seed $$seed --hide-features monitor --out results/recipes/ppo_nomonitor_seed$$seed && \
	  $(PY) -m train.train_ppo --env-id TimeGapMonitor-v1 --seed $$seed --env-config '{"monitor": {"estimator": "raw_gap"}}' --out results/recipes/ppo_rawgap_seed$$seed || exit 1; \
	done
	MPLBACKEND=Agg $(PY) -m train.compare_curves results/ppo_v1 results/ppo_v1_nomonitor results/ppo_v1_rawgap results/recipes/ppo_* --out results/recipes/curves
	MPLBACKEND=Agg $(PY) -m train.evaluate_task --split selection --chart-step-tuning results/rule/tuning.csv --model results/ppo_v1 results/ppo_v1_nomonitor results/ppo_v1_rawgap results/recipes/ppo_* --out results/recipes/selection
	MPLBACKEND=Agg $(PY) -m train.evaluate_task --chart-step-tuning results/rule/tuning.csv --model results/ppo_v1 results/ppo_v1_nomonitor results/ppo_v1_rawgap results/recipes/ppo_* --out results/recipes/held_out
	MPLBACKEND=Agg $(PY) -m train.evaluate_task --policies rule_platoon --model results/ppo_v1 results/ppo_v1_nomonitor results/ppo_v1_rawgap results/recipes/ppo_seed* results/recipes/ppo_nomonitor_seed* results/recipes/ppo_rawgap_seed* --groups regimes --out results/recipes/regimes_seeds

bench: $(STAMP)
	MPLBACKEND=Agg $(PY) -m train.bench

calibrate: $(STAMP)
	MPLBACKEND=Agg $(PY) -m train.calibrate_openacc

map: $(STAMP)  # where reading the monitor can pay: weightings x severities x traffic (results/task, docs/task.md)
	MPLBACKEND=Agg $(PY) -m train.task_map

degradation: $(STAMP)
	MPLBACKEND=Agg $(PY) -m train.choose_degradation_mix
	MPLBACKEND=Agg $(PY) -m train.value_of_information
	MPLBACKEND=Agg $(PY) -m train.detection_benchmark

clean:
	rm -rf $(VENV) build dist *.egg-info .pytest_cache .mypy_cache

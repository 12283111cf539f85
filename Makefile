# Every target creates .venv with python3 if it is missing and installs the project into it.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: install demo test train bench calibrate degradation clean

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

demo: $(STAMP)
	MPLBACKEND=Agg $(PY) -m train.demo
	MPLBACKEND=Agg $(PY) -m train.reproduce_paper
	MPLBACKEND=Agg $(PY) -m train.field_validation
	MPLBACKEND=Agg $(PY) -m train.value_of_information
	MPLBACKEND=Agg $(PY) -m train.detection_benchmark
	MPLBACKEND=Agg $(PY) -m train.tune_rule
	MPLBACKEND=Agg $(PY) -m train.evaluate

test: $(STAMP)
	MPLBACKEND=Agg $(PY) -m pytest -q

train: $(STAMP)
	$(PY) -m train.train_ppo

bench: $(STAMP)
	MPLBACKEND=Agg $(PY) -m train.bench

calibrate: $(STAMP)
	MPLBACKEND=Agg $(PY) -m train.calibrate_openacc

degradation: $(STAMP)
	MPLBACKEND=Agg $(PY) -m train.choose_degradation_mix
	MPLBACKEND=Agg $(PY) -m train.value_of_information
	MPLBACKEND=Agg $(PY) -m train.detection_benchmark

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache

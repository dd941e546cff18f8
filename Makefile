# The two commands of the README: `make demo` and `make test` install whatever is missing first.
SHELL := /bin/bash
VENV := .venv
export OMPI_ALLOW_RUN_AS_ROOT := 1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM := 1
export OMP_NUM_THREADS := 1
MPIRUN := mpirun --oversubscribe
SCENE ?= configs/two_cubes_dies.toml
NP ?= 2

.PHONY: setup demo test test-serial test-mpi container-test clean

setup:
	@scripts/setup

demo: setup
	$(MPIRUN) -n $(NP) $(VENV)/bin/qsc run $(SCENE)

test: setup
	$(VENV)/bin/python -m pytest -q tests
	$(MPIRUN) -n 2 $(VENV)/bin/python -m pytest -q -p no:cacheprovider tests/parallel
	$(MPIRUN) -n 3 $(VENV)/bin/python -m pytest -q -p no:cacheprovider tests/parallel

container-test:
	scripts/container-test

clean:
	rm -rf results .pytest_cache

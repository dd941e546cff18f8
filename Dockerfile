# The qsc_petsc image: Debian 12's PETSc/petsc4py/mpi4py/h5py/OpenMPI, installed by the same
# scripts/setup as on a host. `docker run IMAGE` runs the test suite (serial and under mpirun);
# `docker run -v "$PWD/out:/out" IMAGE qsc run configs/patch_test.toml --out /out` runs a scene.
FROM debian:bookworm-slim

# Root in a container: OpenMPI refuses to start without the two ALLOW flags. One thread per rank,
# like `make`. The venv's bin (qsc, python, pytest) comes first on PATH.
ENV OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 \
    PATH=/app/.venv/bin:$PATH DEBIAN_FRONTEND=noninteractive
WORKDIR /app

# apt + pip first, from scripts/setup and pyproject.toml only, so that editing the code, tests or
# README does not redo this slow layer. The editable install only records where qsc_petsc lives, so
# empty packages and an empty README (pyproject's readme) stand in until the sources arrive; the
# __init__.py files matter: without them setuptools maps the packages as namespaces and `qsc` breaks.
# `make` is for the default command; setup has just run apt-get update, so no second update.
COPY pyproject.toml ./
COPY scripts/setup scripts/setup
RUN mkdir -p qsc_petsc/contact && touch README.md qsc_petsc/__init__.py qsc_petsc/contact/__init__.py \
 && scripts/setup \
 && apt-get install -y -q --no-install-recommends make \
 && rm -rf /var/lib/apt/lists/* /root/.cache

COPY README.md Makefile ./
COPY scripts/ scripts/
COPY configs/ configs/
COPY qsc_petsc/ qsc_petsc/
COPY tests/ tests/

# `make test` = scripts/setup (a no-op check here, under a second) + the suite serial and under
# `mpirun --oversubscribe -n 2` and `-n 3`. Give the container --shm-size=1g for OpenMPI.
CMD ["make", "test"]

# The two commands of the README: `make demo` and `make test`. Both set up the environment first
# (scripts/bootstrap.sh is idempotent and returns in about a second when nothing changed).
SHELL := /bin/bash
VENV  ?= .venv
PY    := $(VENV)/bin/python
MPIRUN_ENV := OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
PYTEST_OPTS ?=

.PHONY: bootstrap demo test test-serial test-mpi bench container-test doctor clean

bootstrap:
	@bash scripts/bootstrap.sh

demo: bootstrap
	$(VENV)/bin/soro demo

doctor: bootstrap
	$(VENV)/bin/soro doctor

# The serial suite (everything but `bench` and `mpi`), then the MPI tests on two ranks, then one summary line.
# Time limits turn a hung test (e.g. an MPI rank waiting for a peer that failed) into a failure.
test: bootstrap
	@mkdir -p out/test
	@rm -f out/test/*.xml
	@status=0; \
	timeout --kill-after=30 2400 $(PY) -m pytest -m "not bench and not mpi" --junitxml=out/test/serial.xml \
	  $(PYTEST_OPTS) || status=$$?; \
	$(MPIRUN_ENV) timeout --kill-after=30 900 mpirun -n 2 $(PY) scripts/mpi_pytest.py -m mpi \
	  --junitxml=out/test/mpi.xml $(PYTEST_OPTS) \
	  || { s=$$?; [ $$status -ne 0 ] || status=$$s; }; \
	$(PY) scripts/test_summary.py out/test/serial.xml out/test/mpi.xml || { [ $$status -ne 0 ] || status=1; }; \
	exit $$status

# The same suite on Debian 13 (DOLFINx 0.9, Python 3.13, numpy 2): a debootstrap root cached in /var/cache/soro
# (built once, ~3-10 min; rebuilt when stale), the project installed there by bootstrap.sh, then `make test`.
.PHONY: test-trixie
test-trixie:
	@bash scripts/test-trixie.sh

bench: bootstrap
	$(PY) -m pytest -m bench tests/benchmarks -s $(PYTEST_OPTS)

# Build the container image (docker, or podman where no Docker engine runs) and run the suite inside it.
container-test:
	@bash docker/container-test.sh

clean:
	rm -rf out .pytest_cache

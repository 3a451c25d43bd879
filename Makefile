# The two commands of the README: `make demo` and `make test`. Both set up the environment first
# (scripts/bootstrap.sh is idempotent and returns in about a second when nothing changed).
SHELL := /bin/bash
VENV  ?= .venv
PY    := $(VENV)/bin/python
MPIRUN_ENV := OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1 \
              OMPI_MCA_btl_tcp_if_include=lo
PYTEST_OPTS ?=

.PHONY: bootstrap demo test test-serial test-mpi bench container-test doctor clean

bootstrap:
	@bash scripts/bootstrap.sh

demo: bootstrap
	$(VENV)/bin/soro demo

doctor: bootstrap
	$(VENV)/bin/soro doctor

# Collection first (under whatever pytest the venv has: Debian 12's 7.2 or Debian 13's 8.x): an import or
# collection error stops here with pytest's message instead of reading as a count of failed tests. Then the
# serial suite (everything but `bench` and `mpi`), the MPI tests on two ranks, and one summary line.
# Time limits turn a hung test (e.g. an MPI rank waiting for a peer that failed) into a failure.
# PYTHONFAULTHANDLER: a native crash (segfault, abort) prints the Python stack of every thread, children included;
# PETSc's own signal handlers would replace faulthandler's when DOLFINx loads (and print no Python stack):
# sorofem starts PETSc without them (sorofem._petsc), and PETSC_OPTIONS does the same for a test that imports
# DOLFINx before sorofem.
test: bootstrap
	@mkdir -p out/test
	@rm -f out/test/*.xml
	@$(PY) -m pytest --collect-only -q -p no:cacheprovider -m "not bench" $(PYTEST_OPTS) > out/test/collect.log 2>&1 \
	  || { tail -40 out/test/collect.log; \
	       echo "make test: collection failed ($$($(PY) -m pytest --version 2>&1 | tail -1)): nothing was run (out/test/collect.log)"; \
	       exit 2; }
	@export PYTHONFAULTHANDLER=1 PETSC_OPTIONS="-no_signal_handler $${PETSC_OPTIONS:-}"; status=0; \
	timeout --kill-after=30 2400 $(PY) -m pytest -m "not bench and not mpi" --junitxml=out/test/serial.xml \
	  $(PYTEST_OPTS) || status=$$?; \
	$(MPIRUN_ENV) timeout --kill-after=30 900 mpirun -n 2 $(PY) scripts/mpi_pytest.py -m mpi \
	  --junitxml=out/test/mpi.xml $(PYTEST_OPTS) \
	  || { s=$$?; [ $$status -ne 0 ] || status=$$s; }; \
	$(PY) scripts/test_summary.py out/test/serial.xml out/test/mpi.xml || { [ $$status -ne 0 ] || status=1; }; \
	exit $$status

# The same suite on Debian 13 (DOLFINx 0.9, Python 3.13, numpy 2): a debootstrap root cached in /var/cache/soro
# (built once in 2.5-10 min; rebuilt when stale), the project installed there by bootstrap.sh, then `make test`.
.PHONY: test-trixie
test-trixie:
	@bash scripts/test-trixie.sh

# The peers of the beam benchmarks: MuJoCo from the optional group 'peers' (PyElastica gets its own venv);
# without network the MuJoCo comparison says it is missing and is skipped.
bench: bootstrap
	-@$(PY) -m pip install -q --disable-pip-version-check --no-build-isolation -c $(VENV)/constraints.txt -e '.[peers]' \
	  || echo "make bench: could not install MuJoCo (pip install -e '.[peers]'); its comparison will be skipped"
	$(PY) -m pytest -m bench tests/benchmarks -s $(PYTEST_OPTS)

# Build the container image (docker, or podman where no Docker engine runs) and run the suite inside it.
container-test:
	@bash docker/container-test.sh

clean:
	rm -rf out .pytest_cache

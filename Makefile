# Two commands do all set-up on a fresh machine:
#   make demo   flatten the built-in Surf1 mesh (writes demo/)
#   make test   run the test suite
VENV  := .venv
STAMP := $(VENV)/.springflat-installed

.PHONY: demo test test-fast paper bench clean

$(STAMP): pyproject.toml scripts/setup.sh
	bash scripts/setup.sh
	touch $@

demo: $(STAMP)
	@mkdir -p demo
	$(VENV)/bin/springflat flatten surf1 --out demo/surf1.obj --history demo/surf1.csv --plot demo/surf1.png
	@echo "wrote demo/surf1.obj, demo/surf1.csv, demo/surf1.png"

# One pytest worker per core (pytest-xdist; a worker more than the cores was measured no faster),
# each with one BLAS/OpenMP thread, so that two workers do not start a pool of threads each on two
# cores. A test file stays on one worker, so its module fixtures run once, and files start in
# collection order, the longest first (tests/support: LONGEST_FIRST). Exports and simulator
# builds shared across files are cached under build/ behind file locks
# (sim.cocotb_support.build_lock). The slowest tests are listed at the end, so a CI log shows where
# its time goes.
PYTEST := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \
	$(VENV)/bin/python -m pytest -n auto --dist loadfile --no-loadscope-reorder --durations=25

test: $(STAMP)
	$(PYTEST)

# The edit-test loop: everything but the tests marked slow (simulators, synthesis, sweeps).
# CI runs `make test`, all of them.
test-fast: $(STAMP)
	$(PYTEST) -m "not slow"

paper: $(STAMP)
	$(VENV)/bin/springflat paper --out paper-report

bench: $(STAMP)
	$(VENV)/bin/python benchmarks/bench_engines.py

clean:
	rm -rf $(VENV) demo paper-report .pytest_cache build *.egg-info

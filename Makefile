# The two commands of the README. Each one sets itself up first (scripts/bootstrap.sh).
PY := .venv/bin/python
VERIFY := .venv/bin/mjed-verify

# The oracle on a current dolfinx (PyPI wheel, .venv-modern; scripts/bootstrap-modern.sh).
# -p dolfinx_solver loads the wheel's MPI before any test module imports dolfinx.
MODERN_PY := .venv-modern/bin/python
MODERN_TESTS := tests/test_compat.py tests/test_oracle_mapping.py tests/test_equivalence_oracle.py tests/test_mpi.py \
	tests/test_viscous.py tests/test_darcy.py tests/test_porous.py tests/test_adapters_felupe.py tests/test_user_energy.py \
	tests/test_compiled.py tests/test_compiled_classical.py tests/test_compiled_oracle.py

# Test workers (pytest-xdist, installed by both bootstraps): one per core by default; each test
# module runs whole on one worker (--dist loadfile), so a module's fixtures (its kits, compiled
# fields, oracle runs) are built once. `make test WORKERS=0` runs the suite in one process.
WORKERS ?= auto
PARALLEL := $(if $(filter 0,$(WORKERS)),,-n $(WORKERS) --dist loadfile)

.PHONY: demo test test-debian test-sweep lint bootstrap bootstrap-modern test-modern cross-release docs

bootstrap:
	@bash scripts/bootstrap.sh

# The main job: every study, one self-contained report in reports/latest/index.html.
# The modern dolfinx stack is set up first so that the cross-release study can run; where it
# cannot be installed (exit 3), the report says that study was not fully run.
# Exit code: 0 every check passed completely, 1 a check failed, 3 a target missed or something
# not run (the report is written in every case). `make demo ARGS=--quick` is the small,
# partial version (exit 3 by design).
demo: bootstrap
	@bash scripts/bootstrap-modern.sh || [ $$? -eq 3 ]
	$(VERIFY) all $(ARGS)

# The test suite: everything on Debian's dolfinx 0.5.2 (oracle tests serial and on 2 MPI
# ranks), then the oracle tests on dolfinx 0.11 and the cross-release check (a loud NOT RUN
# banner if that stack cannot be installed here; scripts/test-modern-leg.sh).
test: test-debian
	@bash scripts/test-modern-leg.sh

# Only the Debian leg (the quick loop while developing), after the lint gate.
test-debian: lint
	$(PY) -m pytest -q $(PARALLEL)

# The full sweeps: the tests marked `sweep` (cross products whose every code path `make test`
# already checks, skipped there; docs/tests.md, "Full sweeps"), on the Debian stack.
test-sweep: bootstrap
	$(PY) -m pytest -q $(PARALLEL) --sweep -m sweep

# The lint and format gate (ruff, configured in pyproject.toml: 100 characters, Google-style
# docstrings, sorted imports). `ruff format .` and `ruff check --fix .` repair most of it.
lint: bootstrap
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

bootstrap-modern:
	@bash scripts/bootstrap-modern.sh

# The oracle's tests (compat layer, numbering, equivalence with MJED, 2 MPI ranks) on dolfinx 0.11.
test-modern: bootstrap-modern
	$(MODERN_PY) -m pytest -p dolfinx_solver -q $(PARALLEL) $(MODERN_TESTS)

# The same oracle cases on both stacks, serial and on 2 ranks, compared to 1e-12.
cross-release: bootstrap bootstrap-modern
	$(PY) -m comparisons.cross_release check --json reports/cross_release.json

# The documentation site (Sphinx + MyST, offline): docs/_build/html/index.html. The tutorials
# are executed during the build and kept in docs/_build/tutorials until their sources change.
docs: bootstrap
	$(PY) -m sphinx -b html -q docs docs/_build/html -d docs/_build/doctrees
	@echo "site: docs/_build/html/index.html"

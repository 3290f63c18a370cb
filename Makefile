# The two commands of the README. Each one sets itself up first (scripts/bootstrap.sh).
PY := .venv/bin/python
VERIFY := .venv/bin/mjed-verify

.PHONY: demo test bootstrap

bootstrap:
	@bash scripts/bootstrap.sh

# The main job: the equivalence study on the built-in meshes.
demo: bootstrap
	$(VERIFY) equivalence --material all --mesh all --json reports/equivalence.json

# The test suite, oracle tests included (dolfinx comes from Debian).
test: bootstrap
	$(PY) -m pytest -q

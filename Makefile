# Two commands on a fresh machine (see README):
#   make demo   installs everything into .venv/ and runs the main job
#   make test   installs everything into .venv/ and runs the tests
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
PYTHON ?= $(shell scripts/find-python.sh)

.PHONY: demo test install bench clean

$(PY):
	@test -n "$(PYTHON)" || { echo "no Python >= 3.12: see the message above" >&2; exit 1; }
	$(PYTHON) -m venv $(VENV)

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[all,dev]'
	@touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/edem verify quick --out results/verify/quick

test: $(STAMP)
	@scripts/ensure-chromium.sh
	$(PY) -m pytest -q -m "not slow"

bench: $(STAMP)
	$(PY) benchmarks/bench_edem.py
	$(PY) benchmarks/bench_whole_run.py
	$(PY) benchmarks/bench_fine_mesh.py
	$(PY) benchmarks/bench_raycast.py
	$(PY) benchmarks/bench_thin_layer.py
	$(PY) benchmarks/bench_factorisations.py
	$(PY) benchmarks/bench_step_vs_cast.py --floor
	$(PY) benchmarks/bench_vtk_read.py
	$(PY) benchmarks/bench_campaign_throughput.py sensitivity population-coupled

clean:
	rm -rf $(VENV) results .pytest_cache

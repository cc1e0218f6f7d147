# soilvolume: the two commands a fresh machine needs are `make setup` and `make test`.
VENV    := .venv
PY      := $(VENV)/bin/python
PYTEST  := QT_QPA_PLATFORM=offscreen $(VENV)/bin/pytest

.PHONY: setup test test-engine test-qgis lint demo bench bench-full accuracy accuracy-quick calibration calibration-quick readme-figures package deploy clean

setup:  ## install Debian packages (QGIS LTR, Chromium), the venv and the wheels (idempotent)
	bash scripts/setup.sh

test: lint  ## lint and format check, then the whole test suite: engine, PDAL pipelines, QGIS algorithms headless
	$(PYTEST) -q -p no:cacheprovider tests

test-engine:
	$(PYTEST) -q -p no:cacheprovider tests --ignore=tests/qgis

test-qgis:
	$(PYTEST) -q -p no:cacheprovider tests/qgis

lint:   ## ruff lint and ruff format --check (CI runs it through make test)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

demo:   ## seeded synthetic pair with known volumes, whole pipeline, estimated vs true
	$(VENV)/bin/soilvolume demo --out demo_out

bench:  ## benchmark: the paper pair beside CloudCompare and the read floor (interleaved, medians), then the 1M/4M ladder
	$(PY) bench/versus.py
	$(PY) bench/run_bench.py

bench-full:  ## adds the 16M and 64M pairs
	$(PY) bench/run_bench.py --full

accuracy:  ## accuracy harness (issue 10): seeded matrix + real pairs vs targets, rewrites bench/ACCURACY.md
	$(PY) bench/accuracy.py

accuracy-quick:  ## ~1 minute subset of the accuracy harness (bench/results/accuracy-quick.md)
	$(PY) bench/accuracy.py --quick

calibration:  ## held-out random sites (issue 53, ~15-30 min): interval coverage, verdict confusion, worst sites; rewrites bench/CALIBRATION.md
	$(PY) bench/calibration.py

calibration-quick:  ## the first 20 held-out random sites (bench/results/calibration-quick.md)
	$(PY) bench/calibration.py --quick

readme-figures:  ## run the real pairs with default options and rewrite README.md's generated table of their volumes
	$(PY) scripts/readme_figures.py

package:  ## installable plugin zip in dist/
	bash scripts/package.sh

deploy:  ## link the working tree into the local QGIS profile
	bash scripts/deploy.sh

clean:
	rm -rf dist build demo_out .pytest_cache .ruff_cache

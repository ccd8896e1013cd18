# Two commands do everything on a fresh Debian machine with Python 3.11:
#   make run   - the dataset, the whole SLAM run and the executed tutorial as a book (build/html/index.html)
#   make test  - lint, unit tests and notebook regression tests (nbval)
# Both create .venv and install what is missing first.

PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# Debian package : shared library it provides (checked with ldconfig)
SYSDEPS := libusb-1.0-0:libusb-1.0.so.0 libosmesa6:libOSMesa.so.8

.PHONY: run test robustness lint notebooks html sysdeps browser setup clean data

# OpenMP threads (Open3D, small_gicp) spin after each parallel call and starve numpy's unless told to
# sleep; it must be set before Open3D loads, so here rather than in the package (13 % faster registration).
# Lower case: libgomp compares it in the user's locale, and in Turkish "PASSIVE" does not read as passive.
export OMP_WAIT_POLICY ?= passive

# The suite runs in TEST_WORKERS processes (pytest-xdist), each test file whole in one of them: a notebook's
# cells share one kernel, a module's fixtures are built once. Most tests hold one core, so two workers on two
# cores take make test from 12 to about 8 minutes. TEST_WORKERS=0 runs it in this process.
TEST_WORKERS ?= 2
PYTEST := $(VENV)/bin/pytest -n $(TEST_WORKERS) --dist loadfile

run: $(STAMP)
	$(PY) -m helpers dataset --out build/dataset
	$(PY) -m helpers run --out build/run
	$(PY) -m helpers site --out build/html

test: $(STAMP) browser
	$(VENV)/bin/ruff check helpers tests benchmarks
	$(VENV)/bin/ruff format --check helpers tests benchmarks
	$(PYTEST)

# The tests hold on any machine and still bite: the whole suite again on
# other lidar noise and one thread, then one-line mutants of the pipeline
# that the suite must catch (tests/mutants.py). CI runs it after make test.
# The book's browser tests read the committed notebooks, not the noise: make
# test runs them once.
robustness: $(STAMP)
	HELPERS_NOISE_SEED=1 OMP_NUM_THREADS=1 $(PYTEST) --ignore=tests/test_site.py --ignore=tests/test_interactive_views.py
	$(PY) tests/mutants.py

setup: $(STAMP)

# JupyterLab on the notebooks with the project's settings (jupyter/: no build prompt, conftest.py hidden, the
# kernels' OpenMP and Open3D variables); JupyterLab refuses to run as root without --allow-root.
.PHONY: lab
lab: $(STAMP)
	JUPYTER_CONFIG_PATH=$(CURDIR)/jupyter $(VENV)/bin/jupyter lab $$([ "$$(id -u)" = 0 ] && echo --allow-root) notebooks/

# data/: the default flight in the reference's file formats (aerialMap.tar.gz, gTruthWayPoints.mat), written
# by the package; tests/test_datafiles.py fails when the committed files and the package disagree.
data: $(STAMP)
	$(PY) -m helpers.sim.reference_files data

$(STAMP): environment.txt pyproject.toml | sysdeps
	@command -v $(PYTHON) >/dev/null || { echo "error: $(PYTHON) not found; install Python 3.11 (Debian: apt-get install python3.11 python3.11-venv)" >&2; exit 1; }
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r environment.txt
	$(PY) -m pip install --quiet --no-deps -e .
	touch $(STAMP)

sysdeps:
	@missing=""; for dep in $(SYSDEPS); do \
	  pkg=$${dep%%:*}; lib=$${dep#*:}; \
	  ldconfig -p 2>/dev/null | grep -q "$$lib" || missing="$$missing $$pkg"; \
	done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    echo "installing Debian packages:$$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing >/dev/null; \
	  else \
	    echo "error: missing Debian package(s):$$missing; run: sudo apt-get install$$missing" >&2; exit 1; \
	  fi; \
	fi

# Debian's Chromium, for the tests that open the book in a headless browser
# (tests/test_site.py); those tests alone are skipped, with their reason,
# where Chromium cannot be installed.
browser:
	@command -v chromium >/dev/null || { \
	  if [ "$$(id -u)" = 0 ]; then \
	    echo "installing Debian's chromium for the browser tests of the book"; \
	    { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium fonts-dejavu-core >/dev/null; } \
	      || echo "warning: chromium could not be installed; the browser tests of the book will be skipped" >&2; \
	  else \
	    echo "note: no chromium (sudo apt-get install chromium); the browser tests of the book will be skipped" >&2; \
	  fi; }

clean:
	rm -rf build data/cache .pytest_cache

# Both targets create (or reuse) the virtual environment in .venv.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup lint browser promtool node test demo paper bench schema clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

# An editable install leaves fcso and fcsod uncompiled, and where
# PYTHONDONTWRITEBYTECODE is set every command would compile them again.
setup: $(STAMP)
	@$(PY) -m compileall -q fcso fcsod >/dev/null

# ruff's rules and format are in pyproject.toml
lint: setup
	$(VENV)/bin/ruff check fcso fcsod tests benchmarks examples docs/images
	$(VENV)/bin/ruff format --check fcso fcsod tests benchmarks examples docs/images

# the report's 3D view is tested in a real headless browser: Debian's Chromium, installed when missing
browser:
	@command -v chromium >/dev/null || command -v chromium-browser >/dev/null || \
		(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium)

# the daemon's metrics are checked by Prometheus' own linter: promtool from Debian's prometheus, installed when missing
promtool:
	@command -v promtool >/dev/null || \
		(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends prometheus)

# the live Foxglove server is tested with Foxglove's reference client (npm's @foxglove/ws-protocol, which the test
# installs into build/npm): Node.js and npm from Debian, installed when missing
node:
	@command -v node >/dev/null && command -v npm >/dev/null || \
		(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends nodejs npm)

# pytest exits 5 when it collected no tests: that is a failure here. The test files run on every core
# (at most 4 workers); a file's tests stay on one worker, which builds its module fixtures once.
# The ten slowest tests are listed at the end: where a slow CI machine spends its time.
test: setup lint browser promtool node
	$(PY) -m pytest -q --numprocesses=auto --maxprocesses=4 --dist loadfile --durations=10; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "pytest collected no tests: failing"; exit 1; fi; \
	exit $$rc

# the daemon on a temporary watch folder with the bundled batch; outputs in demo-out/daemon/out
demo: setup
	$(PY) -m examples.demo_daemon

# the paper's experiment (METHOD §10) on the bundled bunny; outputs in demo-out/paper
paper: setup
	$(VENV)/bin/fcso design examples/parts/stanford_bunny_closed.ply --scale-to 65 \
		--config examples/paper.toml --out demo-out/paper

# every benchmarks/bench_*.py, one after the other, printing its figures
bench: setup
	@for module in $(basename $(notdir $(wildcard benchmarks/bench_*.py))); do \
		echo "== benchmarks.$$module"; $(PY) -m benchmarks.$$module || exit 1; done

schema: setup
	$(VENV)/bin/fcso schema --out schemas/
	$(VENV)/bin/fcsod schema --out schemas/

clean:
	rm -rf $(VENV) *.egg-info demo-out

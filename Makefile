# Everything a fresh clone needs: `make demo`, `make test`, `make bench`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-fast lint lint-fix coverage bench install broker browser ffmpeg systemd node clean pi-check

# pip shows its progress: the first install downloads numpy, scipy, OpenCV and friends
$(STAMP): pyproject.toml
	@echo "installing moi and its dependencies into $(VENV) (about a minute on a fresh clone)..."
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --progress-bar on -e '.[test,lint]'
	@# the Sparkplug tests' host application decodes with pysparkplug, an implementation independent of ours;
	@# it pins paho-mqtt below 2 for its own client, which the tests do not use: installed without that pin
	$(PY) -m pip install --quiet --no-deps 'pysparkplug>=0.6.1,<0.7'
	@touch $(STAMP)
	@echo "moi is installed in $(VENV)"

install: $(STAMP)

# Components of the suite from Debian, each installed when missing and we are root (scripts/component.sh):
# otherwise their tests skip with a note, and under CI=true the step fails. The MQTT tests start their own
# Mosquitto on a free loopback port and read it with mosquitto's own clients (the TLS test makes its CA with
# openssl and its passwords with mosquitto_passwd); the browser test drives headless Chromium with its chromedriver; the vision tests encode
# rendered videos to H.264 with FFmpeg (real codec artefacts).
broker:
	@$(SHELL) scripts/component.sh "MQTT tests" "mosquitto mosquitto-clients openssl" mosquitto mosquitto_passwd mosquitto_sub mosquitto_pub openssl

# Independent protocol clients from the npm registry, run by Debian's Node.js: each tests/node/<client>/ holds a
# package.json and its package-lock.json (node-opcua in opcua/, Eclipse Tahu's Sparkplug B codec in sparkplug/). Installed again when
# the lock file changes; the tests that need one are skipped without it, and fail under CI=true.
NODE_LOCKS := $(wildcard tests/node/*/package-lock.json)
NODE_STAMPS := $(NODE_LOCKS:package-lock.json=node_modules/.installed)
node: $(NODE_STAMPS)
tests/node/%/node_modules/.installed: tests/node/%/package-lock.json
	@command -v npm >/dev/null 2>&1 || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && \
	  (apt-get install -y -qq nodejs npm >/dev/null 2>&1 || \
	   (apt-get update -qq >/dev/null && apt-get install -y -qq nodejs npm >/dev/null)); } || true
	@cd tests/node/$* && npm ci --ignore-scripts --no-audit --no-fund --loglevel=error && touch node_modules/.installed || \
	  { echo "note: npm could not install tests/node/$*; its tests will be skipped (with CI=true this fails the run)"; test "$$CI" != true; }

browser:
	@$(SHELL) scripts/component.sh "browser test" "chromium chromium-driver" chromium chromedriver

ffmpeg:
	@$(SHELL) scripts/component.sh "H.264 video tests" ffmpeg ffmpeg

# the unit file's test runs systemd-analyze verify on it
systemd:
	@$(SHELL) scripts/component.sh "unit file check" systemd systemd-analyze

demo: $(STAMP)
	$(VENV)/bin/moi demo

# One run on four workers (pytest-xdist, a test file per worker): the computations keep the cores busy while
# the tests marked `clock` (servers, threads and a simulated rig in wall-clock time; see tests/conftest.py) wait
# on their peers, so each of those must pass on a loaded machine (no test waits on a time; each awaits a
# condition). Under coverage (pytest-cov), and the product's coverage is held to the floor (fail_under in
# pyproject.toml). `make test-fast`: the same run without the coverage tracer, for a quick local check; `pytest
# -m clock` runs the clock tests alone (to try them under a busy loop on each core).
WORKERS ?= 4
test: COVERAGE = --cov --cov-report=
test test-fast: $(STAMP) broker browser ffmpeg systemd node
	@rm -f .coverage .coverage.*
	@$(PY) -m pytest -q -n $(WORKERS) --dist loadfile $(COVERAGE); status=$$?; \
	if [ -n "$(COVERAGE)" ]; then echo "coverage of the product: $$($(PY) -m coverage report --format=total --fail-under=0) % (floor: fail_under in pyproject.toml; per file: make coverage)"; fi; \
	exit $$status

# the coverage of the last `make test`, file by file
coverage: $(STAMP)
	$(PY) -m coverage report --skip-covered

# ruff (pyflakes, bugbear, pyupgrade...) and mypy, configured in pyproject.toml, over the whole tree
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy

# ruff's mechanical fixes for the rule families added to the gates (import order, pytest style, SIM, RUF100)
lint-fix: $(STAMP)
	tools/lint_autofix.sh

bench: $(STAMP)
	$(PY) bench/run.py

# Installs moi in an emulated Debian arm64 root (the Pi's architecture) as systemd/README.md says and
# checks it computes the J this machine computes. Needs root; slow (emulation); not part of `make test`.
pi-check: $(STAMP)
	sh scripts/pi-check.sh

clean:
	rm -rf $(VENV) build *.egg-info

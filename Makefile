# Two commands do all set-up on a fresh machine (README):
#   make demo   - print the bundled sample on the emulator, write the media and a job report
#   make test   - install the test dependencies and run the whole suite
# and for working on it:
#   make test-fast   - the suite without the tests marked slow, system or gui (the inner loop)
#   make lint        - ruff and mypy against tools/lint-baseline.json, which may only shrink
#   make wheel-check - build the wheel, install it into a fresh venv outside the checkout and
#                      print, rip, compare and run the acceptance suite from it (CI runs it)
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    := out
SAMPLE := resources/samples/sample.tif
# the IPP Everywhere Printer Application (docs/ipp.md): C against PAPPL (libpappl-dev)
IPP_BIN := app/ipp/wideprint-ipp
IPP_SRC := app/ipp/wideprint-ipp.c
# avahi for the DNS-SD test (tests/support/private_mdns.py): Debian's avahi-daemon and avahi-utils
# unpacked, not installed - the test runs its own daemon in private namespaces and the
# machine gets no mDNS service of its own (docs/ipp.md "DNS-SD")
AVAHI  := build/avahi/.unpacked
AOT    := build/aot.stamp

.PHONY: demo test test-fast wheel-check install bench clean bytecode kernels lint lint-baseline

# __init__.py holds the version: an editable install's metadata is written at install
$(STAMP): setup.cfg pyproject.toml constraints.txt __init__.py
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -c constraints.txt -e '.[test,gui]'
	touch $(STAMP)

# the numba kernels compiled ahead of time into rip/_aot*.so and device_sim/_aot*.so, so no
# command imports numba or waits for its cache (tools/build_kernels.py: build tooling, not in
# the package; docs/rip.md "Compiled kernels"); built again whenever a source of those packages
# changes (until then they run on numba's JIT)
$(AOT): $(STAMP) $(wildcard rip/*.py rip/*/*.py device_sim/*.py device_sim/*/*.py) tools/build_kernels.py
	$(BIN)/python tools/build_kernels.py
	@mkdir -p build && touch $@

$(IPP_BIN): $(IPP_SRC)
	@pkg-config --exists pappl || { echo "make: $(IPP_BIN) needs PAPPL: apt-get install libpappl-dev pkg-config (resources/debian-packages.txt; .ci/run installs them)" >&2; exit 1; }
	$(CC) -Wall -Wextra -O2 -o $@ $< $$(pkg-config --cflags --libs pappl) -ltiff -lpthread

$(AVAHI):
	@command -v apt-get >/dev/null && command -v dpkg-deb >/dev/null || { echo "make: the DNS-SD test needs Debian's avahi-daemon and avahi-utils packages (apt-get download)" >&2; exit 1; }
	rm -rf build/avahi && mkdir -p build/avahi/deb
	cd build/avahi/deb && apt-get download -q avahi-daemon avahi-utils 2>&1 | grep -v '^W: Download is performed unsandboxed' || true
	@ls build/avahi/deb/avahi-daemon_*.deb build/avahi/deb/avahi-utils_*.deb >/dev/null || { echo "make: apt-get download avahi-daemon avahi-utils failed (run apt-get update?)" >&2; exit 1; }
	for deb in build/avahi/deb/*.deb; do dpkg-deb -x $$deb build/avahi; done
	touch $@

# wideprint's own modules byte-compiled: an editable install leaves them as sources, and where
# PYTHONDONTWRITEBYTECODE is set (CI, containers) every command would compile them again at
# start-up (~0.2 s of each `wideprint print`); compileall skips what is up to date
bytecode: $(STAMP) $(AOT)
	$(BIN)/python -m compileall -q app driver device_sim rip __init__.py >/dev/null

kernels: $(AOT)

install: $(STAMP) $(IPP_BIN) bytecode
	@# a CUPS server here: its driverless queues pass TIFF and PDF unchanged (docs/ipp.md)
	@if [ -x /usr/sbin/cupsd ] && [ -d "$${CUPS_SERVERROOT:-/etc/cups}" ]; then \
	  $(BIN)/wideprint cups install || echo "make: wideprint cups install failed (run it as root)" >&2; fi

demo: $(STAMP) bytecode
	mkdir -p $(OUT)
	$(BIN)/wideprint print $(SAMPLE) --device emulator --media-out $(OUT)/media.tif \
	    --report $(OUT)/report.json --event-log $(OUT)/events.jsonl \
	    --preview $(OUT)/media.png
	$(BIN)/wideprint rip $(SAMPLE) -o $(OUT)/planes.tif
	$(BIN)/python -m wideprint.app.compare $(OUT)/media.tif $(OUT)/planes.tif
	@echo "demo: media $(OUT)/media.tif (picture $(OUT)/media.png), report $(OUT)/report.json, events $(OUT)/events.jsonl"

test: $(STAMP) $(IPP_BIN) $(AVAHI) bytecode
	$(BIN)/python -m pytest -q -p no:cacheprovider

# the markers (setup.cfg [tool:pytest], assigned in tests/conftest.py): slow (measured),
# system (a real cupsd, avahi, network namespaces), gui (Qt)
FAST := not slow and not system and not gui
test-fast: $(STAMP) $(IPP_BIN) bytecode
	$(BIN)/python -m pytest -q -p no:cacheprovider -m "$(FAST)"

# ruff and mypy (configuration: pyproject.toml); a file's findings may not grow beyond its count
# in tools/lint-baseline.json, nor the strict modules' beyond none (tools/lint.py)
lint: $(STAMP)
	$(BIN)/python tools/lint.py

# after fixing findings: lower the baseline's counts to what is found now (it never raises one)
lint-baseline: $(STAMP)
	$(BIN)/python tools/lint.py --update

# the package as a packager installs it (.ci/wheel-check): not the checkout's .venv
wheel-check: $(IPP_BIN)
	PYTHON=$(PYTHON) bash .ci/wheel-check

bench: $(STAMP) $(AOT) bytecode
	$(BIN)/python bench/run.py

clean:
	rm -rf $(OUT) .pytest_cache $(IPP_BIN) $(AOT) rip/_aot.* device_sim/_aot.* build/mypy-cache build/typecheck

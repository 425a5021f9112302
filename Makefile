# Every target creates and uses .venv itself: a fresh machine needs only python3.11, make and git.
PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
VDMCHECK_VERSION := 1.1.3
VDMCHECK_DIR := tools/vdmcheck

.PHONY: all venv fmus demo test test-fast lint bench vdmcheck crosscheck clean

all: test

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

fmus: $(STAMP)
	$(BIN)/ipcosim build

# VDMCheck2 (FMI 2 static checker) from Maven Central; skipped where Java or Maven is absent.
vdmcheck:
	@if [ -f $(VDMCHECK_DIR)/.ok ]; then exit 0; fi; \
	if command -v java >/dev/null 2>&1 && command -v mvn >/dev/null 2>&1; then \
	  mkdir -p $(VDMCHECK_DIR) && \
	  mvn -q dependency:copy -Dartifact=org.into-cps.vdmcheck.fmi2:vdmcheck2:$(VDMCHECK_VERSION):zip:distribution-static \
	      -DoutputDirectory=$(VDMCHECK_DIR) && \
	  (cd $(VDMCHECK_DIR) && unzip -qo vdmcheck2-$(VDMCHECK_VERSION)-distribution-static.zip) && touch $(VDMCHECK_DIR)/.ok \
	  || echo "vdmcheck: download failed; VDMCheck tests will be skipped"; \
	else echo "vdmcheck: java/mvn not found; VDMCheck tests will be skipped"; fi

demo: fmus
	$(BIN)/ipcosim run single-mass-lqr --plot --out out/demo
	@echo "out/demo/metrics.json:" && cat out/demo/metrics.json

lint: $(STAMP)
	$(BIN)/ruff check .

# The tests run on every core (pytest-xdist; --dist loadfile keeps a file's tests on one worker, so its module
# fixtures are made once); the FMUs are built here once and the tests' own build reuses them (tests/conftest.py).
XDIST := -n auto --dist loadfile

# What CI runs: every test. The real-time tests (marker realtime: runs paced at 1 kHz, judged by how late their
# steps start) run after the parallel pass, serially, so that no other worker's load is on the cores they
# are judged on. Both passes always run; the target fails if either did.
test: fmus vdmcheck lint
	$(BIN)/python -m pytest $(XDIST) -m "not realtime" --durations=20; parallel=$$?; \
	$(BIN)/python -m pytest -m realtime --durations=20; serial=$$?; \
	test $$parallel -eq 0 -a $$serial -eq 0

# Before each commit: every test but the slow, real-time and cross-platform ones, on every core.
test-fast: fmus
	$(BIN)/python -m pytest $(XDIST) -m "not slow and not realtime and not cross" --durations=20

# Every benchmark, then benchmarks/last.json; `python -m benchmarks.docs --update` writes the docs' figures from it.
bench: fmus
	$(BIN)/ipcosim build --native
	$(BIN)/ipcosim build --native --fmi 3
	$(BIN)/python -m benchmarks.bench

# The FMUs of both flavours with reference results in the FMI cross-check layout, checked by fmpy.cross_check.
crosscheck: $(STAMP)
	$(BIN)/ipcosim build --native
	$(BIN)/ipcosim build --native --fmi 3
	$(BIN)/python -m evidence.fmi_crosscheck build/crosscheck

clean:
	rm -rf build out

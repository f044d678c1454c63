# A newcomer needs only Python 3.11 and make.
PYTHON ?= python3.11
VENV   ?= .venv
PY     := $(VENV)/bin/python
OUT    ?= out

.PHONY: demo test lint format bench bench-demux bench-mc bench-viewer bench-mitsuba browser llvm clean venv

venv: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $@

demo: venv
	$(VENV)/bin/planeray demo --out $(OUT)

# The browser tests (tests/test_viewer_browser.py) drive the system's chromium through Playwright;
# nothing ever downloads a browser.  As root (CI) a missing chromium is installed with apt.
browser:
	@if command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || [ -n "$$PLANERAY_CHROMIUM" ]; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing chromium for the browser tests (apt-get install chromium)"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	else \
		echo "note: no chromium, so the browser tests will be skipped; install it (Debian: sudo apt-get install chromium)"; \
	fi

# Mitsuba's llvm variants (planeray render: the one-pass tally) need LLVM >= 16 at run time; Debian 12
# ships 14/15 by default.  As root (CI) libllvm19 is installed with apt; without it planeray renders
# row by row in Mitsuba's scalar variant (slower) and the one-pass tests are skipped.
llvm:
	@if ls /usr/lib/x86_64-linux-gnu/libLLVM.so.19* /usr/lib/x86_64-linux-gnu/libLLVM-19* /usr/lib/llvm-19/lib/libLLVM* 2>/dev/null | grep -q . || [ -n "$$DRJIT_LIBLLVM_PATH" ]; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing libllvm19 for Mitsuba's llvm variants (apt-get install libllvm19)"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >/dev/null; \
	else \
		echo "note: no LLVM >= 16, so planeray render falls back to row-by-row scalar rendering; install it (Debian: sudo apt-get install libllvm19)"; \
	fi

# Independent tests run in parallel on every core (pytest-xdist; worksteal balances the slow ones).
test: venv browser llvm
	$(PY) -m pytest -q -n auto --dist worksteal

lint: venv
	$(VENV)/bin/ruff check src tests benchmarks tools
	$(VENV)/bin/ruff format --check src tests benchmarks tools

format: venv
	$(VENV)/bin/ruff check --fix src tests benchmarks tools
	$(VENV)/bin/ruff format src tests benchmarks tools

bench: venv
	$(PY) benchmarks/bench_render.py --size 512

bench-demux: venv
	$(PY) benchmarks/bench_demux.py --pixels 384 --large 512

bench-viewer: venv browser
	$(PY) benchmarks/bench_viewer.py --sizes 128 512

bench-mitsuba: venv llvm
	$(PY) benchmarks/bench_render_mitsuba.py --size 64 --rows 720 --spp 64

bench-mc: venv
	$(PY) benchmarks/bench_mc.py --plot $(OUT)/mc_vs_mitsuba.png

clean:
	rm -rf $(VENV) $(OUT) build src/*.egg-info .pytest_cache

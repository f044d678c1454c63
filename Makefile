# A newcomer needs only Python 3.11 and make.
PYTHON ?= python3.11
VENV   ?= .venv
PY     := $(VENV)/bin/python
OUT    ?= out

.PHONY: demo test docs wheel-check lint format bytecode kernels bench bench-demux bench-mc bench-viewer bench-mitsuba bench-pulse-memory browser llvm xvfb aravis clean venv

venv: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $@

# An editable install leaves planeray's own modules uncompiled (pip byte-compiles a regular install), and
# where PYTHONDONTWRITEBYTECODE is set nothing ever writes them: every test worker, subprocess and Dask
# worker then compiled every module it imported (measured: make test 363 -> 344 s).  Compiled here once;
# compileall redoes only the modules changed since.  The same holds for pytest's rewrite of the asserts of
# the test modules (tools/rewrite_tests.py: ~2.5 s of each test worker's start).
bytecode: venv
	@$(PY) -m compileall -q src >/dev/null
	@$(PY) tools/rewrite_tests.py conftest.py tests/test_*.py

# planeray's Numba kernels (demultiplexer, band renderer, Monte Carlo engines) compile on first call, 4-10 s
# each; from an empty cache every test worker, Dask worker and subprocess that needs one at the same moment
# compiled it (measured: make test 350 -> 411 s).  Compiled here once, a process per group (~19 s on 2 cores),
# into Numba's cache beside each module; again only when a kernel's module changes.
KERNEL_SOURCES := $(shell grep -rl --include='*.py' 'numba.njit' src/planeray) src/planeray/_jit.py
KERNELS_STAMP := src/planeray/__pycache__/kernels.stamp
kernels: $(KERNELS_STAMP)
$(KERNELS_STAMP): $(VENV)/.installed $(KERNEL_SOURCES)
	@$(PY) -m planeray._jit
	@mkdir -p $(@D) && touch $@

demo: venv bytecode kernels
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

# The projector tests (tests/test_projector.py, tests/test_rig.py) start their own two-screen Xvfb and never
# touch the user's display.  As root (CI) a missing Xvfb is installed with apt (with libXtst, for the key presses).
xvfb:
	@if command -v Xvfb >/dev/null 2>&1; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing Xvfb for the projector tests (apt-get install xvfb libxtst6)"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq xvfb libxtst6 >/dev/null; \
	else \
		echo "note: no Xvfb, so the projector and rig tests will be skipped; install it (Debian: sudo apt-get install xvfb)"; \
	fi

# The GenICam driver (--device genicam) and its tests use Aravis's fake camera through PyGObject: Debian's
# gir1.2-aravis-0.8, and PyGObject built into the venv against the system's gobject-introspection (its build
# needs libgirepository1.0-dev, libcairo2-dev and pkg-config).  As root (CI) they are installed with apt and pip;
# otherwise a note says what to install and the GenICam tests are skipped.
ARAVIS_STAMP := $(VENV)/.aravis
aravis: $(ARAVIS_STAMP)
$(ARAVIS_STAMP): $(VENV)/.installed
	@if [ -e /usr/lib/x86_64-linux-gnu/girepository-1.0/Aravis-0.8.typelib ] || ls /usr/lib/*/girepository-1.0/Aravis-0.8.typelib >/dev/null 2>&1; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing Aravis for the GenICam tests (apt-get install gir1.2-aravis-0.8 libgirepository1.0-dev libcairo2-dev pkg-config)"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq gir1.2-aravis-0.8 libgirepository1.0-dev \
			libcairo2-dev pkg-config >/dev/null; \
	fi
	@if $(PY) -c "import gi; gi.require_version('Aravis', '0.8')" >/dev/null 2>&1; then touch $@; \
	elif ls /usr/lib/*/girepository-1.0/Aravis-0.8.typelib >/dev/null 2>&1 && pkg-config --exists gobject-introspection-1.0 cairo 2>/dev/null; then \
		echo "building PyGObject into $(VENV) (pip install -e '.[genicam]')"; \
		$(PY) -m pip install --quiet -e ".[genicam]" && touch $@; \
	else \
		echo "note: no Aravis, so the GenICam tests will be skipped; install it (Debian: sudo apt-get install gir1.2-aravis-0.8 libgirepository1.0-dev libcairo2-dev pkg-config, then $(PY) -m pip install -e '.[genicam]')"; \
	fi

# Independent tests run in parallel, a worker per core (pytest-xdist, conftest.py; worksteal balances the
# slow ones).
test: venv bytecode kernels browser llvm xvfb aravis
	$(PY) -m pytest -q -n auto --dist worksteal

# The documentation site: docs/ -> docs/_build/html (open docs/_build/html/index.html), offline, warnings as
# errors, then opened in chromium by tests/test_docs_site.py.  The equations need MathJax: it is installed
# (pinned) from the npm registry into docs/_build/mathjax and served from the site itself, never from a CDN.
MATHJAX_VERSION := 3.2.2
MATHJAX := docs/_build/mathjax/node_modules/mathjax/es5/tex-chtml.js
SPHINXOPTS ?= -j 2

docs: venv browser $(MATHJAX)
	$(VENV)/bin/sphinx-build -W --keep-going -q $(SPHINXOPTS) -b html docs docs/_build/html
	PLANERAY_DOCS_SITE=docs/_build/html $(PY) -m pytest -q -p no:cacheprovider tests/test_docs_site.py
	@$(PY) tools/gallery_times.py docs/_build/html

$(MATHJAX):
	@if ! command -v npm >/dev/null 2>&1 && [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing npm to fetch MathJax for the docs (apt-get install npm)"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq npm >/dev/null; fi
	@command -v npm >/dev/null 2>&1 || { echo "make docs: npm is needed to install MathJax for the site (Debian: sudo apt-get install npm)"; exit 1; }
	@mkdir -p docs/_build/mathjax
	@npm install --prefix docs/_build/mathjax --no-audit --no-fund --no-save --loglevel=error --fetch-retries=1 \
		--fetch-timeout=60000 mathjax@$(MATHJAX_VERSION) >docs/_build/mathjax/npm.log 2>&1 \
		|| { echo "make docs: could not install MathJax $(MATHJAX_VERSION) from the npm registry (offline? see docs/_build/mathjax/npm.log)"; exit 1; }

# What a user of the package index gets: the wheel and the sdist built as an index would (python -m build, in an
# isolated environment), the wheel installed alone (no extras) into a fresh venv, and the newcomer's commands run
# from it outside the source tree: planeray --version, python -m planeray demo.
WHEEL_CHECK := build/wheel-check
wheel-check: venv
	rm -rf $(WHEEL_CHECK) && mkdir -p $(WHEEL_CHECK)
	$(PY) -m build --sdist --wheel --outdir $(WHEEL_CHECK)/dist . >$(WHEEL_CHECK)/build.log 2>&1 \
		|| { tail -20 $(WHEEL_CHECK)/build.log; exit 1; }
	$(PYTHON) -m venv $(WHEEL_CHECK)/venv
	$(WHEEL_CHECK)/venv/bin/python -m pip install --quiet $(WHEEL_CHECK)/dist/planeray-*.whl
	cd $(WHEEL_CHECK) && venv/bin/planeray --version && venv/bin/python -m planeray demo --out d
	@tar -tzf $(WHEEL_CHECK)/dist/planeray-*.tar.gz | grep -q '/LICENSE$$' || { echo "the sdist lacks LICENSE"; exit 1; }
	@echo "wheel-check: $$(ls $(WHEEL_CHECK)/dist) install and run from a fresh venv"

lint: venv
	$(VENV)/bin/ruff check conftest.py src tests benchmarks tools docs/conf.py docs/_ext docs/_plots docs/examples
	$(VENV)/bin/ruff format --check conftest.py src tests benchmarks tools docs/conf.py docs/_ext docs/_plots docs/examples

format: venv
	$(VENV)/bin/ruff check --fix conftest.py src tests benchmarks tools docs/conf.py docs/_ext docs/_plots docs/examples
	$(VENV)/bin/ruff format conftest.py src tests benchmarks tools docs/conf.py docs/_ext docs/_plots docs/examples

bench: venv
	$(PY) benchmarks/bench_render.py --size 512

bench-demux: venv
	$(PY) benchmarks/bench_demux.py --pixels 384 --large 512

bench-viewer: venv browser
	$(PY) benchmarks/bench_viewer.py --sizes 128 512
	$(PY) benchmarks/bench_view_live.py --size 512

bench-mitsuba: venv llvm
	$(PY) benchmarks/bench_render_mitsuba.py --size 64 --rows 720 --spp 64

bench-mc: venv
	$(PY) benchmarks/bench_mc.py --plot $(OUT)/mc_vs_mitsuba.png

# skin pulse on a 30 s 1080p video: peak memory (and ~8 GB of temporary files in the system's temp folder)
bench-pulse-memory: venv
	$(PY) benchmarks/bench_pulse_memory.py

clean:
	rm -rf $(VENV) $(OUT) build dist src/*.egg-info .pytest_cache docs/_build docs/auto_examples docs/reference/api/generated \
		docs/reference/api/backreferences docs/reference/api/index.rst docs/reference/cli_commands.rst docs/sg_execution_times.rst

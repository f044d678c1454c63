# A newcomer needs only Python 3.11 and make.
PYTHON ?= python3.11
VENV   ?= .venv
PY     := $(VENV)/bin/python
OUT    ?= out

.PHONY: demo test lint format bench bench-demux bench-mc clean venv

venv: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $@

demo: venv
	$(VENV)/bin/planeray demo --out $(OUT)

test: venv
	$(PY) -m pytest -q

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

bench-mc: venv
	$(PY) benchmarks/bench_mc.py --plot $(OUT)/mc_vs_mitsuba.png

clean:
	rm -rf $(VENV) $(OUT) build src/*.egg-info .pytest_cache

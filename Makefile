# Two commands that work on a fresh clone: `make demo` and `make test`.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-slow bench notebooks docs install clean

$(STAMP): pyproject.toml
	# Mitsuba's vectorized llvm_* variants need LLVM >= 17 for Dr.Jit (Debian 12's default LLVM 14/15 aborts):
	# libllvm19 where apt-get can install it (as root); elsewhere the render tests run the scalar variants
	@if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && ! ls /usr/lib/*/libLLVM.so.19* >/dev/null 2>&1; then \
		apt-get install -y -q libllvm19 >/dev/null 2>&1 || (apt-get update -q >/dev/null 2>&1 && apt-get install -y -q libllvm19 >/dev/null 2>&1) \
		|| echo "libllvm19 not installed: Mitsuba renders use the scalar variants"; fi
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test,readers,render,cube,docs]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	mkdir -p out
	# main job: fit the shipped (synthetic, labelled) calibration series of a varnish over a red paint
	$(PY) examples/fit_calibration_series.py
	$(PY) -m layerstack_cli fit examples/calibration_fit.toml examples/calibration_series.csv -g 45/0 --joint --background background --sigma 0.002 -o out/calibration_fit.json --plot out/calibration_fit.png
	$(PY) -m layerstack_cli predict examples/varnished_painting.toml --wavelengths 380:780:5 --geometry 45/0 -o out/varnished_painting_45-0.csv --plot out/varnished_painting_45-0.png
	$(PY) -m layerstack_cli predict examples/thin_film_on_metal.toml --wavelengths 380:780:5 --geometry specular:30 -o out/thin_film_on_metal.csv --plot out/thin_film_on_metal.png
	# design: a four-layer broadband AR coating from database materials (exit 1 if its targets are not met)
	$(PY) -m layerstack_cli design examples/ar_coating_design.toml -o out/ar_design.toml --plot out/ar_design.png

test: $(STAMP)
	$(PY) -m pytest -n 2 -q

test-slow: $(STAMP)
	$(PY) -m pytest -n 2 -q -m slow

bench: $(STAMP)
	# peers: the CPU build of torch first (never the CUDA one), then tmm-fast without deps
	$(PY) -m pip install -q torch==2.13.0 && $(PY) -m pip install -q --no-deps tmm-fast || echo "tmm-fast unavailable: reported as missing"
	$(PY) -m pip install -q tmm-faster jaxlayerlumos || echo "some peers unavailable: reported as missing"
	$(PY) -m benchmarks
	$(PY) -m benchmarks.fitting_cases
	$(PY) -m benchmarks.design_case

notebooks: $(STAMP)
	# each notebooks/NN_*.py read by jupytext, executed by nbclient on an ipykernel kernel; writes NN_*.md and figures/
	$(PY) notebooks/execute.py

docs: $(STAMP)
	# the site from mkdocs.yml: pages under docs/, the API reference from the docstrings (mkdocstrings)
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict -d site

clean:
	rm -rf $(VENV) out site .pytest_cache .hypothesis

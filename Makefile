# Two entry points: `make demo` and `make test` (see README). Both create .venv and install
# everything the project needs, including the Debian packages below when run as root.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
# the Khronos glTF-Validator (npm), used by the glTF export test; project-local, not global
NPM_PREFIX := .npm
GLTF_VALIDATOR := $(NPM_PREFIX)/node_modules/gltf-validator/package.json
GLTF_VALIDATOR_VERSION := 2.0.0-dev.3.10
# three.js (npm), the engine of the three.js round trip (tests/evaluation/test_engines_threejs.py,
# bench/bench_engines_threejs.py): served from .npm/ to headless Chromium, offline
THREE := $(NPM_PREFIX)/node_modules/three/package.json
THREE_VERSION := 0.187.0
# esbuild (npm): bundles three + OrbitControls + GLTFLoader + the report's viewer into one
# classic script (threejs_page/vendor/viewer.bundle.js, committed; tools/build_viewer_bundle.py)
ESBUILD := $(NPM_PREFIX)/node_modules/esbuild/package.json
ESBUILD_VERSION := 0.28.2
DEBIAN_PACKAGES := libllvm19 chromium glslang-tools
# Blender as a Python module (bpy, PyPI) for the engine round trips
# (brdffit.evaluation.engines.blender): its own venv, because bpy pins numpy < 2 and needs
# CPython 3.11 exactly; the project runs it in a subprocess. About 375 MB to download,
# about 1 GB installed.
BLENDER_VENV := .venv-blender
BLENDER_STAMP := $(BLENDER_VENV)/.installed-stamp
BPY_VERSION := 5.0.1

.PHONY: demo test bench sysdeps npmdeps blender install clean

demo: $(STAMP)
	$(VENV)/bin/brdffit demo

# the suite on 2 processes (pytest-xdist): most tests are single-threaded Python; 1.46x
# faster than one process on the 2-core machine (docs/design/testing.md)
TEST_WORKERS ?= 2
test: $(STAMP) npmdeps blender
	$(PY) -m pytest -q -n $(TEST_WORKERS)

bench: $(STAMP) blender
	$(PY) bench/run_all.py
	$(PY) bench/readme.py

install: $(STAMP) blender

$(STAMP): pyproject.toml
	@$(MAKE) --no-print-directory sysdeps
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev,engines]'
	@$(MAKE) --no-print-directory npmdeps
	@touch $(STAMP)

blender: $(BLENDER_STAMP)

# bpy needs CPython 3.11 (its wheels are cp311 only): without one, the Blender round trips
# are skipped and say so
$(BLENDER_STAMP):
	@if $(PYTHON) -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then \
		$(PYTHON) -m venv $(BLENDER_VENV) && \
		$(BLENDER_VENV)/bin/python -m pip install -q --upgrade pip && \
		$(BLENDER_VENV)/bin/python -m pip install -q 'bpy==$(BPY_VERSION)' && touch $(BLENDER_STAMP); \
	else echo "NOTE: $(PYTHON) is not CPython 3.11, skipping bpy (the Blender round trips will be skipped)"; fi

# libllvm19: Mitsuba 3's LLVM back-end (the machine's default LLVM crashes it).
# chromium: the report test renders the HTML report headless.
# glslang-tools: the export test compiles the generated GLSL (glslangValidator).
sysdeps:
	@missing=""; for p in $(DEBIAN_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -z "$$missing" ]; then echo "Debian packages present: $(DEBIAN_PACKAGES)"; \
	elif [ "$$(id -u)" = 0 ]; then echo "Installing Debian packages:$$missing"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; \
	else echo "NOTE: not root, skipping Debian packages:$$missing (rendering and report tests will be skipped)"; fi

# gltf-validator, three and esbuild into .npm/ (need node and npm: present in the machine
# image; when npm is missing and we are root, Debian's nodejs + npm are installed first). All
# are installed (again) when gltf-validator is absent or three or esbuild is not at its version.
NPM_PACKAGES := gltf-validator@$(GLTF_VALIDATOR_VERSION) three@$(THREE_VERSION) esbuild@$(ESBUILD_VERSION)
npmdeps:
	@if [ -f $(GLTF_VALIDATOR) ] && grep -q '"version": "$(THREE_VERSION)"' $(THREE) 2>/dev/null \
		&& grep -q '"version": "$(ESBUILD_VERSION)"' $(ESBUILD) 2>/dev/null; then \
		echo "gltf-validator, three@$(THREE_VERSION) and esbuild@$(ESBUILD_VERSION) present in $(NPM_PREFIX)/"; \
	else if ! command -v npm >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
		echo "Installing Debian packages: nodejs npm"; apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive apt-get install -y -qq nodejs npm >/dev/null; fi; \
	if command -v npm >/dev/null 2>&1; then echo "Installing $(NPM_PACKAGES) into $(NPM_PREFIX)/"; \
		npm install --prefix $(NPM_PREFIX) --no-audit --no-fund --no-save --silent \
			$(NPM_PACKAGES) || echo "NOTE: npm install failed (the glTF validation, three.js and viewer bundle tests will be skipped)"; \
	else echo "NOTE: npm not found, skipping $(NPM_PACKAGES) (the glTF validation, three.js and viewer bundle tests will be skipped)"; fi; fi

clean:
	rm -rf $(VENV) $(BLENDER_VENV) build *.egg-info src/*.egg-info .pytest_cache $(NPM_PREFIX)

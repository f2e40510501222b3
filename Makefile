# Two entry points: `make demo` and `make test` (see README). Both create .venv and install
# everything the project needs, including the Debian packages below when run as root.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
DEBIAN_PACKAGES := libllvm19 chromium glslang-tools

.PHONY: demo test bench sysdeps install clean

demo: $(STAMP)
	$(VENV)/bin/brdffit demo

test: $(STAMP)
	$(PY) -m pytest -q

bench: $(STAMP)
	$(PY) bench/run_all.py

install: $(STAMP)

$(STAMP): pyproject.toml
	@$(MAKE) --no-print-directory sysdeps
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev]'
	@touch $(STAMP)

# libllvm19: Mitsuba 3's LLVM back-end (the machine's default LLVM crashes it).
# chromium: the report test renders the HTML report headless.
# glslang-tools: the export test compiles the generated GLSL (glslangValidator).
sysdeps:
	@missing=""; for p in $(DEBIAN_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -z "$$missing" ]; then echo "Debian packages present: $(DEBIAN_PACKAGES)"; \
	elif [ "$$(id -u)" = 0 ]; then echo "Installing Debian packages:$$missing"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; \
	else echo "NOTE: not root, skipping Debian packages:$$missing (rendering and report tests will be skipped)"; fi

clean:
	rm -rf $(VENV) build *.egg-info src/*.egg-info .pytest_cache

# The two commands in the README: `make demo` (main job on the built-in default) and `make test`.
PYTHON ?= python3
export XDG_RUNTIME_DIR ?= /tmp/gma-xdg-$(shell id -u)
# Anny's cache defaults to ~/.cache/gma/anny in the code (gma/body/anny_body.py); set ANNY_CACHE_DIR to move it.
# LAVAPIPE=backports (e.g. `make install LAVAPIPE=backports`, or with demo/test/bench) also installs, on Debian 12
# or 13, the backports' faster lavapipe for this user beside the system's (scripts/lavapipe_backport.py).
LAVAPIPE ?= system

.PHONY: install demo test lint bench

install:
	@mkdir -p $(XDG_RUNTIME_DIR) && chmod 700 $(XDG_RUNTIME_DIR)
	@LAVAPIPE=$(LAVAPIPE) bash scripts/install.sh

demo: install
	$(PYTHON) -m gma.cli demo --out out/demo

test: install
	$(PYTHON) -m pytest tests -q --durations=20

lint:
	$(PYTHON) -m ruff check gma viewer tests benchmarks
	lint-imports
	$(PYTHON) -m deptry .

bench: install
	$(PYTHON) benchmarks/render.py

# Two commands do everything on a fresh machine: `make render` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY      = $(VENV)/bin/python
STAMP   = $(VENV)/.installed

.PHONY: render test install bench previews clean wheel

$(PY):
	$(PYTHON) -m venv $(VENV)

# uv (a Rust installer, itself from PyPI) fetches, unpacks and byte-compiles the
# dependencies in parallel: 21 s on a fresh machine of this kind against pip's 34.
# Byte-compiled at install because this machine kind sets PYTHONDONTWRITEBYTECODE=1:
# nothing would be compiled later, every import would compile from source. Should uv
# be unavailable, pip does the same (compileall -j 0: pip compiles on one core). The
# tree's own modules too: a stale .pyc is ignored, never wrong.
SITE = $(shell $(PY) -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")
$(STAMP): pyproject.toml | $(PY)
	($(PY) -m pip install -q uv && $(PY) -m uv pip install -q --python $(PY) --compile-bytecode -e ".[test]") \
	|| ($(PY) -m pip install -q --upgrade pip && $(PY) -m pip install -q --no-compile -e ".[test]" \
	    && $(PY) -m compileall -q -j 0 "$(SITE)" > /dev/null)
	$(PY) -m compileall -q -j 0 cli anim raycore > /dev/null
	touch $(STAMP)

install: $(STAMP)

## Install, then render the demo animation (shipped in the package: anim/builtin/demo/) to out/.
render: $(STAMP)
	$(VENV)/bin/frustrace render anim/builtin/demo/anim.yaml -o out --overwrite

## Install with test extras, then run the test suite on every core (pytest-xdist; a file per
## worker at a time, so that a file's fixtures are made once; the numba cache is shared).
test: $(STAMP)
	$(PY) -m pytest -n auto --dist loadfile

## Build the installable wheel: dist/frustrace-*.whl (the demo scene inside; what workers install).
wheel: $(STAMP)
	rm -rf dist build
	$(PY) -m pip wheel --no-deps -q -w dist .

## Measure fps per phase on every built-in scene.
bench: $(STAMP)
	$(VENV)/bin/frustrace bench

## Regenerate the README's preview images of the built-in scenes (rendered by frustrace).
SCENES = hand runner toys marbles fairy field
previews: $(STAMP)
	for s in $(SCENES); do \
	  $(VENV)/bin/frustrace assets make $$s -o out/assets/$$s --overwrite --preview assets/previews/$$s.png || exit 1; \
	done

clean:
	rm -rf out dist build $(VENV) *.egg-info

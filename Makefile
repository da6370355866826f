# Two commands do everything on a fresh machine: `make render` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY      = $(VENV)/bin/python
STAMP   = $(VENV)/.installed

.PHONY: render test install bench clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install -q -e ".[test]"
	touch $(STAMP)

install: $(STAMP)

## Install, then render the demo animation in assets/ to out/.
render: $(STAMP)
	$(VENV)/bin/frustrace render assets/demo/anim.yaml -o out --overwrite

## Install with test extras, then run the test suite.
test: $(STAMP)
	$(PY) -m pytest

## Measure fps per phase on the demo animation.
bench: $(STAMP)
	$(VENV)/bin/frustrace bench

clean:
	rm -rf out $(VENV) *.egg-info

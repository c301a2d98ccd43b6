# Two commands for a fresh machine (see README):  make demo   and   make test
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
INSTALLED := $(VENV)/.installed

.PHONY: demo test install lock clean

# The virtual environment is rebuilt whenever the lock file or the package metadata changes.
$(INSTALLED): requirements.lock pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet --no-deps -r requirements.lock
	$(BIN)/pip install --quiet --no-deps -e .
	touch $@

install: $(INSTALLED)

# The whole pipeline, small enough for a laptop (about 2 minutes on 2 cores): real envs against the
# paper's random scores, noise-distilled histories, a short training run, in-context evaluation,
# report. Re-running resumes: collection and training skip what is done. Outputs under demo/.
DEMO := demo
demo: $(INSTALLED)
	$(BIN)/vintix tasks
	$(BIN)/vintix check-envs --episodes 5
	$(BIN)/vintix demonstrator list
	$(BIN)/vintix collect --recipe tiny --out $(DEMO)/data
	$(BIN)/vintix data plot $(DEMO)/data --out $(DEMO)/figs
	$(BIN)/vintix train --config tiny --data $(DEMO)/data --out $(DEMO)/run \
		--set max_steps=30 --set window_len=500 --set batch_size=4 --set warmup_steps=5 --set log_every=5
	$(BIN)/vintix eval --checkpoint $(DEMO)/run --tasks reach-v3,button-press-v3 --shots 5 --seeds 2 --out $(DEMO)/results
	$(BIN)/vintix report $(DEMO)/results --out $(DEMO)/report

test: $(INSTALLED)
	$(BIN)/python -m pytest -q

# Re-resolve dependencies from pyproject.toml into requirements.lock (needs the package index).
lock:
	rm -rf /tmp/vintix-lock && $(PYTHON) -m venv /tmp/vintix-lock
	/tmp/vintix-lock/bin/pip install --quiet torch==2.13.0 -e '.[dev]'
	/tmp/vintix-lock/bin/pip install --quiet --no-deps industrial-benchmark-python==2.0
	{ sed -n '1,/^torch==/p' requirements.lock | sed '$$d'; \
	  /tmp/vintix-lock/bin/pip freeze --exclude-editable | sed 's/^torch==\(.*\)+cpu/torch==\1/'; } > requirements.lock.new
	mv requirements.lock.new requirements.lock

clean:
	rm -rf $(VENV) build src/*.egg-info $(DEMO)

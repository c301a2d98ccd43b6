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

# Watch the shipped model (src/vintix/agent/pretrained/cpu-suite, trained on the CPU suite by the
# commands in its TRAINING.md) learn in context: cold-start many-shot runs on Meta-World goals, Industrial
# Benchmark seeds and MuJoCo seeds it never saw in training, plus a held-out setpoint; a per-shot table
# of normalized scores, then a report with curves. No training. Outputs under demo/.
DEMO := demo
DEMO_TASKS := reach-v3,push-v3,button-press-v3,drawer-close-v3,door-open-v3,window-open-v3,industrial-benchmark-30-v1,industrial-benchmark-70-v1,industrial-benchmark-90-v1,Reacher-v5,Pusher-v5
demo: $(INSTALLED)
	$(BIN)/vintix eval --checkpoint cpu-suite --tasks $(DEMO_TASKS) --shots 10 --seeds 3 --first-seed 100 \
		--reference ours --label "Vintix cpu-suite" --out $(DEMO)/results
	$(BIN)/vintix report $(DEMO)/results --reference ours --plateau-shots 3 --out $(DEMO)/report

test: $(INSTALLED)
	$(BIN)/python -m pytest -q

# Re-resolve dependencies from pyproject.toml into requirements.lock (needs the package index).
lock:
	rm -rf /tmp/vintix-lock && $(PYTHON) -m venv /tmp/vintix-lock
	/tmp/vintix-lock/bin/pip install --quiet torch==2.13.0 -e '.[dev,cluster]'
	/tmp/vintix-lock/bin/pip install --quiet --no-deps industrial-benchmark-python==2.0
	{ sed -n '1,/^torch==/p' requirements.lock | sed '$$d'; \
	  /tmp/vintix-lock/bin/pip freeze --exclude-editable | sed 's/^torch==\(.*\)+cpu/torch==\1/'; } > requirements.lock.new
	mv requirements.lock.new requirements.lock

clean:
	rm -rf $(VENV) build src/*.egg-info $(DEMO)

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

# The reward-ablation test on the shipped models, cold start on goals and seeds training never used
# (README, "In-context RL"; docs/in-context-rl.md): each plays with the true rewards fed back, then with zeros; scores and
# success always come from the true returns. point-goal (the toy hidden-goal task) shows rewards doing
# the work, and icrl-reach (Meta-World reach) too: it probes in shot 1, then reaches the goal the rewards revealed;
# cpu-suite (Meta-World, Industrial Benchmark, MuJoCo) shows a model whose gain over shots does not
# come from rewards. Per-shot tables of score and success rate, then a report with the reward-use gap
# per task, under demo/. No training. Each eval runs on one thread, so a model's zero-reward eval runs
# beside its true-reward one on the second core (its table is printed after), and the numbers are the
# same as run one after the other.
DEMO := demo
DEMO_SUITE_TASKS := reach-v3,push-v3,industrial-benchmark-30-v1,industrial-benchmark-70-v1,industrial-benchmark-90-v1,Reacher-v5,Pusher-v5
# model:tasks:seeds
DEMO_RUNS := point-goal:point-goal-v1:20 icrl-reach:reach-v3:20 cpu-suite:$(DEMO_SUITE_TASKS):3
DEMO_EVAL := --shots 10 --first-seed 100 --reference ours
demo: $(INSTALLED)
	mkdir -p $(DEMO)/logs
	for run in $(DEMO_RUNS); do \
	  set -- $$(echo $$run | tr : ' '); \
	  $(BIN)/vintix eval --checkpoint $$1 --tasks $$2 --seeds $$3 $(DEMO_EVAL) --reward-input zero \
	    --label $$1 --out $(DEMO)/$$1/zero > $(DEMO)/logs/$$1-zero.log 2>&1 & zero=$$!; \
	  $(BIN)/vintix eval --checkpoint $$1 --tasks $$2 --seeds $$3 $(DEMO_EVAL) --reward-input true \
	    --label $$1 --out $(DEMO)/$$1/true || { wait $$zero; exit 1; }; \
	  wait $$zero; status=$$?; cat $(DEMO)/logs/$$1-zero.log; [ $$status -eq 0 ] || exit 1; \
	  $(BIN)/vintix report $(DEMO)/$$1/true $(DEMO)/$$1/zero --reference ours --plateau-shots 3 \
	    --out $(DEMO)/report/$$1 || exit 1; \
	done

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

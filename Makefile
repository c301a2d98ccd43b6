# Two commands for a fresh machine (see README):  make demo   and   make test
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
INSTALLED := $(VENV)/.installed

.PHONY: demo test test-fast install lock clean

# The virtual environment is rebuilt whenever the lock file or the package metadata changes.
$(INSTALLED): requirements.lock pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet --no-deps -r requirements.lock
	$(BIN)/pip install --quiet --no-deps -e .
	touch $@

install: $(INSTALLED)

# The reward-ablation test on the flagship, vintix-cpu, cold start on goals and seeds training never used (README;
# docs/in-context-rl.md): it plays with the true rewards fed back, then with zeros; scores and success always come
# from the true returns. Where the goal is hidden (Meta-World reach and pick-place, MuJoCo's Reacher-hidden) it
# probes in shot 1, then succeeds where its rewards pointed, and fails with zeros; where the goal is visible
# (Meta-World button-press, MuJoCo Pusher, Industrial Benchmark) it plays like its demonstrators either way. Beside
# it, vintix-cpu-meta (the flagship fine-tuned with the meta-RL tasks) on HalfCheetah-Vel, HalfCheetah-Dir and
# Ant-Dir, whose target velocity or direction only the rewards tell; the Dark Room model on AD^ε's 16 held-out goals
# and the Key-to-Door model on 16 held-out (key, door) pairs (the discrete benchmarks; their TRAINING.md); last, a
# model that learnt with no search written for its task, point-goal-dpt (DPT's target: a goal-aware expert's action
# behind random and then its own contexts) on 30 hidden goals of the toy task.
# Per-shot tables of score and success rate, then a report with the reward-use gap per task, under demo/; the last
# lines give each run's gap (true − zero) per domain with its CI and shots. No training. Each eval runs on one
# thread, so the zero-reward eval runs beside the true-reward one on the second core (its table is printed after),
# and the numbers are the same as run one after the other.
DEMO := demo
# name:model:tasks:seeds
DEMO_RUNS := hidden-goals:vintix-cpu:reach-v3,pick-place-v3,Reacher-hidden-v5:10 \
	visible-goals:vintix-cpu:button-press-v3,Pusher-v5,industrial-benchmark-30-v1:3 \
	meta-rl:vintix-cpu-meta:HalfCheetah-Vel-v5,HalfCheetah-Dir-v5,Ant-Dir-v5:5 \
	darkroom:darkroom:DarkRoom-heldout-v0:16 \
	keytodoor:keytodoor:KeyToDoor-heldout-v0:16 \
	dpt:point-goal-dpt:point-goal-v1:30
DEMO_EVAL := --shots 10 --first-seed 100 --reference ours
demo: $(INSTALLED)
	mkdir -p $(DEMO)/logs
	for run in $(DEMO_RUNS); do \
	  set -- $$(echo $$run | tr : ' '); \
	  $(BIN)/vintix eval --checkpoint $$2 --tasks $$3 --seeds $$4 $(DEMO_EVAL) --reward-input zero \
	    --label "$$2, $$1" --out $(DEMO)/$$1/zero > $(DEMO)/logs/$$1-zero.log 2>&1 & zero=$$!; \
	  $(BIN)/vintix eval --checkpoint $$2 --tasks $$3 --seeds $$4 $(DEMO_EVAL) --reward-input true \
	    --label "$$2, $$1" --out $(DEMO)/$$1/true || { wait $$zero; exit 1; }; \
	  wait $$zero; status=$$?; cat $(DEMO)/logs/$$1-zero.log; [ $$status -eq 0 ] || exit 1; \
	  $(BIN)/vintix report $(DEMO)/$$1/true $(DEMO)/$$1/zero --reference ours --plateau-shots 3 \
	    --out $(DEMO)/report/$$1 > $(DEMO)/logs/$$1-report.log 2>&1 || { cat $(DEMO)/logs/$$1-report.log; exit 1; }; \
	done; \
	echo "What the rewards do (true − zero fed back, 95 % CI; reports under $(DEMO)/report):"; \
	for run in $(DEMO_RUNS); do grep -h "^reward-use gap: " $(DEMO)/logs/$${run%%:*}-report.log; done

# One pytest worker per core (pytest-xdist), each test file on one worker (a file's fixtures are built once), the files
# in collection order, where tests/conftest.py puts the minutes-long end-to-end ones first (xdist's default order, most
# tests first, left those one-test files to run last, side by side with nothing). It ends with the 15 slowest tests.
TEST_WORKERS := -n auto --dist loadfile --no-loadscope-reorder
test: $(INSTALLED)
	$(BIN)/python -m pytest -q $(TEST_WORKERS) --durations=15

# Everything but the minutes-long end-to-end runs (tests marked slow): for the edit-test loop; CI runs make test.
test-fast: $(INSTALLED)
	$(BIN)/python -m pytest -q $(TEST_WORKERS) -m "not slow"

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

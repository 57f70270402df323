# Two commands do all the set-up: `make run` (the default experiment) and `make test`.
VENV   ?= .venv
PY     := $(VENV)/bin/python
# The CPU build of torch: from the local wheel store when the machine has one, else PyTorch's CPU index.
TORCH_FROM := $(if $(wildcard /opt/wheels/torch-2.13.0+cpu*),--find-links /opt/wheels,--index-url https://download.pytorch.org/whl/cpu)

.PHONY: run test bench clean default-checkpoint
run: $(VENV)/.installed
	$(PY) train/run.py $(ARGS)

# the suite on two workers (pyproject's pytest options: -n 2, pytest-xdist)
test: $(VENV)/.installed
	$(PY) -m pytest

# checkpoints/default.pt, the default run's final state that the README's examples load: latest.pt of the default
# run (train/run.py without arguments), remade whenever the runner's config or learning changes
# (tests/test_default_checkpoint.py fails until it is)
DEFAULT_RUN := runs/default-checkpoint
default-checkpoint: $(VENV)/.installed
	rm -rf $(DEFAULT_RUN)
	$(PY) train/run.py --out $(DEFAULT_RUN)
	cp $(DEFAULT_RUN)/checkpoints/latest.pt checkpoints/default.pt

# Every bench in turn, with --record: each rewrites its block of BENCHMARKS.md (and generalization.py and
# trial_strip.py their tracked PNGs; a bench run by hand without --record rewrites nothing tracked). The first that
# fails stops the rest, and make fails. record.py, cli_args.py and memory_reference.py are modules the benches import.
# MiniSom is the SOM bench's peer, pinned: its defaults (decay schedules) are what that bench matches.
# episode_speed.py also runs the default experiment at an older commit (git worktree) for its speed ratio.
BENCH_MODULES := benches/record.py benches/cli_args.py benches/memory_reference.py
bench: $(VENV)/.installed
	$(PY) -m pip install -q "minisom==2.3.6"
	set -e; for b in $(filter-out $(BENCH_MODULES),$(wildcard benches/*.py)); do echo "== $$b"; $(PY) $$b --record; done

$(VENV)/.installed: pyproject.toml
	@echo "== setting up $(VENV): once, or again when pyproject.toml changes (a few minutes on a bare machine; the"
	@echo "   environment takes about 2.2 GB)"
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	@echo "== installing torch 2.13.0, CPU build (a 190 MB wheel: $(if $(findstring find-links,$(TORCH_FROM)),from /opt/wheels,downloaded from PyTorch's CPU index))"
	$(PY) -m pip install -q $(TORCH_FROM) "torch==2.13.0+cpu"
	@echo "== installing aesop-torch and what it needs (pybullet, the iCub model, tensorboard, Ray, pytest, ...)"
	$(PY) -m pip install -q -e ".[dev]"
	@echo "== $(VENV) is ready"
	touch $@

clean:
	rm -rf $(VENV)

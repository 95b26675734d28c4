# psyop: the two set-up commands are `make figures` and `make test`.
# Both bootstrap a local virtual environment (.venv) and any Debian packages they
# need on first use, so a fresh machine needs nothing else.

SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
SYSDEPS_STAMP := $(VENV)/.sysdeps-stamp
JOBS ?= $(shell nproc 2>/dev/null || echo 2)
export MPLBACKEND := Agg
export PYTHONHASHSEED := 0

.PHONY: figures test test-cross-cpu lint bench power power-run clean venv sysdeps help

help:
	@echo "make figures  - simulate sessions if data/ is empty, say which sessions are used, rebuild every figure and table"
	@echo "                (MIX=1: allow a study to pool simulated and real sessions;"
	@echo "                 POOL=1: pool a study's protocol versions; default: each analysed apart as <study>@<hash12>)"
	@echo "make resimulate - delete the simulated sessions in data/ (refused if any is real), then make figures"
	@echo "make test     - run make lint, then the whole test suite, then its cross_cpu tests with numpy and OpenBLAS narrowed to AVX2"
	@echo "make test-cross-cpu - only the tests that depend on the CPU's float kernels, with AVX-512 and narrowed to AVX2"
	@echo "make lint     - ruff over the repository, mypy over psyop/ (and lint-imports once pyproject.toml has a contract)"
	@echo "make bench    - run the benchmarks; results in bench/"
	@echo "make power    - power curves of the five shipped studies by simulation; results in power/"
	@echo "                (POWER_REPLICATIONS=N simulated studies per sample size, default $(POWER_REPLICATIONS))"
	@echo "make clean    - remove generated figures, results, benchmarks, power/, demo/ and the venv (never data/)"

venv: $(STAMP)

$(STAMP): pyproject.toml
	@echo "[psyop] setting up $(VENV) (first run only)"
	@test -x "$(PY)" || "$(PYTHON)" -m venv "$(VENV)"
	@"$(PY)" -m pip install -q --disable-pip-version-check --upgrade pip
	@"$(PY)" -m pip install -q --disable-pip-version-check -e '.[test]'
	@touch "$@"

# Debian packages: EGL/Mesa for headless rendering, Xvfb for the real-window test.
# Installed only when missing and only when we can (root + apt-get).
SYS_PACKAGES := libegl1 libgl1-mesa-dri libgles2 xvfb xauth
# how long apt-get waits for the apt/dpkg lock another process (unattended-upgrades) holds
APT_LOCK_WAIT_S ?= 300
sysdeps: $(SYSDEPS_STAMP)

$(SYSDEPS_STAMP): | $(STAMP)
	@missing=$$(for p in $(SYS_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || echo $$p; done); \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "[psyop] installing Debian packages: $$missing (waiting up to $(APT_LOCK_WAIT_S) s if another process holds the apt/dpkg lock)"; \
	    apt-get -o DPkg::Lock::Timeout=$(APT_LOCK_WAIT_S) update -qq && DEBIAN_FRONTEND=noninteractive \
	      apt-get -o DPkg::Lock::Timeout=$(APT_LOCK_WAIT_S) install -y -qq $$missing >/dev/null \
	      || { echo "[psyop] error: apt-get failed (the apt/dpkg lock still held after $(APT_LOCK_WAIT_S) s, or no network); rerun make once it is free"; exit 2; }; \
	  else echo "[psyop] warning: missing Debian packages ($$missing); install them with apt-get"; fi; \
	fi
	@touch "$@"

# ruff, mypy (cache in .mypy_cache, so a rerun checks only what changed) and the import-layering
# contract when pyproject.toml declares one; any finding fails make test (docs/architecture.md,
# "Types and lint").
lint: $(STAMP)
	"$(VENV)/bin/ruff" check .
	"$(VENV)/bin/mypy"
	@if grep -q '^\[tool.importlinter\]' pyproject.toml; then "$(VENV)/bin/lint-imports"; fi

# The tests whose results depend on the CPU's float kernels (marker cross_cpu) run a second time with numpy's
# SIMD dispatch and OpenBLAS's kernel narrowed to AVX2, so a machine with AVX-512 also checks the machines
# without it (and one without it repeats them); docs/architecture.md, "Reproducibility across CPUs".
# x86-64 only: the names are x86 kernels.
NARROW_CPU_ENV := NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR" OPENBLAS_CORETYPE=Haswell
ifeq ($(shell uname -m),x86_64)
CROSS_CPU_RUN = $(NARROW_CPU_ENV) "$(PY)" -m pytest -n $(TEST_JOBS) $(PYTEST_DIST) -q -m "cross_cpu and not bench" -p no:cacheprovider
else
CROSS_CPU_RUN = @echo "[psyop] not x86-64: the cross_cpu tests ran once, with this machine's kernels"
endif

# pytest workers: two more than the cores, since many tests wait on real time (real-clock sessions, the headset
# runtime, a Dask cluster, subprocesses) rather than compute. Each test module goes to one worker whole (--dist
# loadscope), so a module-scoped fixture (simulated studies, recorded sessions) is built once, not once per worker
# that runs one of its tests. Measured on 2 cores, one fresh clone, unloaded, back to back, 4 workers:
# 620.9 s with --dist worksteal, 518.5 s (1,003 CPU s) with --dist loadscope.
TEST_JOBS ?= $(shell echo $$(( $(JOBS) + 2 )))
PYTEST_DIST := --dist loadscope

test: lint $(STAMP) $(SYSDEPS_STAMP)
	"$(PY)" -m pytest -n $(TEST_JOBS) $(PYTEST_DIST) -q -m "not bench"
	$(CROSS_CPU_RUN)

# only the cross_cpu tests, both ways (the machine's widest kernels, then narrowed to AVX2)
test-cross-cpu: $(STAMP) $(SYSDEPS_STAMP)
	"$(PY)" -m pytest -n $(JOBS) -q -m "cross_cpu and not bench"
	$(CROSS_CPU_RUN)

bench: $(STAMP) $(SYSDEPS_STAMP)
	@mkdir -p bench
	"$(PY)" -m pytest -n $(JOBS) -q -m bench
	"$(PY)" -m benchmarks --out bench

# Power curves of the five shipped studies (psyop power: whole simulated studies through compile ->
# session -> analysis). Too slow for `make figures` (docs/adaptive.md says how long), so a target
# of its own. Sample sizes bracket each paper's (detection/discrimination 6, ordinal/realism 19,
# egocentric 13); one progress bar per protocol. Writes POWER/NAME/power.{csv,png,txt}; finished
# replications are kept in POWER/NAME/replications/, so an interrupted `make power` resumes.
POWER ?= power
POWER_REPLICATIONS ?= 40
POWER_SIZES := detection:4,6,12 discrimination:4,6,12 ordinal:6,12,19 egocentric:6,13,19 realism:6,12,19

power: $(STAMP) $(SYSDEPS_STAMP)
	@"$(MAKE)" --no-print-directory power-run

power-run:
	@i=0; for spec in $(POWER_SIZES); do \
	  i=$$((i + 1)); name=$${spec%%:*}; sizes=$${spec#*:}; mkdir -p "$(POWER)/$$name"; \
	  echo "[psyop] power $$i/5: protocols/$$name.yaml, $$sizes participants, $(POWER_REPLICATIONS) replications each"; \
	  "$(PY)" -m psyop power protocols/$$name.yaml --participants $$sizes --replications $(POWER_REPLICATIONS) \
	    --seed 0 --jobs $(JOBS) --out "$(POWER)/$$name" | tee "$(POWER)/$$name/.power.txt.tmp"; \
	  test $${PIPESTATUS[0]} -eq 0 -a $${PIPESTATUS[1]} -eq 0 || { rm -f "$(POWER)/$$name/.power.txt.tmp"; exit 1; }; \
	  mv -f "$(POWER)/$$name/.power.txt.tmp" "$(POWER)/$$name/power.txt"; \
	done; echo "[psyop] power curves in $(POWER)/ (NAME/power.png, power.csv, power.txt)"

include figures.mk

clean:
	rm -rf figures results bench power demo .psyop-power "$(VENV)" build *.egg-info .pytest_cache .hypothesis .mypy_cache .ruff_cache

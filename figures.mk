# Figure and table rules for `make figures` (included by Makefile).
#
# `make figures` first makes sure data/ holds sessions (simulating all five studies
# headless when it holds none), then runs a second make over the figure graph, so that
# the session files it lists exist when make reads them. Every figure or table is one
# analysis/ script; make's dependencies rebuild only what changed (new sessions, changed
# statistics or drawing code). The slow psychometric fits are cached in results/<study>_fits.csv.
# Every study in data/ is analysed by its response kind and its outputs carry its name.
# make decides what to rebuild; the scripts it lists then run in JOBS processes (analysis/batch.py
# runs make's dry run of figures-all, its independent parts side by side), so the statistics stack is
# imported once per process, not per script.
# `make figures-all` runs each script in a process of its own instead (same outputs).

# A recipe that fails (a full disk, a crash) leaves no target behind for the next make to trust:
# the scripts write atomically (psyop.atomic), and make deletes a target its failed recipe touched.
.DELETE_ON_ERROR:

DATA ?= data
RESULTS ?= results
FIGDIR ?= figures
# DATA may hold spaces (quoted in every recipe; its sessions are escaped by `psyop studies`);
# RESULTS and FIGDIR name make targets, which make cannot hold with spaces: refused here
ifneq ($(words $(RESULTS)) $(words $(FIGDIR)),1 1)
$(error RESULTS='$(RESULTS)' / FIGDIR='$(FIGDIR)': these folders are make targets and may not contain spaces; choose paths without spaces (DATA may have them))
endif
# POOL=1: analyse a study whose sessions ran different protocol versions (hashes) together, on purpose
ifeq ($(POOL),1)
export PSYOP_POOL_PROTOCOLS := 1
endif
# what runs an analysis script: the venv's python (analysis/batch.py sets it to its own marker)
ANALYSE ?= $(PY)
# `make -n`: show the real graph (the analysis commands), run nothing
DRY_RUN := $(findstring n,$(firstword -$(MAKEFLAGS)))

OPTICS_SRC := $(wildcard psyop/optics/*.py) psyop/figures/optics_figures.py psyop/figures/labels.py
# the gaze-quality measures and the quality: rules (load_dataset applies them: every study analysis reads them)
QUALITY_SRC := $(wildcard psyop/quality/*.py) psyop/protocol/quality.py
STATS_SRC := $(wildcard psyop/statistics/*.py) analysis/_common.py analysis/_twoafc.py $(QUALITY_SRC)
DRAW_SRC := $(STATS_SRC) psyop/figures/study_figures.py psyop/figures/labels.py
# each study's sessions (its trials.parquet files) are listed, escaped, by `psyop studies --make-rules`

MODEL_FIGURES := $(FIGDIR)/fig03_parallax_vs_eccentricity.png $(FIGDIR)/supp_linearity.png
TABLES := $(RESULTS)/summary.md
# Every study found in $(DATA)/ gets its figures by its response kind (`psyop studies`, which
# writes these rules and says what each study builds); outputs are named after the study.
STUDY_FIGURES :=
STUDIES_MK ?=
ifneq ($(STUDIES_MK),)
include $(STUDIES_MK)
endif

.PHONY: figures figures-data figures-build figures-all resimulate

figures: $(STAMP) $(SYSDEPS_STAMP)
	@"$(MAKE)" --no-print-directory figures-data
	@"$(MAKE)" --no-print-directory figures-build
	@# the measured timing of real (not simulated) sessions: psyop timing's summary and a figure each (docs/sessions.md "Timing")
	@"$(PY)" -m psyop timing "$(DATA)" --skip-simulated --out "$(FIGDIR)"
	@echo "[psyop] figures in $(FIGDIR)/, statistics in $(RESULTS)/ (summary: $(RESULTS)/summary.md)"

# Simulate only when no session has been logged yet; real data is never overwritten.
# Then say which sessions the figures use (per study: count, simulated or real) and refuse
# a study that mixes simulated and real sessions unless MIX=1.
figures-data: $(STAMP)
	@if find "$(DATA)" -name trials.parquet -print -quit 2>/dev/null | grep -q .; then \
	  echo "[psyop] using the sessions in $(DATA)/"; \
	else \
	  echo "[psyop] $(DATA)/ holds no sessions: simulating all five studies (marked simulated)"; \
	  "$(PY)" -m psyop simulate --data "$(DATA)" --protocols protocols --jobs $(JOBS); \
	fi
	@"$(PY)" -m psyop sessions "$(DATA)" $(if $(filter 1,$(MIX)),--allow-mixed) | sed 's/^/[psyop] /'; \
	  test $${PIPESTATUS[0]} -eq 0

# Re-simulate from scratch: only when every session in $(DATA)/ is simulated (real data is
# never deleted), remove them with the results and figures, then `make figures`.
resimulate: $(STAMP)
	@"$(PY)" -m psyop sessions "$(DATA)" --require-simulated --allow-mixed >/dev/null
	@echo "[psyop] removing the simulated sessions in $(DATA)/, $(RESULTS)/ and $(FIGDIR)/"
	@find "$(DATA)" -mindepth 1 -maxdepth 1 ! -name README.md -exec rm -rf {} + 2>/dev/null || true
	@rm -rf "$(RESULTS)" "$(FIGDIR)"
	@"$(MAKE)" --no-print-directory figures

# The study rules depend on what data/ holds, so they are written first (psyop studies), then a
# second make reads them: its dry run lists what is out of date and analysis/batch.py runs that in
# JOBS processes. `+` runs both under `make -n` too, so a dry run shows the real graph.
figures-build:
	+@"$(PY)" -m psyop studies "$(DATA)" --protocols protocols --make-rules "$(RESULTS)/.studies.mk"
ifeq ($(DRY_RUN),)
	+@"$(PY)" analysis/batch.py --jobs $(JOBS) "$(MAKE)" -n -s --no-print-directory figures-all STUDIES_MK="$(RESULTS)/.studies.mk"
else
	+@"$(MAKE)" --no-print-directory figures-all STUDIES_MK="$(RESULTS)/.studies.mk"
endif

figures-all: $(MODEL_FIGURES) $(STUDY_FIGURES) $(TABLES)

$(FIGDIR)/fig03_parallax_vs_eccentricity.png: analysis/fig03_parallax_vs_eccentricity.py $(OPTICS_SRC)
	@mkdir -p "$(FIGDIR)"
	@echo "[psyop] $@"
	@"$(ANALYSE)" "$<" --out "$@"

$(FIGDIR)/supp_linearity.png: analysis/supp_linearity.py $(OPTICS_SRC)
	@mkdir -p "$(FIGDIR)"
	@echo "[psyop] $@"
	@"$(ANALYSE)" "$<" --out "$@"

# The results table collects the JSON each figure script writes beside its figure: the paper's rows
# from the paper's protocols (by hash), every other study in results/<study>_summary.md.
$(RESULTS)/summary.md: analysis/results_table.py analysis/paper_values.py $(STUDY_FIGURES) $(STATS_SRC) $(wildcard protocols/*.yaml)
	@echo "[psyop] $@"
	@"$(ANALYSE)" "$<" --data "$(DATA)" --results "$(RESULTS)" --protocols protocols --out "$@"

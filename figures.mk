# Figure and table rules for `make figures` (included by Makefile).
#
# `make figures` first makes sure data/ holds sessions (simulating all five studies
# headless when it holds none), then runs a second make over the figure graph, so that
# the session files it lists exist when make reads them. Every figure or table is one
# analysis/ script; make's dependencies rebuild only what changed (new sessions, changed
# statistics or drawing code). The slow psychometric fits are cached in results/*_fits.csv.

# A recipe that fails (a full disk, a crash) leaves no target behind for the next make to trust:
# the scripts write atomically (psyop.atomic), and make deletes a target its failed recipe touched.
.DELETE_ON_ERROR:

DATA ?= data
RESULTS ?= results
FIGDIR ?= figures

OPTICS_SRC := $(wildcard psyop/optics/*.py) psyop/figures/optics_figures.py psyop/figures/labels.py
STATS_SRC := $(wildcard psyop/statistics/*.py) analysis/_common.py
DRAW_SRC := $(STATS_SRC) psyop/figures/study_figures.py psyop/figures/labels.py
trials_of = $(wildcard $(DATA)/$(1)/sub-*/ses-*/trials.parquet)

MODEL_FIGURES := $(FIGDIR)/fig03_parallax_vs_eccentricity.png $(FIGDIR)/supp_linearity.png
STUDY_FIGURES := $(FIGDIR)/detection_thresholds.png $(FIGDIR)/discrimination_thresholds.png \
	$(FIGDIR)/supp_psychometric_detection.png $(FIGDIR)/supp_psychometric_discrimination.png \
	$(FIGDIR)/ordinal_depth.png $(FIGDIR)/egocentric_reach.png $(FIGDIR)/realism_preferences.png
TABLES := $(RESULTS)/summary.md

.PHONY: figures figures-data figures-build resimulate

figures: $(STAMP) $(SYSDEPS_STAMP)
	@$(MAKE) --no-print-directory figures-data
	@$(MAKE) --no-print-directory figures-build
	@echo "[psyop] figures in $(FIGDIR)/, statistics in $(RESULTS)/ (summary: $(RESULTS)/summary.md)"

# Simulate only when no session has been logged yet; real data is never overwritten.
# Then say which sessions the figures use (per study: count, simulated or real) and refuse
# a study that mixes simulated and real sessions unless MIX=1.
figures-data: $(STAMP)
	@if find $(DATA) -name trials.parquet -print -quit 2>/dev/null | grep -q .; then \
	  echo "[psyop] using the sessions in $(DATA)/"; \
	else \
	  echo "[psyop] $(DATA)/ holds no sessions: simulating all five studies (marked simulated)"; \
	  $(PY) -m psyop simulate --data $(DATA) --protocols protocols --jobs $(JOBS); \
	fi
	@$(PY) -m psyop sessions $(DATA) $(if $(filter 1,$(MIX)),--allow-mixed) | sed 's/^/[psyop] /'; \
	  test $${PIPESTATUS[0]} -eq 0

# Re-simulate from scratch: only when every session in $(DATA)/ is simulated (real data is
# never deleted), remove them with the results and figures, then `make figures`.
resimulate: $(STAMP)
	@$(PY) -m psyop sessions $(DATA) --require-simulated --allow-mixed >/dev/null
	@echo "[psyop] removing the simulated sessions in $(DATA)/, $(RESULTS)/ and $(FIGDIR)/"
	@find $(DATA) -mindepth 1 -maxdepth 1 ! -name README.md -exec rm -rf {} + 2>/dev/null || true
	@rm -rf $(RESULTS) $(FIGDIR)
	@$(MAKE) --no-print-directory figures

figures-build: $(MODEL_FIGURES) $(STUDY_FIGURES) $(TABLES)

$(FIGDIR)/fig03_parallax_vs_eccentricity.png: analysis/fig03_parallax_vs_eccentricity.py $(OPTICS_SRC)
	@mkdir -p $(FIGDIR)
	@echo "[psyop] $@"
	@$(PY) $< --out $@

$(FIGDIR)/supp_linearity.png: analysis/supp_linearity.py $(OPTICS_SRC)
	@mkdir -p $(FIGDIR)
	@echo "[psyop] $@"
	@$(PY) $< --out $@

# Psychometric fit caches (the slow step), one per threshold study.
$(RESULTS)/%_fits.csv: analysis/fit_psychometric.py $(STATS_SRC)
	@mkdir -p $(RESULTS)
	@echo "[psyop] fitting psychometric functions: $*"
	@$(PY) $< --study $* --data $(DATA) --out $@ --n-jobs $(JOBS)

$(RESULTS)/detection_fits.csv: $(call trials_of,detection)
$(RESULTS)/discrimination_fits.csv: $(call trials_of,discrimination)

$(FIGDIR)/detection_thresholds.png: analysis/fig_detection_thresholds.py $(RESULTS)/detection_fits.csv $(DRAW_SRC)
	@mkdir -p $(FIGDIR)
	@echo "[psyop] $@"
	@$(PY) $< --data $(DATA) --fits $(RESULTS)/detection_fits.csv --results $(RESULTS) --out $@

$(FIGDIR)/discrimination_thresholds.png: analysis/fig_discrimination_thresholds.py $(RESULTS)/discrimination_fits.csv $(DRAW_SRC)
	@mkdir -p $(FIGDIR)
	@echo "[psyop] $@"
	@$(PY) $< --data $(DATA) --fits $(RESULTS)/discrimination_fits.csv --results $(RESULTS) --out $@

$(FIGDIR)/supp_psychometric_%.png: analysis/supp_psychometric_functions.py $(RESULTS)/%_fits.csv $(DRAW_SRC)
	@mkdir -p $(FIGDIR)
	@echo "[psyop] $@"
	@$(PY) $< --study $* --data $(DATA) --fits $(RESULTS)/$*_fits.csv --results $(RESULTS) --out $@

$(FIGDIR)/ordinal_depth.png: analysis/fig_ordinal_depth.py $(call trials_of,ordinal) $(DRAW_SRC)
	@mkdir -p $(FIGDIR)
	@echo "[psyop] $@"
	@$(PY) $< --data $(DATA) --results $(RESULTS) --out $@

$(FIGDIR)/egocentric_reach.png: analysis/fig_egocentric_reach.py $(call trials_of,egocentric) $(DRAW_SRC)
	@mkdir -p $(FIGDIR)
	@echo "[psyop] $@"
	@$(PY) $< --data $(DATA) --results $(RESULTS) --out $@

$(FIGDIR)/realism_preferences.png: analysis/fig_realism.py $(call trials_of,realism) $(DRAW_SRC)
	@mkdir -p $(FIGDIR)
	@echo "[psyop] $@"
	@$(PY) $< --data $(DATA) --results $(RESULTS) --out $@

# The results table collects the JSON each figure script writes beside its figure.
$(RESULTS)/summary.md: analysis/results_table.py analysis/paper_values.py $(STUDY_FIGURES) $(STATS_SRC)
	@echo "[psyop] $@"
	@$(PY) $< --data $(DATA) --results $(RESULTS) --out $@

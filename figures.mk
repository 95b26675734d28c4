# Figure and table rules for `make figures` (included by Makefile).
# Every figure is one analysis/ script; make's dependencies rebuild only what changed.

OPTICS_SRC := $(wildcard psyop/optics/*.py)
MODEL_FIGURES := figures/fig03_parallax_vs_eccentricity.png figures/supp_linearity.png

figures: $(MODEL_FIGURES)

figures/fig03_parallax_vs_eccentricity.png: analysis/fig03_parallax_vs_eccentricity.py $(OPTICS_SRC) | $(STAMP)
	@mkdir -p figures
	$(PY) $< --out $@

figures/supp_linearity.png: analysis/supp_linearity.py $(OPTICS_SRC) | $(STAMP)
	@mkdir -p figures
	$(PY) $< --out $@

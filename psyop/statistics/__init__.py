"""Statistics for psyop studies: tidy tables in, tidy tables or typed results out.

Modules (one job each):

- :mod:`psyop.statistics.dataset`: load every session's ``trials.parquet`` of a study.
- :mod:`psyop.statistics.psychometric`: nAFC and yes/no psychometric fits with psignifit 4.3 (the public
  fit API); a status per fit (censored thresholds are bounds, not numbers) and the rule analyses use
  (``usable_for_analysis``).
- :mod:`psyop.statistics.psignifit_grid`: the posterior-grid engine the fits run on (psignifit's pipeline,
  grid refinement, edge moves), over :mod:`~psyop.statistics.psignifit_posterior` (the model, vectorised)
  and :mod:`~psyop.statistics.posterior_modes` (MAP zooms, separated peaks, hill-climbs).
- :mod:`psyop.statistics.psignifit_private`: the only module that imports psignifit's private functions,
  each named with its parameters in one table and checked on first use.
- :mod:`psyop.statistics.goodness`: deviance and its parametric-bootstrap p-value.
- :mod:`psyop.statistics.anova`: repeated-measures ANOVA (pingouin), listwise deletion made visible,
  degenerate data flagged or refused.
- :mod:`psyop.statistics.binomial`: one-tailed binomial tests of pairwise preferences.
- :mod:`psyop.statistics.regression`: linear fits, the condition-interaction regression and its
  subject-aware mixed-model counterpart.
- :mod:`psyop.statistics.formatting`: each test in the paper's written form.
- :mod:`psyop.statistics.simulate`: simulated tidy tables with known effects (tests, power).
"""

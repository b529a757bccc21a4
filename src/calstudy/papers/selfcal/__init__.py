"""The one-step self-calibration paper (``selfcal``).

The model, the identification, base parameters, pose selection and planning, and the reading
of a measured cell are the user's door :mod:`calstudy.selfcal`; this package holds what is the
paper's own, on top of it. Modules, lowest first (a module imports only those before it):

- :mod:`~calstudy.papers.selfcal.routes`: the multi-step routes (three-step in the paper's order,
  reordered, alternated, two-step) on the same measurements;
- :mod:`~calstudy.papers.selfcal.scenario`: the validated ``data/selfcal/scenario.toml`` (its
  schema is the scenario: the simulated cell and the published numbers);
- :mod:`~calstudy.papers.selfcal.simulate`: true stations, planned views, scans, tracker readings;
- :mod:`~calstudy.papers.selfcal.experiments`: trials, Monte Carlo, compliance and noise sweeps,
  basin, identifiability designs, pose selection, the simulated cell as measured data;
- :mod:`~calstudy.papers.selfcal.report`: summary tables, figures and claim rows;
- :mod:`~calstudy.papers.selfcal.report_sweeps`: the five verdicts along the compliance and noise
  sweeps, their figure and the sentences the chapter shows;
- :mod:`~calstudy.papers.selfcal.report_owncell`: tables and figures of your cell and of the
  pose-selection study.
"""

"""The one-step self-calibration paper (``selfcal``).

Modules, lowest first (a module imports only those before it):

- :mod:`~calstudy.papers.selfcal.model`: the 30-parameter global model of robot, sensor mounting
  and base (Eq. 1-6) on Pinocchio;
- :mod:`~calstudy.papers.selfcal.identify`: sphere fit, bad-input checks, one-step identification
  (Eq. 10-11), its covariance and identifiability;
- :mod:`~calstudy.papers.selfcal.routes`: the multi-step routes (three-step in the paper's order,
  reordered, alternated, two-step) on the same measurements;
- :mod:`~calstudy.papers.selfcal.design`: base parameters by column-pivoted QR and D-optimal
  selection of measuring poses;
- :mod:`~calstudy.papers.selfcal.measured`: your own cell: the measurement files (reader and
  writer), identification on measured data with outliers flagged, the validation report;
- :mod:`~calstudy.papers.selfcal.scenario`: the simulated cell and the published numbers, read
  from ``data/selfcal/scenario.toml``;
- :mod:`~calstudy.papers.selfcal.simulate`: true stations, planned views, scans, tracker readings;
- :mod:`~calstudy.papers.selfcal.experiments`: trials, Monte Carlo, compliance and noise sweeps,
  basin, identifiability designs, pose selection;
- :mod:`~calstudy.papers.selfcal.report`: summary tables, figures and claim rows;
- :mod:`~calstudy.papers.selfcal.report_sweeps`: the five verdicts along the compliance and noise
  sweeps, their figure and the sentences the chapter shows;
- :mod:`~calstudy.papers.selfcal.report_owncell`: tables and figures of your cell and of the
  pose-selection study.

``model``, ``identify``, ``routes``, ``design`` and ``measured`` know nothing of the simulation,
so they serve measured data as well.
"""

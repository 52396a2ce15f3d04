"""Research studies built on the library, each runnable as a module:

- :mod:`granflow.studies.stability` — runs at the edges of the parameter space
  (``python -m granflow.studies.stability``);
- :mod:`granflow.studies.timestep` — work-precision (timestep) studies
  (``python -m granflow.studies.timestep``);
- :mod:`granflow.studies.reproduce_000` — the channel across widths, volume fractions and
  stiffnesses, and its report (``python -m granflow.studies.reproduce_000``);
- :mod:`granflow.studies.reproduce_002` — the cell's Table 1 and figures 3-8, and its report
  (``python -m granflow.studies.reproduce_002``);
- :mod:`granflow.studies.cross_scene` — the channel predicted from the cell (local mu(I) and
  nonlocal fluidity, calibrated in the cell), and its report
  (``python -m granflow.studies.cross_scene``);
- :mod:`granflow.studies.seed_coverage` — are the cell's SEs honest: seeds of one point
  against their reported SEs (``python -m granflow.studies.seed_coverage``).

The last four run as resumable campaigns on one engine (:mod:`granflow.studies._campaign`: a
study gives a point, a plan, its scene, a row and one stop rule). Studies import no other study
but through ``_campaign``; a study's ``*_report`` module imports its own study.
"""

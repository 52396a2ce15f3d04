"""Research studies built on the library, each runnable as a module:

- :mod:`granflow.studies.stability` — runs at the edges of the parameter space
  (``python -m granflow.studies.stability``);
- :mod:`granflow.studies.timestep` — work-precision (timestep) studies
  (``python -m granflow.studies.timestep``).
"""

"""granflow: discrete-element simulation of dense granular flow.

A Rust kernel (spring–dashpot contacts with tangential history and Coulomb friction; linear and
Hertzian) driven from Python; results as Arrow/Parquet tables with error bars.

Scenes from the papers live in :mod:`granflow.scenes`; analysis in :mod:`granflow.analysis`.
"""

from granflow import sizes
from granflow._core import __version__
from granflow.errors import (
    ConfigurationError,
    GranflowError,
    GranflowIOError,
    InstabilityError,
    ParameterError,
)
from granflow.simulation import (
    Box,
    ContactLaw,
    Simulation,
    Wall,
    maxwell_velocities,
    random_packing,
    to_table,
)

__all__ = [
    "__version__",
    "Box",
    "ContactLaw",
    "Simulation",
    "Wall",
    "maxwell_velocities",
    "random_packing",
    "to_table",
    "sizes",
    "GranflowError",
    "ParameterError",
    "ConfigurationError",
    "InstabilityError",
    "GranflowIOError",
]

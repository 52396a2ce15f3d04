"""granflow: discrete-element simulation of dense granular flow.

A Rust kernel (spring–dashpot contacts with tangential history and Coulomb friction; linear and
Hertzian) driven from Python; results as Arrow/Parquet tables with error bars.

Scenes from the papers live in :mod:`granflow.scenes`, their materials in
:mod:`granflow.material`, the flow states in :mod:`granflow.states`; analysis in
:mod:`granflow.analysis`.
"""

from granflow import material, sizes, states
from granflow._core import __version__
from granflow.errors import (
    ConfigurationError,
    DilationError,
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
    "material",
    "sizes",
    "states",
    "GranflowError",
    "ParameterError",
    "ConfigurationError",
    "InstabilityError",
    "DilationError",
    "GranflowIOError",
]

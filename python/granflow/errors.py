"""granflow's exception hierarchy (raised by the Rust kernel through the bindings).

``GranflowError`` is the base class; ``ParameterError`` names the parameter
and its allowed range; ``ConfigurationError`` rejects unusable particle configurations (and a
scene's kernel asked for before :meth:`prepare`); ``InstabilityError`` stops a run that went
unstable (step, particles, likely cause), and its subclass ``DilationError`` a stress-controlled
cell that dilated without bound; ``GranflowIOError`` covers files.
"""

from granflow._core import (
    ConfigurationError,
    GranflowError,
    GranflowIOError,
    InstabilityError,
    ParameterError,
)


class DilationError(InstabilityError):
    """The stress-controlled cell dilated without bound: the imposed shear stress exceeds what
    the packing sustains (the flow accelerates and dilutes; there is no steady state to
    average). Raised by :class:`granflow.scenes.ShearCell` when the kernel's dilation guard
    stops the run, or another guard stops a cell that had already dilated under shear."""


__all__ = [
    "GranflowError",
    "ParameterError",
    "ConfigurationError",
    "InstabilityError",
    "DilationError",
    "GranflowIOError",
]

"""granflow's exception hierarchy (raised by the Rust kernel through the bindings).

``GranflowError`` is the base class; ``ParameterError`` names the parameter
and its allowed range; ``ConfigurationError`` rejects unusable particle configurations;
``InstabilityError`` stops a run that went unstable (step, particles, likely cause), and its
``DilationError`` the stress-controlled cell's runaway dilation;
``GranflowIOError`` covers files.
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
    the packing sustains."""


__all__ = [
    "GranflowError",
    "ParameterError",
    "ConfigurationError",
    "InstabilityError",
    "DilationError",
    "GranflowIOError",
]

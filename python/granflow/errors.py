"""granflow's exception hierarchy (raised by the Rust kernel through the bindings).

``GranflowError`` is the base class; ``ParameterError`` names the parameter
and its allowed range; ``ConfigurationError`` rejects unusable particle configurations;
``InstabilityError`` stops a run that went unstable (step, particles, likely cause);
``GranflowIOError`` covers files.
"""

from granflow._core import (
    ConfigurationError,
    GranflowError,
    GranflowIOError,
    InstabilityError,
    ParameterError,
)

__all__ = [
    "GranflowError",
    "ParameterError",
    "ConfigurationError",
    "InstabilityError",
    "GranflowIOError",
]

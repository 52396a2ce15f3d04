"""The flow states a run is classified into, one vocabulary for every scene, analysis and study.

:class:`FlowState` is a ``str`` Enum: a state compares equal to its value (``FlowState.STEADY ==
"steady"``) and is written to tables and JSON as that string, so the committed datasets read
the same.
"""

from __future__ import annotations

from enum import Enum


class FlowState(str, Enum):
    """A run's flow state.

    The channel (:func:`granflow.analysis.channel_profiles.flow_state`, on |vcm_y|): ``STEADY``
    (a flat trend, small fluctuations), ``FLUCTUATING`` (a flat trend, large fluctuations),
    ``ARRESTED`` (the flow stopped), ``ACCELERATING`` / ``DECELERATING`` (a significant trend).
    The cell (:func:`granflow.analysis.rheology.analyse_run`, on the shear rate): ``FLOWING``
    (steady flow), ``ARRESTED``, ``ACCELERATING`` / ``DECELERATING``.
    A campaign's point: ``SHORT`` (too little data to classify yet), ``RUNAWAY`` (the cell
    dilated without bound, :class:`granflow.errors.DilationError`), ``FAILED`` (the run stopped
    on another error).
    """

    STEADY = "steady"
    FLUCTUATING = "fluctuating"
    FLOWING = "flowing"
    ARRESTED = "arrested"
    ACCELERATING = "accelerating"
    DECELERATING = "decelerating"
    SHORT = "short"
    RUNAWAY = "runaway"
    FAILED = "failed"

    def __str__(self) -> str:
        return self.value

    @property
    def is_steady(self) -> bool:
        """A steady flow whose averages mean something (channel: steady or fluctuating; cell:
        flowing)."""
        return self in (FlowState.STEADY, FlowState.FLUCTUATING, FlowState.FLOWING)


__all__ = ["FlowState"]

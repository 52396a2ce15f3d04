"""The flow states of a run: one vocabulary for every scene, analysis and campaign.

:class:`FlowState` is a ``str`` enum: a member *is* its string (``FlowState.STEADY ==
"steady"``; ``str()``, f-strings and JSON give the value), so tables and the committed datasets
hold the plain strings, which compare equal to the members. (Build a table from row dicts, as
the campaigns do: polars reads a column given as a list of enum members as its own Enum
type.)

This module is a leaf: it imports nothing from granflow, so every layer can use it.
"""

from __future__ import annotations

from enum import Enum

__all__ = ["FlowState"]


class FlowState(str, Enum):
    """The state of a run, as analysis classifies it and campaigns record it.

    Classified from the data (:mod:`granflow.analysis`):

    * ``STEADY`` ("steady"): channel; the centre-of-mass velocity is stationary and its
      fluctuation small (:func:`granflow.analysis.channel_profiles.flow_state`).
    * ``FLUCTUATING`` ("fluctuating"): channel; stationary, but with a relative fluctuation
      amplitude above the threshold (paper 000's 1-2 % at phi_bar = 0.62). Averaged like
      ``STEADY``.
    * ``FLOWING`` ("flowing"): stress-controlled cell; steady shear flow
      (:func:`granflow.analysis.rheology.classify_run`).
    * ``ARRESTED`` ("arrested"): channel (the velocity vanishes) and cell (the shear rate is zero
      within its error): no flow.
    * ``ACCELERATING`` ("accelerating") / ``DECELERATING`` ("decelerating"): channel and cell;
      a significant drift, not a steady state.
    * ``DRIFTING`` ("drifting"): cell and channel; flowing (channel: steady or fluctuating by
      its centre-of-mass velocity), but a reported quantity drifts across the steady part (its
      first and last thirds differ beyond their errors,
      :func:`granflow.analysis.stats.stationarity`; the channel's
      :func:`granflow.analysis.channel.steady_check`): not averaged, not fitted.

    Recorded by campaigns (:mod:`granflow.studies`), not classified from data:

    * ``SHORT`` ("short"): too few samples yet to classify the run.
    * ``RUNAWAY`` ("runaway"): cell; the packing dilated without bound (no steady state under
      the imposed stresses).
    * ``FAILED`` ("failed"): the run stopped on another error (an instability).
    """

    STEADY = "steady"
    FLUCTUATING = "fluctuating"
    FLOWING = "flowing"
    ARRESTED = "arrested"
    ACCELERATING = "accelerating"
    DECELERATING = "decelerating"
    DRIFTING = "drifting"
    SHORT = "short"
    RUNAWAY = "runaway"
    FAILED = "failed"

    # the value, as a plain string would print (Python's default for a str mixin changed in 3.11)
    def __str__(self) -> str:
        return str(self.value)

    def __format__(self, format_spec: str) -> str:
        return format(str(self.value), format_spec)


    @property
    def is_steady(self) -> bool:
        """A steady flow whose averages mean something (channel: steady or fluctuating; cell:
        flowing)."""
        return self in (FlowState.STEADY, FlowState.FLUCTUATING, FlowState.FLOWING)

"""Pure-Python analysis of granflow output tables (docs/columns.md).

* :mod:`.tables` — column access for any table type (pyarrow, polars, mappings), ``to_polars``.
* :mod:`.estimate` — :class:`Estimate`, a value with its standard error (the one such type).
* :mod:`.stats` — Flyvbjerg-Petersen blocking, means and ratios with SEs, trend test,
  steady-state detection, the stationarity (thirds) test, SE against run time, jackknife over
  blocks.
* :mod:`.replicas` — a campaign point's value from its replicas (seeds): mean, within and
  between SEs.
* :mod:`.coverage` — the coverage audit: do the runs' SEs hold across seeds? (a command).
* :mod:`.laws` — the forms of the flow laws mu(I), phi(I) (fits and continuum models).
* :mod:`.binned` — binned profiles: window x bin matrices, whole-profile SEs.
* :mod:`.channel_profiles` — vertical channel, paper 000 (Debnath, Kesava Rao & Kumaran
  2022): flow state and steady profiles with jackknife SEs.
* :mod:`.channel` — the same paper's model curves, velocity scaling, zones, rheology, summary.
* :mod:`.order` — bond-orientational order (Steinhardt Q6, crystal-like fraction) of a
  packing, bin by bin (the channel's plug: crystal or dense amorphous?).
* :mod:`.rheology` — stress-controlled cell, paper 002 (Srivastava et al.), Table 1.
* :mod:`.report` — SE of a run's key figures against averaging and wall time.
* :mod:`.plots` — the papers' figures, error / work-precision plots and a run directory's
  figures (PNG).

Flow states are :class:`granflow.states.FlowState` members.
"""

from . import (
    binned,
    channel,
    channel_profiles,
    coverage,
    estimate,
    laws,
    order,
    plots,
    replicas,
    rheology,
    stats,
    tables,
)
from .binned import ProfileErrors, profile_se, profile_se_vs_time
from .channel import (
    Zones,
    conduction_length,
    mean_velocity_32,
    mu_B3,
    phi_B4,
    scaled_profile_31,
    summary,
    velocity_profile_31,
    velocity_scaling,
    zones,
)
from .channel_profiles import ChannelProfiles, ChannelState, flow_state, profiles
from .coverage import pair_z, steady_rows
from .estimate import Estimate
from .plots import (
    plot_cell_rheology,
    plot_channel_fields,
    plot_channel_mu_phi_I,
    plot_channel_velocity,
    plot_run,
    plot_se_vs_time,
    plot_work_precision,
)
from .replicas import replica_mean
from .rheology import (
    CellState,
    FitResult,
    FlowLaw,
    RunAnalysis,
    analyse_run,
    classify_run,
    collect_runs,
    fit_all,
    fit_flow_law,
    fit_law,
    format_table1,
    load_table1,
    pool_realizations,
    print_table1,
    reference_curve,
    reference_parameters,
    table1_row,
)
from .stats import (
    BlockingResult,
    SEvsTime,
    Stationarity,
    SteadyStart,
    blocking,
    blocking_many,
    mean_se,
    ratio_se,
    se_vs_time,
    stationarity,
    steady_state_start,
)
from .tables import as_columns, to_polars

__all__ = [
    "binned",
    "channel",
    "channel_profiles",
    "coverage",
    "estimate",
    "laws",
    "order",
    "plots",
    "replicas",
    "rheology",
    "stats",
    "tables",
    # tables, stats, binned
    "BlockingResult",
    "Estimate",
    "ProfileErrors",
    "SEvsTime",
    "Stationarity",
    "SteadyStart",
    "as_columns",
    "blocking",
    "blocking_many",
    "mean_se",
    "profile_se",
    "profile_se_vs_time",
    "ratio_se",
    "se_vs_time",
    "stationarity",
    "steady_state_start",
    "to_polars",
    # replicas and their coverage
    "pair_z",
    "replica_mean",
    "steady_rows",
    # channel
    "ChannelProfiles",
    "ChannelState",
    "Zones",
    "conduction_length",
    "flow_state",
    "mean_velocity_32",
    "mu_B3",
    "phi_B4",
    "profiles",
    "scaled_profile_31",
    "summary",
    "velocity_profile_31",
    "velocity_scaling",
    "zones",
    # rheology
    "CellState",
    "FitResult",
    "FlowLaw",
    "RunAnalysis",
    "analyse_run",
    "classify_run",
    "collect_runs",
    "fit_all",
    "fit_flow_law",
    "fit_law",
    "format_table1",
    "load_table1",
    "pool_realizations",
    "print_table1",
    "reference_curve",
    "reference_parameters",
    "table1_row",
    # plots
    "plot_cell_rheology",
    "plot_channel_fields",
    "plot_channel_mu_phi_I",
    "plot_channel_velocity",
    "plot_run",
    "plot_se_vs_time",
    "plot_work_precision",
]

"""Stress-controlled cell rheology (paper 002: Srivastava, Silbert, Grest & Lechman, "Viscometric
flow of dense granular materials under controlled pressure and shear stress"), §3-§5, Table 1.

Per run (one cell ``series`` table, docs/columns.md): steady-state detection, mean / blocking SE
/ correlation time of every observable (the paper uses Flyvbjerg-Petersen block averaging, §3),
and a flow / arrest classification.  Across runs: one row per run (:func:`collect_runs`), fits
of the flow laws (4.2), (4.4), (4.6), (4.7) with parameter uncertainties, and the comparison with
Table 1 and the values quoted in the text.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import polars as pl
from scipy import optimize

from granflow.errors import ParameterError
from granflow.states import FlowState

from ._numerics import quiet
from .laws import jop_law, jop_linear_law, power_law, power_quadratic_law
from .stats import (
    DEFAULT_MIN_BLOCKS,
    DRIFT_Z,
    Stationarity,
    SteadyStart,
    Trend,
    blocking,
    blocking_many,
    shared_mode_se,
    stationarity,
    steady_state_start,
    trend,
)
from .tables import FloatArray, TableLike, column, column_names, sample_interval, to_polars

# --------------------------------------------------------------------------------------------
# reference values from paper 002
# --------------------------------------------------------------------------------------------
#: Table 1 of paper 002 (mu_s, A1, A2, A3, A4); identical to shared/reference/srivastava_table1.csv.
TABLE1: tuple[tuple[float, float, float, float, float], ...] = (
    (0.0, 0.530, 0.240, 0.052, 0.272),
    (0.001, 0.530, 0.243, 0.052, 0.274),
    (0.003, 0.528, 0.247, 0.052, 0.276),
    (0.01, 0.522, 0.252, 0.052, 0.274),
    (0.03, 0.516, 0.270, 0.051, 0.263),
    (0.04, 0.516, 0.274, 0.054, 0.259),
    (0.05, 0.520, 0.284, 0.059, 0.254),
    (0.06, 0.518, 0.290, 0.059, 0.251),
    (0.08, 0.531, 0.322, 0.059, 0.247),
    (0.1, 0.526, 0.303, 0.067, 0.246),
    (0.14, 0.545, 0.330, 0.062, 0.243),
    (0.18, 0.554, 0.360, 0.070, 0.241),
    (0.23, 0.562, 0.366, 0.088, 0.238),
    (0.3, 0.573, 0.398, 0.084, 0.230),
)
#: Values quoted in the text of 002 §4 for frictionless (mu_s = 0) and high-friction
#: (mu_s = 0.3, the largest friction studied) particles.  mu3_0 is only said to be positive
#: (fig. 5c), so it is not available; alpha_3 ~ 0.5 "independent of friction".
TEXT_VALUES: dict[float, dict[str, float]] = {
    0.0: {
        "mu1_0": 0.09,
        "a1": 0.37,
        "mu2_0": 0.01,
        "a2": 0.28,
        "mu3_0": math.nan,
        "a3": 0.5,
        "phi_0": 0.63,
        "a4": 0.82,
    },
    0.3: {
        "mu1_0": 0.33,
        "a1": 0.70,
        "mu2_0": 0.10,
        "a2": 0.44,
        "mu3_0": math.nan,
        "a3": 0.5,
        "phi_0": 0.59,
        "a4": 0.92,
    },
}
#: the unit of the last digit 002 prints each value with: Table 1's A's three decimals, the
#: text's constants two (alpha_3 "~0.5": one). A value printed as 0.63 is known to +-0.005,
#: and a comparison must allow that (:func:`printed_unit`).
PRINTED_UNIT: dict[str, float] = {"A1": 1e-3, "A2": 1e-3, "A3": 1e-3, "A4": 1e-3, "a3": 0.1,
                                  **{k: 1e-2 for k in ("mu1_0", "a1", "mu2_0", "a2", "mu3_0",
                                                       "phi_0", "a4")}}


def printed_unit(name: str) -> float:
    """The unit of the last digit paper 002 prints parameter ``name`` with (PRINTED_UNIT)."""
    if name not in PRINTED_UNIT:
        raise KeyError(f"no printed precision for {name!r}: allowed {sorted(PRINTED_UNIT)}")
    return PRINTED_UNIT[name]


DEFAULT_TABLE1_PATH = (
    Path(os.environ.get("GRANFLOW_REFERENCE_DIR", "/work/shared/reference"))
    / "srivastava_table1.csv"
)


@dataclass(frozen=True)
class FlowLaw:
    """A flow law of 002 §4, ``y = c0 + sign * A * (I^x_power)^a``
    (:func:`granflow.analysis.laws.power_law`)."""

    y: str
    params: tuple[str, str, str]
    x_power: int
    sign: float
    equation: str


#: The four flow laws of 002 §4.
LAWS: dict[str, FlowLaw] = {
    "mu1": FlowLaw("mu1", ("mu1_0", "A1", "a1"), 1, +1.0, "(4.2) mu1 = mu1_0 + A1 I^a1"),
    "mu2": FlowLaw("mu2", ("mu2_0", "A2", "a2"), 2, +1.0, "(4.4) mu2 = mu2_0 + A2 (I^2)^a2"),
    "mu3": FlowLaw("mu3", ("mu3_0", "A3", "a3"), 2, -1.0, "(4.6) mu3 = mu3_0 - A3 (I^2)^a3"),
    "phi": FlowLaw("phi", ("phi_0", "A4", "a4"), 1, -1.0, "(4.7) phi = phi_0 - A4 I^a4"),
}


@quiet
def law_value(law: str, I: npt.ArrayLike, c0: float, A: float, a: float) -> FloatArray:  # noqa: E741
    """Evaluate a flow law: (4.2) ``mu1_0 + A1 I^a1``, (4.4) ``mu2_0 + A2 (I^2)^a2``,
    (4.6) ``mu3_0 - A3 (I^2)^a3`` or (4.7) ``phi_0 - A4 I^a4``."""
    spec = LAWS[law]
    x = np.asarray(I, dtype=np.float64) ** spec.x_power
    return power_law(x, c0, A, a, spec.sign)


@quiet
def load_table1(path: str | os.PathLike[str] | None = None) -> pl.DataFrame:
    """Table 1 of paper 002 as a polars frame (mu_s, A1, A2, A3, A4).

    Reads ``path`` (default ``$GRANFLOW_REFERENCE_DIR/srivastava_table1.csv``, i.e.
    /work/shared/reference); falls back to the embedded copy :data:`TABLE1` if the default file
    is absent.
    """
    p = Path(path) if path is not None else DEFAULT_TABLE1_PATH
    if path is not None or p.exists():
        return pl.read_csv(p).cast(pl.Float64)
    return pl.DataFrame(list(TABLE1), schema=["mu_s", "A1", "A2", "A3", "A4"], orient="row")


@quiet
def reference_parameters(mu_s: float, table: pl.DataFrame | None = None) -> dict[str, Any]:
    """Paper values of all twelve flow-law parameters for friction ``mu_s``.

    ``A1..A4`` from Table 1 (linear interpolation in mu_s between rows, flagged by
    ``interpolated``); ``mu1_0, a1, mu2_0, a2, a3, phi_0, a4`` from the text of §4, available
    for mu_s = 0 and 0.3 only (``a3 = 0.5`` for all mu_s); NaN where the paper gives no number
    (``mu3_0`` always).
    """
    tab = table if table is not None else load_table1()
    ms = tab["mu_s"].to_numpy()
    out: dict[str, Any] = {"mu_s": float(mu_s)}
    exact = np.flatnonzero(np.isclose(ms, mu_s, rtol=0, atol=1e-9))
    for k in ("A1", "A2", "A3", "A4"):
        col = tab[k].to_numpy()
        if exact.size:
            out[k] = float(col[exact[0]])
        elif ms.min() <= mu_s <= ms.max():
            out[k] = float(np.interp(mu_s, ms, col))
        else:
            out[k] = math.nan
    out["interpolated"] = not bool(exact.size)
    text = next((v for k, v in TEXT_VALUES.items() if abs(k - mu_s) < 1e-9), None)
    for k in ("mu1_0", "a1", "mu2_0", "a2", "mu3_0", "a3", "phi_0", "a4"):
        out[k] = text[k] if text is not None else (0.5 if k == "a3" else math.nan)
    return out


@quiet
def reference_curve(
    law: str,
    I: npt.ArrayLike,  # noqa: E741
    mu_s: float = 0.3,
    offset: float | None = None,
) -> FloatArray:
    """Paper 002 curve of ``law`` at inertial numbers ``I`` for friction ``mu_s``.

    ``offset`` replaces the quasi-static value (``mu3_0`` is not given in the paper: pass e.g.
    the fitted one to compare shapes).  Raises ``ValueError`` when a needed value is missing.
    """
    p = reference_parameters(mu_s)
    c0n, an, expn = LAWS[law].params
    c0 = p[c0n] if offset is None else offset
    vals = (c0, p[an], p[expn])
    if not all(np.isfinite(v) for v in vals):
        raise ValueError(f"paper 002 gives no complete parameter set for {law} at mu_s={mu_s}")
    return law_value(law, I, *vals)


# --------------------------------------------------------------------------------------------
# one run
# --------------------------------------------------------------------------------------------
_NON_OBSERVABLE_PREFIXES = ("H_", "F_")
_NON_OBSERVABLES = {"step", "t", "tilt_flips"}
KEY_COLUMNS = ("shear_rate", "phi", "p", "mu1")
#: the quantities whose drift makes a flowing run "drifting" (those the campaigns report)
DRIFT_COLUMNS = ("I", "phi", "mu1", "mu2")
#: the series that carries the cell's slow mode (the volume under the barostat)
SLOW_MODE_REFERENCE = "phi"
_SHEAR_COMPONENTS = ("L_xy", "L_yx", "L_xz", "L_zx", "L_yz", "L_zy")


def observable_columns(series: TableLike) -> list[str]:
    """Columns of a cell ``series`` that are averaged: all except step, t, the cell matrix
    H_ab and deformation gradient F_ab (they grow with the strain) and the cumulative
    tilt_flips."""
    return [
        c
        for c in column_names(series)
        if c not in _NON_OBSERVABLES and not c.startswith(_NON_OBSERVABLE_PREFIXES)
    ]


#: the channel's variables from a cell series (:func:`gradient_frame`)
GRADIENT_COLUMNS = ("mu_g", "I_g", "sigma_g_p")


def gradient_frame(series: TableLike) -> pl.DataFrame:
    """A cell ``series`` with the shear measured as the channel of 000 measures it: against
    the normal stress on the shear planes, not the pressure. The cell's H is upper
    triangular, so L_yx = 0 and its mean flow is along x with the gradient along y: the
    gradient normal stress is sigma_yy (the channel's sigma_xx). Added per sample:
    ``mu_g = -sigma_xy/sigma_yy`` (002 (2.11): tau_ext > 0 gives sigma_xy = -tau), ``I_g =
    2 |D| a/sqrt(sigma_yy/rho) = 2 I sqrt(p/sigma_yy)`` (the cell's I is |D| a/sqrt(p/rho),
    |D| = gamma_dot/2 in simple shear; the channel's is |du/dx| d/sqrt(sigma_xx/rho_p)) and
    ``sigma_g_p = sigma_yy/p``."""
    d = to_polars(series)
    syy = pl.col("sigma_yy")
    return d.with_columns(
        (-pl.col("sigma_xy") / syy).alias("mu_g"),
        (2.0 * pl.col("I") * (pl.col("p") / syy).sqrt()).alias("I_g"),
        (syy / pl.col("p")).alias("sigma_g_p"),
    )


@dataclass
class CellState:
    """Flow / arrest classification of one cell run: ``state`` a
    :class:`granflow.states.FlowState`.

    * ``arrested``: every off-diagonal velocity-gradient component L_xy ... L_zy has a mean
      over the steady part that is zero within ``z_arrest`` (default 3, six components are
      tested) blocking standard errors: the shear rate vanishes within error.
      ``shear_component`` is the component with the largest ``|mean| / SE``.
      Without L columns a run is arrested when ``mean(shear_rate) < rate_floor``.
    * ``accelerating`` / ``decelerating``: the shear rate drifts over the steady part (linear
      trend with ``|t| > t_sig``, slope SE corrected for serial correlation, and relative change
      across the part above ``max_rel_drift``): not steady, not averaged.
    * ``drifting``: flowing, but a quantity of ``drift_columns`` (I, phi, mu1, mu2) drifts
      across the steady part: the means of its first and last thirds differ by more than
      ``z_drift`` of their SEs (:func:`granflow.analysis.stats.stationarity`; ``drift_z`` and
      ``drift_quantity`` say which and how far). Near the runaway ratio the flow drifts for
      thousands of t_c, and MSER alone takes a start inside the drift.
    * ``flowing``: steady flow.

    ``averaged`` is True for flowing and arrested runs.  ``settled`` is False if MSER put the
    steady start at the edge of its search range.
    """

    state: FlowState
    averaged: bool
    settled: bool
    t_start: float
    index: int
    shear_component: str
    shear_mean: float
    shear_se: float
    trend: dict[str, float] = field(default_factory=dict)
    drift_z: float = math.nan
    drift_quantity: str = ""


@quiet
def cell_steady_start(
    series: TableLike, key_columns: Sequence[str] = KEY_COLUMNS, **kwargs: Any
) -> SteadyStart:
    """The cell's steady start (the one rule, :func:`granflow.analysis.stats.steady_state_start`
    on the cell's observables): the latest MSER start over the key observables present
    (default shear_rate, phi, p, mu1)."""
    t = column(series, "t")
    names = column_names(series)
    cols = {k: column(series, k) for k in key_columns if k in names}
    if not cols:
        cols = {c: column(series, c) for c in observable_columns(series)[:1]}
    return steady_state_start(t, cols, **kwargs)


@quiet
def classify_run(
    series: TableLike,
    *,
    start: int | None = None,
    z_arrest: float = 3.0,
    t_sig: float = 3.0,
    max_rel_drift: float = 0.1,
    rate_floor: float = 0.0,
    drift_columns: Sequence[str] = DRIFT_COLUMNS,
    z_drift: float = DRIFT_Z,
) -> CellState:
    """Classify a cell run as flowing, arrested, accelerating or decelerating (a
    :class:`granflow.states.FlowState`; criteria in :class:`CellState`)."""
    t = column(series, "t")
    names = column_names(series)
    if start is None:
        ss = cell_steady_start(series)
        start, settled, t_start = ss.index, ss.settled, ss.t_start
    else:
        settled, t_start = True, float(t[start])
    dt = sample_interval(t)
    tt = t[start:]
    comp, smean, sse = "", math.nan, math.nan
    comps = [c for c in _SHEAR_COMPONENTS if c in names]
    if comps:
        mat = np.column_stack([column(series, c)[start:] for c in comps])
        b = blocking_many(mat, dt)
        tval = np.where(b.se > 0, np.abs(b.mean) / b.se, np.where(b.mean != 0, np.inf, 0.0))
        j = int(np.nanargmax(tval))
        comp, smean, sse = comps[j], float(b.mean[j]), float(b.se[j])
        arrested = bool(tval[j] < z_arrest)
    elif "shear_rate" in names:
        bsr = blocking(column(series, "shear_rate")[start:], dt)
        comp, smean, sse = "shear_rate", bsr.mean, bsr.se
        arrested = smean < rate_floor
    else:
        arrested = False
    tr: Trend | None = None
    if "shear_rate" in names:
        tr = trend(tt, column(series, "shear_rate")[start:])
    state = FlowState.FLOWING
    drifting = {c: column(series, c)[start:] for c in drift_columns if c in names}
    drift = (stationarity(drifting, z_max=z_drift) if drifting
             else Stationarity({}, "", math.nan, True, False))
    if arrested:
        state = FlowState.ARRESTED
    elif tr is not None and abs(tr.t_stat) > t_sig and abs(tr.rel_drift) > max_rel_drift:
        state = FlowState.ACCELERATING if tr.slope > 0 else FlowState.DECELERATING
    elif drift.tested and not drift.stationary:
        state = FlowState.DRIFTING
    return CellState(
        state,
        state in (FlowState.FLOWING, FlowState.ARRESTED),
        settled,
        t_start,
        int(start),
        comp,
        smean,
        sse,
        asdict(tr) if tr is not None else {},
        drift.max_abs_z,
        drift.worst,
    )


@dataclass
class RunAnalysis:
    """Classification and per-observable statistics of one run.

    ``stats`` has one row per observable: observable, mean, se, se_err, tau (integrated
    correlation time, time units), converged, n.
    """

    state: CellState
    stats: pl.DataFrame


@quiet
def analyse_run(
    series: TableLike,
    *,
    start: int | None = None,
    columns: Sequence[str] | None = None,
    min_blocks: int = DEFAULT_MIN_BLOCKS,
    **classify_kwargs: Any,
) -> RunAnalysis:
    """Steady-state detection, classification and mean / SE / correlation time of every
    observable column (:func:`observable_columns`) of a cell ``series`` table.

    An observable's SE is the larger of its own blocking SE and its SE through the volume's
    slow mode (:func:`granflow.analysis.stats.shared_mode_se` with phi, SLOW_MODE_REFERENCE,
    as the reference: the rates follow the volume, and their own blocking curves miss its
    slow mode)."""
    st = classify_run(series, start=start, **classify_kwargs)
    cols = list(columns) if columns is not None else observable_columns(series)
    t = column(series, "t")
    mat = (
        np.column_stack([column(series, c)[st.index :] for c in cols])
        if cols
        else np.zeros((t.size - st.index, 0))
    )
    dt = sample_interval(t)
    b = blocking_many(mat, dt, min_blocks=min_blocks)
    se = b.se
    if SLOW_MODE_REFERENCE in column_names(series) and cols:
        shared, _ = shared_mode_se(mat, column(series, SLOW_MODE_REFERENCE)[st.index :], dt)
        own = np.array([c == SLOW_MODE_REFERENCE for c in cols])
        se = np.where(np.isfinite(shared) & ~own, np.fmax(se, shared), se)
    stats = pl.DataFrame(
        {
            "observable": cols,
            "mean": b.mean,
            "se": se,
            "se_err": b.se_err,
            "tau": b.tau,
            "converged": b.converged,
            "n": b.n,
        }
    )
    return RunAnalysis(st, stats)


@quiet
def collect_runs(
    runs: Iterable[tuple[Mapping[str, Any], TableLike]],
    *,
    columns: Sequence[str] | None = None,
    min_blocks: int = DEFAULT_MIN_BLOCKS,
    **classify_kwargs: Any,
) -> pl.DataFrame:
    """One row per run from ``(params, series)`` pairs.

    Columns: the params, ``state``, ``averaged``, ``settled``, ``t_start``, ``T_avg`` (steady
    averaging time), ``n_samples``, ``n_unconverged`` (observables whose blocking did not
    converge), and for every observable ``X``: ``X`` (mean), ``X_se`` and ``X_tau``.  Runs that
    are not averaged (accelerating / decelerating) get null means and SEs.
    """
    rows: list[dict[str, Any]] = []
    for params, series in runs:
        res = analyse_run(series, columns=columns, min_blocks=min_blocks, **classify_kwargs)
        st = res.state
        t = column(series, "t")
        row: dict[str, Any] = dict(params)
        row.update(
            {
                "state": st.state.value,  # a table holds the plain string
                "averaged": st.averaged,
                "settled": st.settled,
                "t_start": st.t_start,
                "T_avg": float(t[-1] - t[st.index]) + sample_interval(t),
                "n_samples": int(t.size - st.index),
                "n_unconverged": int((~res.stats["converged"]).sum()),
            }
        )
        for r in res.stats.iter_rows(named=True):
            ok = st.averaged
            row[r["observable"]] = r["mean"] if ok else None
            row[f"{r['observable']}_se"] = r["se"] if ok else None
            row[f"{r['observable']}_tau"] = r["tau"]
        rows.append(row)
    return pl.from_dicts(rows, infer_schema_length=None)


@quiet
def pool_realizations(df: TableLike, by: Sequence[str]) -> pl.DataFrame:
    """Combine runs with equal ``by`` values (e.g. realizations at the same applied stresses)
    by inverse-variance weighting: ``X = sum(X/se^2)/sum(1/se^2)``, ``X_se = sum(1/se^2)^-1/2``;
    only averaged runs are used and ``n_runs`` counts them."""
    df = to_polars(df)
    obs = [c[:-3] for c in df.columns if c.endswith("_se") and c[:-3] in df.columns]
    d = df.filter(pl.col("averaged")) if "averaged" in df.columns else df
    aggs: list[pl.Expr] = [pl.len().alias("n_runs")]
    for o in obs:
        w = 1.0 / pl.col(f"{o}_se") ** 2
        aggs.append(((pl.col(o) * w).sum() / w.sum()).alias(o))
        aggs.append((1.0 / w.sum().sqrt()).alias(f"{o}_se"))
    return d.group_by(list(by), maintain_order=True).agg(aggs).sort(list(by))


# --------------------------------------------------------------------------------------------
# flow-law fits (section 4)
# --------------------------------------------------------------------------------------------
#: a fitted constant whose (scaled) error exceeds this fraction of its value is not determined
UNDETERMINED = 0.5


def undetermined(value: float, error: float, reference: float = math.nan) -> bool:
    """Whether a fitted constant ``value`` +- ``error`` is not determined: its error exceeds
    UNDETERMINED of its size, or of the ``reference`` value it is compared with where that is
    larger (a small fit beside a large reference is not called determined), or is not finite."""
    size = max(abs(value), abs(reference)) if math.isfinite(reference) else abs(value)
    return not error <= UNDETERMINED * size


@dataclass
class FitResult:
    """Weighted least-squares fit of a flow law (scipy ``curve_fit``, ``sigma`` = SE,
    ``absolute_sigma=True``).

    ``params`` / ``errors`` are keyed by the paper's names (e.g. mu1_0, A1, a1); ``errors``
    are the square roots of the covariance diagonal.  When ``red_chi2`` is well above 1 the
    scatter exceeds the SEs and the errors are optimistic (``errors_scaled`` multiplies them by
    ``sqrt(red_chi2)``).
    """

    law: str
    equation: str
    params: dict[str, float]
    errors: dict[str, float]
    cov: FloatArray
    chi2: float
    dof: int
    n: int
    success: bool
    message: str = ""

    @property
    def red_chi2(self) -> float:
        """chi^2 per degree of freedom."""
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def scale(self) -> float:
        """``max(1, red_chi2)`` (1 when undefined): the factor on the covariance where the
        scatter exceeds the SEs."""
        return max(1.0, self.red_chi2) if math.isfinite(self.red_chi2) else 1.0

    @property
    def errors_scaled(self) -> dict[str, float]:
        """Errors multiplied by ``sqrt(max(1, red_chi2))``."""
        f = math.sqrt(self.scale)
        return {k: v * f for k, v in self.errors.items()}

    @property
    def cov_scaled(self) -> FloatArray:
        """The covariance multiplied by ``max(1, red_chi2)`` (the errors_scaled')."""
        return np.asarray(self.cov * self.scale)

    @quiet
    def __call__(self, I: npt.ArrayLike) -> FloatArray:  # noqa: E741
        """The fitted law at ``I``."""
        if self.law == JOP:
            return jop_value(I, *self.params.values())
        if self.law in FOUR_CONSTANT:
            return FOUR_CONSTANT[self.law].value(np.asarray(I, dtype=np.float64),
                                                 *self.params.values())
        return law_value(self.law, I, *self.params.values())


def _initial_guess(
    spec: FlowLaw, x: FloatArray, y: FloatArray, w: FloatArray
) -> tuple[float, float, float]:
    """Grid over the exponent with a weighted linear solve for (c0, A) at each exponent."""
    best = (float(np.average(y, weights=w)), 0.1, 0.5)
    best_chi = math.inf
    sw = np.sqrt(w)
    for a in np.linspace(0.1, 2.0, 39):
        design = np.column_stack([np.ones_like(x), spec.sign * x**a])
        coef, *_ = np.linalg.lstsq(design * sw[:, None], y * sw, rcond=None)
        if coef[1] <= 0:
            continue
        chi = float(np.sum(w * (y - design @ coef) ** 2))
        if chi < best_chi:
            best_chi, best = chi, (float(coef[0]), float(coef[1]), float(a))
    return best


@quiet
def fit_law(
    law: str,
    I: npt.ArrayLike,  # noqa: E741
    y: npt.ArrayLike,
    y_se: npt.ArrayLike,
    *,
    I_se: npt.ArrayLike | None = None,
    p0: Sequence[float] | None = None,
) -> FitResult:
    """Fit (4.2) / (4.4) / (4.6) / (4.7) (``law`` = 'mu1', 'mu2', 'mu3', 'phi').

    Points with non-finite values, non-positive SE or I <= 0 are dropped.  If ``I_se`` is
    given, the SE of I is propagated by the effective-variance method
    (``sigma^2 = y_se^2 + (dy/dI I_se)^2`` at the first fit, then refitted).  Bounds: A > 0,
    0.01 < exponent < 5.
    """
    spec = LAWS[law]
    ii = np.asarray(I, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    sy = np.asarray(y_se, dtype=np.float64)
    si = None if I_se is None else np.asarray(I_se, dtype=np.float64)
    ok = np.isfinite(ii) & np.isfinite(yy) & np.isfinite(sy) & (sy > 0) & (ii > 0)
    if si is not None:
        ok &= np.isfinite(si)
    ii, yy, sy = ii[ok], yy[ok], sy[ok]
    si = si[ok] if si is not None else None
    names = spec.params
    n = int(ii.size)
    nan3 = dict.fromkeys(names, math.nan)
    if n < 4:
        return FitResult(
            law,
            spec.equation,
            nan3,
            dict(nan3),
            np.full((3, 3), np.nan),
            math.nan,
            n - 3,
            n,
            False,
            "fewer than 4 usable points",
        )
    x = ii**spec.x_power

    def model(xv: FloatArray, c0: float, A: float, a: float) -> FloatArray:
        return power_law(xv, c0, A, a, spec.sign)

    start = tuple(p0) if p0 is not None else _initial_guess(spec, x, yy, 1.0 / sy**2)
    lo, hi = [-np.inf, 0.0, 0.01], [np.inf, np.inf, 5.0]
    start = (start[0], min(max(start[1], 1e-12), 1e12), min(max(start[2], 0.011), 4.99))
    sigma = sy
    try:
        p, cov = optimize.curve_fit(
            model, x, yy, p0=start, sigma=sigma, absolute_sigma=True, bounds=(lo, hi), maxfev=20000
        )
        if si is not None:
            # dy/dI = sign A a x^(a-1) dx/dI, dx/dI = x_power I^(x_power-1)
            dydi = (
                spec.sign
                * p[1]
                * p[2]
                * x ** (p[2] - 1.0)
                * spec.x_power
                * ii ** (spec.x_power - 1)
            )
            sigma = np.sqrt(sy**2 + (dydi * si) ** 2)
            p, cov = optimize.curve_fit(
                model, x, yy, p0=p, sigma=sigma, absolute_sigma=True, bounds=(lo, hi), maxfev=20000
            )
    except (RuntimeError, ValueError) as exc:
        return FitResult(
            law,
            spec.equation,
            nan3,
            dict(nan3),
            np.full((3, 3), np.nan),
            math.nan,
            n - 3,
            n,
            False,
            str(exc),
        )
    chi2 = float(np.sum(((yy - model(x, *p)) / sigma) ** 2))
    err = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return FitResult(
        law,
        spec.equation,
        dict(zip(names, map(float, p), strict=True)),
        dict(zip(names, map(float, err), strict=True)),
        cov,
        chi2,
        n - 3,
        n,
        True,
    )


def _usable(I: npt.ArrayLike, y: npt.ArrayLike, y_se: npt.ArrayLike,  # noqa: E741
            I_se: npt.ArrayLike | None) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The points a fit of Jop's form (or a four-constant form) uses: finite, SE > 0, I > 0;
    ``I_se`` 0 where not given."""
    ii, yy, sy = (np.asarray(v, dtype=np.float64) for v in (I, y, y_se))
    si = np.zeros_like(ii) if I_se is None else np.asarray(I_se, dtype=np.float64)
    ok = np.isfinite(ii) & np.isfinite(yy) & np.isfinite(sy) & (sy > 0) & (ii > 0)
    ok &= np.isfinite(si)
    return ii[ok], yy[ok], sy[ok], si[ok]


#: the mu(I) form of Jop, Forterre & Pouliquen (Nature 2006), mu = mu_s + (mu_2 - mu_s)/(1 +
#: I_0/I): linear in I at small I, where (4.2) with a1 < 1 has an infinite slope and so
#: continues to a lower yield ratio; the form continuum models of granular flow take
JOP = "mu_jop"
JOP_EQUATION = "mu = mu_s + (mu_2 - mu_s)/(1 + I_0/I) (Jop et al. 2006)"


def jop_value(I: npt.ArrayLike, mu_s: float, mu_2: float, I_0: float) -> FloatArray:  # noqa: E741
    """Jop et al.'s mu(I) at ``I``."""
    ii = np.asarray(I, dtype=np.float64)
    return jop_law(ii, mu_s, mu_2 - mu_s, I_0)


@quiet
def fit_jop(I: npt.ArrayLike, y: npt.ArrayLike, y_se: npt.ArrayLike,  # noqa: E741
            *, I_se: npt.ArrayLike | None = None) -> FitResult:
    """Weighted fit of Jop et al.'s mu(I) (constants mu_s, mu_2, I_0), the SE of I
    propagated by effective variance as in :func:`fit_law`. Only I_0 > 0 is bounded: a fit
    that ends with mu_2 <= mu_s is returned as it is (granflow.continuum.LocalLaw refuses
    it by name)."""
    ii, yy, sy, si = _usable(I, y, y_se, I_se)
    names = ("mu_s", "mu_2", "I_0")
    n = int(ii.size)
    nan3 = dict.fromkeys(names, math.nan)
    if n < 4:
        return FitResult(JOP, JOP_EQUATION, nan3, dict(nan3), np.full((3, 3), np.nan),
                         math.nan, n - 3, n, False, "fewer than 4 usable points")
    start = (float(yy.min()) - 0.02, float(yy.max()) + 0.2, float(np.median(ii)))
    bounds = ([-np.inf, -np.inf, 1e-9], [np.inf, np.inf, np.inf])
    sigma = sy
    try:
        p, cov = optimize.curve_fit(jop_value, ii, yy, p0=start, sigma=sigma,
                                    absolute_sigma=True, bounds=bounds, maxfev=20000)
        if I_se is not None:
            slope = (p[1] - p[0]) * p[2] / (ii + p[2]) ** 2
            sigma = np.sqrt(sy**2 + (slope * si) ** 2)
            p, cov = optimize.curve_fit(jop_value, ii, yy, p0=p, sigma=sigma,
                                        absolute_sigma=True, bounds=bounds, maxfev=20000)
    except (RuntimeError, ValueError) as exc:
        return FitResult(JOP, JOP_EQUATION, nan3, dict(nan3), np.full((3, 3), np.nan),
                         math.nan, n - 3, n, False, str(exc))
    chi2 = float(np.sum(((yy - jop_value(ii, *p)) / sigma) ** 2))
    err = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return FitResult(JOP, JOP_EQUATION, dict(zip(names, map(float, p), strict=True)),
                     dict(zip(names, map(float, err), strict=True)), cov, chi2, n - 3, n, True)


def jop_linear_value(I: npt.ArrayLike, mu_s: float, mu_2: float, I_0: float,  # noqa: E741
                     c: float) -> FloatArray:
    """Jop et al.'s mu(I) with a linear term, ``+ c I``, at ``I``."""
    return jop_linear_law(np.asarray(I, dtype=np.float64), mu_s, mu_2 - mu_s, I_0, c)


def phi_quadratic_value(I: npt.ArrayLike, phi_0: float, A4: float, a4: float,  # noqa: E741
                        B: float) -> FloatArray:
    """002's (4.7) with a quadratic term, ``- B I^2``, at ``I``."""
    return power_quadratic_law(np.asarray(I, dtype=np.float64), phi_0, A4, a4, B)


@dataclass(frozen=True)
class FourConstantForm:
    """A three-constant form with one more constant (the calibration's forms): its value, the
    names of its constants and the bounds of the three it extends."""

    equation: str
    value: Any
    names: tuple[str, str, str, str]
    lower: tuple[float, float, float, float]
    upper: tuple[float, float, float, float]


#: Jop et al.'s mu(I) + c I
JOP_LINEAR = "mu_jop_linear"
#: 002's (4.7) phi(I) - B I^2
PHI_QUADRATIC = "phi_quadratic"
FOUR_CONSTANT = {
    JOP_LINEAR: FourConstantForm(
        "mu = mu_s + (mu_2 - mu_s)/(1 + I_0/I) + c I (Jop et al. 2006, a linear term)",
        jop_linear_value, ("mu_s", "mu_2", "I_0", "c"),
        (-np.inf, -np.inf, 1e-9, -np.inf), (np.inf, np.inf, np.inf, np.inf)),
    PHI_QUADRATIC: FourConstantForm(
        "phi = phi_0 - A4 I^a4 - B I^2 (002 (4.7), a quadratic term)",
        phi_quadratic_value, ("phi_0", "A4", "a4", "B"),
        (-np.inf, 0.0, 0.01, -np.inf), (np.inf, np.inf, 5.0, np.inf)),
}


@quiet
def fit_four(law: str, I: npt.ArrayLike, y: npt.ArrayLike,  # noqa: E741
             y_se: npt.ArrayLike, *, I_se: npt.ArrayLike | None = None) -> FitResult:
    """Weighted fit of a form of :data:`FOUR_CONSTANT` (``law`` JOP_LINEAR or
    PHI_QUADRATIC), started from the three-constant fit (:func:`fit_jop`, (4.7) by
    :func:`fit_law`) with the fourth constant 0; the SE of I propagated by effective variance
    as there (the slope taken numerically). Points as in :func:`fit_law`; fewer than 5 usable
    points, or a failed start, give an unsuccessful result."""
    if law not in FOUR_CONSTANT:
        raise ParameterError(f"invalid law = {law!r}: allowed one of {sorted(FOUR_CONSTANT)}")
    form = FOUR_CONSTANT[law]
    ii, yy, sy, si = _usable(I, y, y_se, I_se)
    n = int(ii.size)
    nan4 = dict.fromkeys(form.names, math.nan)

    def failed(message: str) -> FitResult:
        return FitResult(law, form.equation, nan4, dict(nan4), np.full((4, 4), np.nan),
                         math.nan, n - 4, n, False, message)

    if n < 5:
        return failed("fewer than 5 usable points")
    three = (fit_jop(ii, yy, sy, I_se=si) if law == JOP_LINEAR
             else fit_law("phi", ii, yy, sy, I_se=si))
    if not three.success:
        return failed(f"the three-constant start failed: {three.message}")
    lo, hi = np.asarray(form.lower), np.asarray(form.upper)
    start = np.clip([*three.params.values(), 0.0], np.nextafter(lo, np.inf),
                    np.nextafter(hi, -np.inf))
    sigma = sy
    try:
        p, cov = optimize.curve_fit(form.value, ii, yy, p0=start, sigma=sigma,
                                    absolute_sigma=True, bounds=(form.lower, form.upper),
                                    maxfev=20000)
        if I_se is not None:
            h = 1e-6 * ii
            slope = (form.value(ii + h, *p) - form.value(ii - h, *p)) / (2 * h)
            sigma = np.sqrt(sy**2 + (slope * si) ** 2)
            p, cov = optimize.curve_fit(form.value, ii, yy, p0=p, sigma=sigma,
                                        absolute_sigma=True, bounds=(form.lower, form.upper),
                                        maxfev=20000)
    except (RuntimeError, ValueError) as exc:
        return failed(str(exc))
    chi2 = float(np.sum(((yy - form.value(ii, *p)) / sigma) ** 2))
    err = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return FitResult(law, form.equation, dict(zip(form.names, map(float, p), strict=True)),
                     dict(zip(form.names, map(float, err), strict=True)), cov, chi2, n - 4, n,
                     True)


@quiet
def fit_flow_law(
    df: TableLike,
    law: str,
    *,
    states: Sequence[str] | None = (FlowState.FLOWING,),
    include_x_errors: bool = False,
    x_col: str = "I",
    y_col: str | None = None,
) -> FitResult:
    """Fit a flow law to the one-row-per-run frame of :func:`collect_runs` (columns ``I``,
    ``I_se``, ``<y>``, ``<y>_se``; rows restricted to ``states`` if a ``state`` column
    exists)."""
    y_col = y_col or LAWS[law].y
    d = to_polars(df)
    if states is not None and "state" in d.columns:
        d = d.filter(pl.col("state").is_in(list(states)))
    d = d.drop_nulls([x_col, y_col, f"{y_col}_se"])
    ise = d[f"{x_col}_se"].to_numpy() if include_x_errors and f"{x_col}_se" in d.columns else None
    return fit_law(
        law, d[x_col].to_numpy(), d[y_col].to_numpy(), d[f"{y_col}_se"].to_numpy(), I_se=ise
    )


@quiet
def fit_all(df: TableLike, **kwargs: Any) -> dict[str, FitResult]:
    """:func:`fit_flow_law` for every law whose column is present ('mu1', 'mu2', 'mu3',
    'phi')."""
    d = to_polars(df)
    return {
        law: fit_flow_law(d, law, **kwargs) for law, spec in LAWS.items() if spec.y in d.columns
    }


TABLE1_COLUMNS = ("A1", "A2", "A3", "A4")
OTHER_PARAMS = ("mu1_0", "a1", "mu2_0", "a2", "mu3_0", "a3", "phi_0", "a4")


def table1_row(fits: Mapping[str, FitResult], mu_s: float) -> dict[str, float]:
    """One row in the layout of Table 1 (mu_s, A1, A2, A3, A4) followed by the other fit
    parameters (mu1_0, a1, mu2_0, a2, mu3_0, a3, phi_0, a4); every parameter ``P`` also gets
    ``P_err`` (curve_fit standard error)."""
    row: dict[str, float] = {"mu_s": float(mu_s)}
    for k in TABLE1_COLUMNS + OTHER_PARAMS:
        row[k], row[f"{k}_err"] = math.nan, math.nan
    for f in fits.values():
        for k, v in f.params.items():
            row[k] = v
            row[f"{k}_err"] = f.errors[k]
    return row


def _fmt(v: float, e: float | None) -> str:
    if v is None or not math.isfinite(v):
        return "-"
    if e is None or not math.isfinite(e):
        return f"{v:.3f}"
    return f"{v:.3f}±{e:.3f}"


@quiet
def format_table1(
    rows: Sequence[Mapping[str, float]] | pl.DataFrame, *, reference: bool = True
) -> str:
    """Text table: our fits in the columns of Table 1 (mu_s, A1..A4) plus the other
    parameters, each as value±error; with ``reference`` a ``paper`` line follows each row
    (Table 1 A's and the text values where given)."""
    rr = rows.to_dicts() if isinstance(rows, pl.DataFrame) else [dict(r) for r in rows]
    cols = ("mu_s",) + TABLE1_COLUMNS + OTHER_PARAMS
    width = 14
    lines = ["source " + "".join(f"{c:>{width}}" for c in cols)]
    for r in rr:
        cells = [f"{r['mu_s']:.3g}"] + [
            _fmt(r.get(c, math.nan), r.get(f"{c}_err")) for c in cols[1:]
        ]
        lines.append("fit    " + "".join(f"{c:>{width}}" for c in cells))
        if reference:
            ref = reference_parameters(float(r["mu_s"]))
            rc = [f"{r['mu_s']:.3g}"] + [_fmt(ref[c], None) for c in cols[1:]]
            tag = "paper~ " if ref["interpolated"] else "paper  "
            lines.append(tag + "".join(f"{c:>{width}}" for c in rc))
    return "\n".join(lines)


def print_table1(rows: Sequence[Mapping[str, float]] | pl.DataFrame, **kwargs: Any) -> None:
    """Print :func:`format_table1`."""
    print(format_table1(rows, **kwargs))

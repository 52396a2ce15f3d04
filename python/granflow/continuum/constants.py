"""The constants of a channel prediction, fitted once and then held: the local law per cell
pressure (with the fits' covariances, for prediction bands) and the nonlocal amplitude A; kept
as one Parquet table (:meth:`ModelConstants.save`, :meth:`ModelConstants.load`) from which the
models are built without refitting anything."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import polars as pl

from granflow.errors import ParameterError

from ._checks import FloatArray, bad
from .laws import LocalLaw

#: the file metadata key that marks a constants table (and its format version)
TABLE_KEY = "granflow.model_constants"
TABLE_VERSION = 1


def nearest_pressure(pressures: Iterable[float], pressure: float) -> float:
    """The calibration pressure nearest (in log) to ``pressure`` (a channel's
    sigma_xx d/kn): the one rule for which law a channel takes."""
    if not (math.isfinite(pressure) and pressure > 0):
        raise bad("pressure", pressure, "a finite sigma_xx d/kn > 0")
    return min(pressures, key=lambda q: abs(math.log(q / pressure)))


def _square(values: list[float]) -> FloatArray:
    """A covariance written row-major (3x3 or 4x4) as its matrix."""
    v = np.asarray(values, dtype=np.float64)
    k = math.isqrt(v.size)
    if k * k != v.size:
        raise bad("covariance", values, "k*k row-major values (a 3x3 or 4x4 covariance)")
    return np.reshape(v, (k, k))


@dataclass(frozen=True)
class ModelConstants:
    """One set of model constants.

    ``laws``: the local law per cell pressure p_ext (a channel takes the one nearest its
    sigma_xx d/kn, :meth:`law_for`); ``covariances``: per pressure the (mu, phi) covariances
    in the law's parameter order (LocalLaw.sample), empty where none are known (then no band);
    ``A``: the nonlocal amplitude, with its SE ``A_se`` and what it was fitted on
    (``A_from``, e.g. "W = 40, phi_bar = 0.6" or "given")."""

    laws: Mapping[float, LocalLaw]
    A: float
    A_se: float = math.nan
    A_from: str = ""
    covariances: Mapping[float, tuple[FloatArray, FloatArray]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.laws:
            raise bad("laws", dict(self.laws), "at least one pressure's law")
        for p in self.laws:
            if not (math.isfinite(p) and p > 0):
                raise bad("p_ext", p, "a finite pressure > 0")
        if not (isinstance(self.A, (int, float)) and math.isfinite(self.A) and self.A > 0):
            raise bad("A", self.A, "a finite amplitude > 0")
        extra = set(self.covariances) - set(self.laws)
        if extra:
            raise bad("covariances", sorted(extra), f"pressures among {sorted(self.laws)}")

    def law_for(self, pressure: float) -> tuple[float, LocalLaw]:
        """The calibration pressure nearest (in log) to ``pressure`` (a channel's
        sigma_xx d/kn) and its law."""
        p = nearest_pressure(self.laws, pressure)
        return p, self.laws[p]

    def sample(self, p_ext: float, n: int, seed: int = 0) -> list[LocalLaw]:
        """``n`` laws at ``p_ext`` drawn from its covariances (the prediction band); empty
        where the constants carry no covariance."""
        if p_ext not in self.covariances:
            return []
        mu_cov, phi_cov = self.covariances[p_ext]
        return self.laws[p_ext].sample(mu_cov, phi_cov, n, np.random.default_rng(seed))

    def with_amplitude(self, A: float, A_se: float = math.nan,
                       A_from: str = "given") -> ModelConstants:
        """The same laws with another amplitude."""
        return ModelConstants(self.laws, A, A_se, A_from, self.covariances)

    def to_table(self) -> pl.DataFrame:
        """One row per pressure: the law's fields, the covariances (row-major, 9 or 16 values)
        and the amplitude (the same in every row)."""
        rows = []
        for p, law in sorted(self.laws.items()):
            mu_cov, phi_cov = self.covariances.get(p, (None, None))
            rows.append({"p_ext": p, **asdict(law),
                         "mu_cov": None if mu_cov is None else [float(v) for v in
                                                                np.ravel(mu_cov)],
                         "phi_cov": None if phi_cov is None else [float(v) for v in
                                                                  np.ravel(phi_cov)],
                         "A": self.A, "A_se": self.A_se, "A_from": self.A_from})
        return pl.DataFrame(rows, schema_overrides={"mu_cov": pl.List(pl.Float64),
                                                    "phi_cov": pl.List(pl.Float64)})

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write :meth:`to_table` to the Parquet file ``path`` (marked as a constants table)."""
        import pyarrow.parquet as pq

        from granflow.io import atomic_path

        tab = self.to_table().to_arrow()
        tab = tab.replace_schema_metadata({**(tab.schema.metadata or {}), TABLE_KEY.encode():
                                           json.dumps({"version": TABLE_VERSION}).encode()})
        out = Path(path)
        with atomic_path(out) as tmp:
            pq.write_table(tab, tmp)
        return out

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> ModelConstants:
        """Read constants written by :meth:`save`; a file that is not such a table is refused
        (ParameterError naming it)."""
        import pyarrow.parquet as pq

        f = Path(path)
        if not f.is_file():
            raise bad("path", os.fspath(path), "a constants file written by "
                      "ModelConstants.save (e.g. docs/data/cross_scene/model.parquet)")
        if TABLE_KEY.encode() not in (pq.read_schema(f).metadata or {}):
            raise ParameterError(f"invalid path = {os.fspath(path)!r}: not a model constants "
                                 "table (allowed a file written by ModelConstants.save; the "
                                 "cell fits of fits.parquet are not one)")
        t = pl.read_parquet(f)
        # (a table from before the fourth constants has no c_mu, B_phi: they take 0)
        fields = [k for k in LocalLaw.__dataclass_fields__ if k in t.columns]
        laws, covs = {}, {}
        for r in t.iter_rows(named=True):
            p = float(r["p_ext"])
            laws[p] = LocalLaw(**{k: r[k] for k in fields})
            if r["mu_cov"] is not None and r["phi_cov"] is not None:
                covs[p] = (_square(r["mu_cov"]), _square(r["phi_cov"]))
        first = t.row(0, named=True)
        return cls(laws, float(first["A"]), float(first["A_se"]), str(first["A_from"]), covs)

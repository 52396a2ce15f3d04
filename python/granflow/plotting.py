"""Figures of a finished run directory (``granflow plot DIR``), as PNG files in DIR/plots."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pyarrow.parquet as pq

from granflow.errors import GranflowIOError


def plot_run(directory: str | os.PathLike) -> list[Path]:
    """Write the scene's figures for the run in ``directory``; returns the PNG paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from granflow.analysis import channel as ach
    from granflow.analysis import plots

    d = Path(directory)
    man = d / "manifest.json"
    if not man.exists():
        raise GranflowIOError(f"{d}: no manifest.json (not a granflow run directory)")
    scene = json.loads(man.read_text())["spec"]["scene"]
    out = d / "plots"
    out.mkdir(exist_ok=True)
    paths: list[Path] = []
    series = pq.read_table(d / "series.parquet") if (d / "series.parquet").exists() else None
    if scene == "channel" and (d / "bins.parquet").exists():
        bins = pq.read_table(d / "bins.parquet")
        s = ach.summary(bins, series)
        paths.append(plots.plot_channel_velocity(s, out / "velocity.png"))
        paths.append(plots.plot_channel_fields(s, out / "fields.png"))
        paths.append(plots.plot_channel_mu_phi_I(s, out / "mu_phi_I.png"))
    if series is not None and "t" in series.column_names:
        t = series["t"].to_numpy()
        cols = [c for c in ("vcm_y", "ke_trans", "mu1", "phi", "p") if c in series.column_names]
        if cols:
            fig, axes = plt.subplots(len(cols), 1, figsize=(6, 2.2 * len(cols)), sharex=True)
            axes = [axes] if len(cols) == 1 else list(axes)
            for ax, c in zip(axes, cols, strict=True):
                ax.plot(t, series[c].to_numpy(), lw=0.8)
                ax.set_ylabel(c)
            axes[-1].set_xlabel("t")
            fig.tight_layout()
            p = out / "series.png"
            fig.savefig(p, dpi=120)
            plt.close(fig)
            paths.append(p)
    return paths

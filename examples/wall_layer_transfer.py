"""The channel's wall layer as local laws per distance (granflow.continuum.wall_layer),
fitted once on the runs at one width of a channel dataset and held for the runs of another
dataset (a reproduce_000 dataset, or one run's directory of `granflow run`); the bulk beyond
4 d is the nonlocal model with the committed calibration and a given bulk amplitude.

    python examples/wall_layer_transfer.py [--fit docs/data/reproduce_000] [--W 40]
           [--predict docs/data/reproduce_000_widths] [--A 0.433]

Prints the laws and, per predicted run, the whole-channel misfit of u - u_slip relative to
the run's u_max - u_slip (the cross-scene report's measure), its parts in the layer and the
bulk, and u_max - u_slip of the model over the run's.
"""

from __future__ import annotations

import argparse
import warnings

import polars as pl
from granflow.continuum.calibration import calibrate
from granflow.continuum.channel_model import cases_of
from granflow.continuum.wall_layer import fit_layer_laws, layered_table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", default="docs/data/reproduce_000",
                    help="the channel dataset the laws are fitted on")
    ap.add_argument("--W", type=float, default=40.0, help="the width whose runs fit the laws")
    ap.add_argument("--predict", default="docs/data/reproduce_000_widths",
                    help="the dataset or run directory predicted")
    ap.add_argument("--A", type=float, default=0.433,
                    help="the bulk amplitude (docs/cross_scene.md, 'measured in the bulk')")
    ap.add_argument("--cell", default="docs/data/cross_scene/points.parquet",
                    help="the cell runs the bulk's law is calibrated on")
    a = ap.parse_args()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # (unconverged runs are named, left out)
        train = [c for c in cases_of(a.fit) if c.W == a.W]
        held = cases_of(a.predict)
    laws = fit_layer_laws(train)
    cal = calibrate(pl.read_parquet(a.cell))
    print(f"laws fitted on {len(train)} runs at W = {a.W:g} of {a.fit}:")
    print(laws.table())
    print(f"held for {a.predict} (bulk A = {a.A:g}):")
    print(layered_table(held, cal, laws, a.A))


if __name__ == "__main__":
    main()

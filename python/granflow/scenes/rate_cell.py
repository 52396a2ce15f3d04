"""The rate-controlled cell: 002's triclinic periodic cell sheared at an imposed rate with a normal
stress held at p_ext: the protocol LAMMPS runs (``fix deform/pressure`` with
``erate/rescale``), and the one that reaches the slow flows below the stress-controlled cell's
arrest.

Everything but the driving is :class:`granflow.scenes.cell.ShearCell`'s: material, compaction,
observables (the same ``series`` columns), checkpoints. After the compaction under p_ext alone
the kernel holds L_xy = dv_x/dy at ``shear_rate`` (src/domain/prcell.rs, ``drive_at_rate``)
and drives only the normal stress:

- ``normal="pressure"``: the mean pressure tr(sigma)/3, with an isotropic dilation (as the
  stress-controlled cell);
- ``normal="yy"``: sigma_yy, the gradient direction's, with the x and z lengths fixed (LAMMPS's
  ``fix deform/pressure`` on y alone).

The barostat's cell mass sets how fast the normal stress follows its target, not its mean (the
time integral of the drive is the change of the cell momentum). The rate is given as 002's
inertial number at the target stress, I = |D| a / sqrt(p_ext/rho) with |D| = dv_x/dy / 2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from granflow import _core
from granflow.errors import ParameterError

from ._base import register
from .cell import ShearCell

NORMALS = ("pressure", "yy")


@register("rate_cell")
@dataclass
class RateCell(ShearCell):
    """Rate-controlled cell scene (module docstring); the parameters are :class:`ShearCell`'s
    with ``tau_ratio`` 0 (no imposed shear stress: the compaction's), and:

    Args:
        inertial_number: The imposed rate as 002's I at p_ext (0 < I <= 1): dv_x/dy =
            2 I sqrt(p_ext/rho) / a (:attr:`shear_rate`).
        normal: The normal stress held at p_ext, "pressure" or "yy" (module docstring).
    """

    tau_ratio: float = 0.0
    inertial_number: float = 0.01
    normal: str = "pressure"

    scene_name: ClassVar[str]

    def __post_init__(self) -> None:
        if self.tau_ratio != 0:
            raise ParameterError(f"invalid tau_ratio = {self.tau_ratio}: allowed 0 (the rate "
                                 "cell imposes a rate, not a shear stress)")
        i = self.inertial_number
        if not (isinstance(i, (int, float)) and math.isfinite(i) and 0 < i <= 1):
            raise ParameterError(f"invalid inertial_number = {i!r}: allowed 0 < I <= 1 (finite)")
        if self.normal not in NORMALS:
            raise ParameterError(f"invalid normal = {self.normal!r}: allowed one of {NORMALS}")
        super().__post_init__()

    @property
    def shear_rate(self) -> float:
        """The imposed dv_x/dy = L_xy = 2 I sqrt(p_ext/rho)/a (002's |D| is half of it)."""
        return 2.0 * self.inertial_number * math.sqrt(self.p_ext / self.mat.density) / self.a

    def _drive(self, core: _core.Sim) -> None:
        core.set_rate(self.shear_rate, float(self.p_ext), gradient=self.normal == "yy")

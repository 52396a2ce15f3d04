"""The vertical channel of 000_260a8780d7c638a6 (Debnath, Kesava Rao & Kumaran 2022).

Polydisperse frictional spheres between two flat frictional walls at x = 0 and x = W, periodic
in y (vertical; gravity along -y) and z. Units: d (mean diameter), rho_p, sqrt(d/g).

Preparation (paper §2, fig. 2, "fill and release"): "Initially, a flat surface is placed at the
bottom of the channel. The channel is filled by raining the particles uniformly under the effect
of gravity up to a height H - Delta H. After the particles settle, the bottom is removed and the
periodic boundary conditions are imposed". ``preparation`` picks one of two protocols; both
take N from phi_bar (whole particles: N <V_p> = phi_bar W B H to the nearest particle, the
30/40/30 % mix by exact number fractions), so the achieved phi_bar is exact:
(total particle volume) / (W H B).

``preparation = "rain"`` (the default; 000's protocol):

* rain (``_rain``): the N spheres are placed at random (``_core.insert_spheres``) in a dilute
  column at volume fraction ``rain_phi`` (default 0.02) over the whole W x B section, from the
  floor (a wall at y = 0) up to h_col = V_s/(W B rain_phi) + 2 d_max, and released at once
  under gravity with the run's own laws: the particles' (kn, k_t, e_n, friction, damping, form)
  and the particle-wall law (``wall_*``) on the side walls and on the floor, at the run's dt.
  The kernel cannot insert particles during a run, so the rain is one column released at once
  rather than a stream: every sphere falls freely at the same acceleration, the column keeps
  its concentration until it lands, and so it lands on the growing bed as a uniform rain of
  flux ~ rain_phi sqrt(2 g h), lowest spheres first. ``rain_phi`` sets how the rain packs (a
  more dilute column arrives at a lower rate and a higher speed, and packs denser; docs/channel.md,
  "Preparation") and what it costs (the fall time sqrt(2 h_col) ~ rain_phi^-1/2);
  Two ways to a cheaper rain, both off by default (docs/channel.md, "Preparation", measures
  what they change): ``rain_kn`` rains softer (fewer steps; bounded below so that the fastest
  impacts overlap by at most ``RAIN_MAX_IMPACT`` d) and stiffens the settled bed to the run's
  laws on the floor before the release; ``rain_tiles`` rains one z-slab of depth B/rain_tiles
  and repeats it along z. The rain's neighbour lists use a skin of at least ``RAIN_SKIN``
  (a falling column rebuilds them often; the physics is the same);
* settle: checked every ``SETTLE_CHECK_TIME``; the bed is at rest when the kinetic energy per
  particle is below ``settle_ke`` m g d after the fall time sqrt(2 h_col), and its top (the
  highest sphere's top) moved less than ``RAIN_TOP_TOL`` = 0.01 d since the last check
  (giving up, as the pour, after ``SETTLE_T_BASE`` + ``SETTLE_T_FALLS`` t_fall);
* level and refusal: the bed fills H - Delta H up to its *level* (``_bed_level``: the height
  at which its spheres above the core's bottom would end at the core's fraction, a flat top
  of the same solid; the core is the slab of centres ``RAIN_CORE_BOTTOM`` d_max above the
  floor to ``RAIN_CORE_TOP`` d_max below the top), Delta H = H - level. A level above H
  (phi_bar above what the rain packs in this channel) is refused by ``prepare``, before the
  run's simulation exists: a ParameterError naming phi_bar and the largest phi_bar that fits,
  phi_bar H/level rounded down to 3 decimals (an estimate: rains of other seeds differ by
  ~0.005);
* seam (``_close_seam``): the rough top stands ~1 d above the level (000's "H - Delta H" of a
  rough bed is its level). Where its highest spheres rise above H they cross the seam at the
  release, onto the bed's flat bottom layer; there they are shrunk until no pair overlaps by
  more than ``SEAM_START_OVERLAP`` of its mean diameter (with the spheres they would overlap),
  then grown back in steps of ``SEAM_GROWTH``, each relaxed frictionless at the run's kn
  without gravity (as the pour's squeeze) until no overlap exceeds ``PREP_MAX_OVERLAP``. Only
  the seam's spheres move (``prep_info["seam_shift"]``, the largest displacement: ~0.7 d);
  without it a bed could hold no phi_bar above its fraction up to the highest sphere (~0.575
  at W = 20, H = 20 against a core of ~0.613: docs/channel.md, "Preparation");
* release (``_release``): the floor goes, y becomes periodic with period H (Delta H stays empty
  above the bed's level), the velocities start at zero (the bed was at rest, below
  ``settle_ke``) and the tangential histories at zero; law and dt are the run's.
  ``prep_info`` records the bed's top and level, Delta H, the bed's fraction up to its top
  (``phi_bed``) and in its core (``phi_bed_core``), the spheres across the seam and their
  largest shift.

``preparation = "pour"`` (the former default, kept bit for bit: the committed 000 campaign and
the benchmarks that record a channel were prepared with it):

* pour (``_pour``): from a random insertion at phi = ``PHI_INSERT`` = 0.3, frictionless, with
  min(kn, prep_kn = 1e4), e_n = ``POUR_E_N`` = 0.3, dt = t_c/``POUR_DT_DIVISOR`` = t_c/20 for
  speed; the bed is settled when the kinetic energy per particle is below ``settle_ke`` m g d
  (checked every ``SETTLE_CHECK_TIME``, giving up after ``SETTLE_T_BASE`` + ``SETTLE_T_FALLS``
  t_fall = 40 + 4 t_fall); friction and the run's stiffness, restitution and dt apply from the
  release on (all tangential histories start at zero at the release);
* relax (``_relax``): the soft pour's overlaps are relaxed at the run's kn (``RELAX_ROUNDS`` x
  ``RELAX_ROUND_STEPS`` = 1000 damped steps, velocities quenched) so that a stiff run does not
  start with stored elastic energy;
* squeeze (``_squeeze``): if the settled bed is taller than H (phi_bar close to the packing
  fraction) it is compressed affinely into [0, H) (its top ``SQUEEZE_TOP_MARGIN`` d_max below
  H) and relaxed without gravity (at most ``SQUEEZE_ROUNDS`` x ``SQUEEZE_ROUND_STEPS`` steps)
  before the release; if that relaxation leaves overlaps >= ``PREP_MAX_OVERLAP`` = 0.01 d the
  packing cannot hold phi_bar (the densest bed depends on the channel's size: the pour packs to
  ~0.57-0.59 up to its rough top in channels 8-10 d wide, ~0.61 at W = 20 d; squeezed to 0.63
  the bed keeps overlaps of 0.017-0.019 d at W = 8-10 d, 0.008 d at W = 20 d) and ``prepare``
  refuses phi_bar (docs/channel.md, "Input checks");
* release (``_release``): the floor goes, y becomes periodic with period H, the run's law and
  dt apply.

Statistics (000 eqs 2.1–2.5) are taken inside the kernel's step loop (``granflow._core``
samplers ``channel_bins`` and ``channel_series``, src/sampling/channel.rs): every
``sample_every`` steps, averaged over windows of ``window`` samples; each window is one row per
bin of the ``bins`` table and each sample one row of the ``series`` table (docs/columns.md).
The bins across x: the two wall bins are ``wall_bin`` wide, the interior is tiled by
``n = round((W - 2 wall_bin)/bin_width)`` equal bins (width adjusted to tile exactly). How each
quantity is binned (centres, exact sphere–slab volumes, contact stress along branch vectors,
fluctuations about the window's bin means) is said in src/sampling/channel.rs.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

import numpy as np
import polars as pl
import pyarrow as pa

from granflow import _core
from granflow.errors import ConfigurationError, ParameterError
from granflow.material import MATERIAL_000, Material, kernel_default_skin
from granflow.simulation import Box, ContactLaw, Simulation, Wall, run_chunked
from granflow.sizes import SizeDist, solid_volume
from granflow.states import FlowState

from ._base import (
    SampleTables,
    SceneParameters,
    check_run_keys,
    read_checkpoint_state,
    register,
    run_with_checkpoints,
    write_checkpoint,
)

#: random close packing: no phi_bar above it can be packed (refused on construction); below it
#: the densest bed the fill and release reaches depends on the channel's size, so ``prepare``
#: refuses a phi_bar whose squeezed bed keeps overlaps >= PREP_MAX_OVERLAP d
RCP = 0.64
PREP_MAX_OVERLAP = 0.01

# -- the preparation's protocol (module docstring) ---------------------------------------------
#: volume fraction of the random insertion the pour starts from
PHI_INSERT = 0.3
#: restitution of the (frictionless, soft) pour and of the relaxations
POUR_E_N = 0.3
#: the pour's and the relaxations' dt = t_c / POUR_DT_DIVISOR (lightest pair of their law)
POUR_DT_DIVISOR = 20
#: the pour gives up after SETTLE_T_BASE + SETTLE_T_FALLS t_fall (t_fall = sqrt(2 h_fill))
SETTLE_T_BASE = 40.0
SETTLE_T_FALLS = 4
#: the pour's kinetic energy is checked every SETTLE_CHECK_TIME sqrt(d/g)
SETTLE_CHECK_TIME = 0.5
#: a squeezed bed's top ends SQUEEZE_TOP_MARGIN d_max below H
SQUEEZE_TOP_MARGIN = 0.5
#: the squeezed bed relaxes in at most SQUEEZE_ROUNDS rounds of SQUEEZE_ROUND_STEPS steps
SQUEEZE_ROUNDS = 20
SQUEEZE_ROUND_STEPS = 200
#: the soft pour's overlaps relax at the run's kn in RELAX_ROUNDS rounds of RELAX_ROUND_STEPS
RELAX_ROUNDS = 10
RELAX_ROUND_STEPS = 100
#: the inserted region is taller than the solid needs by HEADROOM_DMAX d_max
HEADROOM_DMAX = 2

# -- the rain's protocol (module docstring) ----------------------------------------------------
#: the preparations ``Channel.preparation`` allows: 000's rain (the default) and the soft pour
PREPARATIONS = ("rain", "pour")
#: the rained bed is at rest when, besides the kinetic-energy test, its top moved less than
#: RAIN_TOP_TOL d over the last SETTLE_CHECK_TIME
RAIN_TOP_TOL = 0.01
#: the densest column ``rain_phi`` allows (denser, the column lands as a slab, not as rain)
RAIN_PHI_MAX = 0.3
#: the rain's neighbour-list skin, at least: a falling column rebuilds its lists every
#: skin/(2 v dt) steps, and a dilute one holds few extra pairs in a wide skin
RAIN_SKIN = 1.0
#: the deepest impact overlap (d) a soft rain (``rain_kn``) may allow: at W = 20, H = 40, B = 10,
#: rain_phi = 0.05 (impacts up to 28 sqrt(g d)) kn = 1e5 (0.05 d) packs the bed's core at
#: 0.6133 +- 0.0005 (3 seeds), rain_kn = 1e4 (0.17 d) at 0.6121 +- 0.0004, and rain_phi =
#: 0.02 at rain_kn = 1e4 (0.25 d) went unstable; kn = 1e6 and 1e5 agree (docs/channel.md)
RAIN_MAX_IMPACT = 0.05
#: a rained bed whose rough top crosses the seam: those spheres start shrunk so that no pair
#: overlaps by more than SEAM_START_OVERLAP of its mean diameter (below the kernel's 0.25),
#: at least SEAM_MIN_SCALE of their size, and grow back by SEAM_GROWTH of it per stage
SEAM_START_OVERLAP = 0.2
SEAM_MIN_SCALE = 0.05
SEAM_GROWTH = 0.1
#: the thinnest slab ``rain_tiles`` may rain (thinner, the copies would repeat within a few
#: particles)
RAIN_TILE_MIN = 8.0
#: a soft rain's stiffened bed is checked for rest every STIFFEN_CHECK_TIME sqrt(d/g)
STIFFEN_CHECK_TIME = 0.1
#: the bed's core, for ``prep_info["phi_bed_core"]``: the particles with centres between
#: RAIN_CORE_BOTTOM d_max above the floor and RAIN_CORE_TOP d_max below the bed's top
RAIN_CORE_BOTTOM = 2.0
RAIN_CORE_TOP = 3.0


def _min_image(dx: np.ndarray, h: float, depth: float) -> np.ndarray:
    """Displacements with y (period ``h``) and z (period ``depth``) to the nearest image."""
    out = np.array(dx, dtype=float, copy=True)
    out[..., 1] -= h * np.round(out[..., 1] / h)
    out[..., 2] -= depth * np.round(out[..., 2] / depth)
    return out


def _floor_walls(width: float) -> list[Wall]:
    """The preparation's walls: the side walls at x = 0 and ``width``, and the temporary floor
    at y = 0."""
    return [Wall(0, 0.0, 1.0), Wall(0, width, -1.0), Wall(1, 0.0, 1.0)]


class _Stages:
    """The preparation's stages, one line each on stderr (when ``progress``, or None and
    stderr is a terminal) with the wall seconds since the start; a call returns them."""

    def __init__(self, progress: bool | None) -> None:
        self.show = sys.stderr.isatty() if progress is None else bool(progress)
        self.t0 = time.perf_counter()

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def __call__(self, msg: str) -> float:
        t = self.elapsed
        if self.show:
            print(f"[channel preparation {t:7.1f} s] {msg}", file=sys.stderr, flush=True)
        return t


@dataclass
class _Pour:
    """The state the pour hands to the next stages."""

    d: np.ndarray
    x: np.ndarray
    h_fill: float
    vs: float
    law: ContactLaw
    dt: float
    walls: list[Wall]
    time: float = 0.0
    steps: int = 0
    ke: float = float("inf")


@register("channel")
@dataclass
class Channel(SceneParameters):
    """Vertical channel scene. The material is 000's (:data:`granflow.material.MATERIAL_000`,
    §2, App. A) unless ``material`` says otherwise; the flat overrides (``sizes``, ``kn``,
    ``kt_ratio``, ``e_n``, ``mu``, ...), ``dt``, ``seed`` and ``threads`` are every scene's
    (:class:`~granflow.scenes.SceneParameters`); ``dt`` None is the material's rule (000: 1.2e-4
    sqrt(1e6/kn) sqrt(d/g)). The geometry defaults are a reduced channel for quick runs, not the
    paper's: 000 runs W = 60-150 d, B = 40 d, H = 60 d + Delta H (§2), set them for its scale.
    The kernel is built by :meth:`prepare`.

    Args:
        W: The channel's width (walls at x = 0 and x = W), in d.
        H: The periodic height (along gravity, -y), in d.
        B: The periodic depth (z), in d.
        phi_bar: The mean volume fraction (whole particles: the achieved value is in
            ``prep_info["phi_bar_achieved"]``).
        wall_kn: The walls' normal stiffness (None: the particles' kn).
        wall_e_n: The walls' restitution (None: the particles' e_n).
        wall_mu: The walls' friction coefficient (None: the particles' mu). The walls' k_t is
            the kernel's default, 2/7 of their kn.
        bin_width: The interior bins' width across x, in d (adjusted to tile exactly).
        wall_bin: The width of the bin at each wall, in d.
        sample_every: Steps between two samples of the ``bins`` and ``series`` tables (None: no
            statistics).
        window: Samples averaged into one row of the ``bins`` table.
        settle_ke: The rain (or pour) is settled when the kinetic energy per particle is below
            this, in m g d.
        prep_kn: The soft pour's stiffness (``preparation = "pour"`` only; the pour uses
            min(kn, prep_kn)).
        preparation: How :meth:`prepare` packs the channel: ``"rain"`` (000's protocol, fig. 2:
            rained with the run's own laws onto a temporary floor, filling H - Delta H) or
            ``"pour"`` (the soft frictionless pour, then a squeeze into H; the module
            docstring).
        rain_phi: The volume fraction of the dilute random column the rain falls from
            (``preparation = "rain"``): a more dilute rain falls from higher, arrives at a lower
            rate and a higher speed, and packs denser (docs/channel.md, "Preparation": the
            core at 0.622 at 0.02, 0.613 at 0.05), at the cost of a longer fall; 0.02 reaches
            phi_bar = 0.61 at W = 20, H = 20.
        rain_kn: The rain's stiffness (``preparation = "rain"``): None rains with the run's
            kn; a lower value rains softer (particles and walls scaled alike, the rest of the
            laws the run's, dt the material's rule at rain_kn: sqrt(kn/rain_kn) times fewer
            steps), then stiffens the settled bed to the run's laws on the floor and settles
            it again before the release (docs/channel.md, "Preparation", for what it changes).
        rain_tiles: Rain one slab of depth B/rain_tiles and repeat it rain_tiles times along z
            (periodic there, so the copies join without a seam): rain_tiles times fewer
            spheres to rain; the bed is the slab's, periodic in z with period B/rain_tiles until
            the flow decorrelates the copies; phi_bar is reached to rain_tiles particles.
    """

    W: float = 20.0
    H: float = 30.0
    B: float = 40.0
    phi_bar: float = 0.60
    wall_kn: float | None = None
    wall_e_n: float | None = None
    wall_mu: float | None = None
    bin_width: float = 1.0
    wall_bin: float = 1.5
    sample_every: int | None = 100
    window: int = 50
    settle_ke: float = 1e-4
    prep_kn: float = 1e4
    preparation: str = "rain"
    rain_phi: float = 0.02
    rain_kn: float | None = None
    rain_tiles: int = 1

    scene_name: ClassVar[str]
    default_material: ClassVar[Material] = MATERIAL_000
    #: the runner writes the statistical-error report of a finished run
    error_report: ClassVar[bool] = True
    #: gravity along -y, of unit magnitude (the unit of acceleration, g)
    gravity: ClassVar[tuple[float, float, float]] = (0.0, -1.0, 0.0)

    def __post_init__(self) -> None:
        self._resolve_material()
        self._validate()
        self._sim: Simulation | None = None
        self.prep_info: dict[str, Any] = {}
        self._tables = SampleTables()
        self.pbc = (False, True, True)

    # -- parameters ------------------------------------------------------------------------
    def _validate(self) -> None:
        """Refuse bad input on construction, before anything runs (docs/channel.md, "Input
        checks"); what only the preparation can tell (a phi_bar this channel cannot pack) is
        refused by :meth:`prepare`. The material checks its own fields."""

        def need(cond: bool, name: str, value: Any, allowed: str) -> None:
            if not cond:
                raise ParameterError(f"invalid {name} = {value!r}: allowed {allowed}")

        def real(v: Any) -> bool:
            return (isinstance(v, (int, float, np.integer, np.floating))
                    and not isinstance(v, bool) and bool(np.isfinite(v)))

        def positive(name: str) -> None:
            v = getattr(self, name)
            need(real(v) and v > 0, name, v, "a finite number > 0")

        mat = self.mat
        sd = mat.sizes
        dmax = sd.max
        for name in ("settle_ke", "prep_kn"):
            positive(name)
        need(isinstance(self.preparation, str) and self.preparation in PREPARATIONS,
             "preparation", self.preparation,
             " or ".join(repr(p) for p in PREPARATIONS) + " (000's rain, or the soft pour)")
        need(real(self.rain_phi) and 0 < self.rain_phi <= RAIN_PHI_MAX, "rain_phi",
             self.rain_phi, f"0 < rain_phi <= {RAIN_PHI_MAX} (a dilute column)")
        need(isinstance(self.rain_tiles, (int, np.integer)) and not isinstance(
            self.rain_tiles, bool) and self.rain_tiles >= 1
             and (self.rain_tiles == 1 or self.B / self.rain_tiles >= RAIN_TILE_MIN),
             "rain_tiles", self.rain_tiles, f"an integer >= 1, B/rain_tiles >= "
             f"{RAIN_TILE_MIN:g} d where > 1 (B = {self.B:g})")
        need(self.rain_kn is None or (real(self.rain_kn) and 0 < self.rain_kn <= mat.kn_value),
             "rain_kn", self.rain_kn,
             f"0 < rain_kn <= kn = {mat.kn_value:g}, or None for the run's kn")
        if self.rain_kn is not None and real(self.phi_bar) and real(self.H):
            # the last spheres land at v = sqrt(2 g h_col) and overlap the bed by up to
            # v sqrt(m_eff/kn) (the heaviest pair, undamped): a soft rain may not press them
            # in deeper than RAIN_MAX_IMPACT d, or than the run's own law does
            v = float(np.sqrt(2 * (self.phi_bar * self.H / self.rain_phi + HEADROOM_DMAX * dmax)))
            m_eff = 0.5 * mat.density * np.pi / 6 * dmax**3
            kn_min = min(mat.kn_value, m_eff * (v / RAIN_MAX_IMPACT) ** 2)
            need(self.rain_kn >= kn_min, "rain_kn", self.rain_kn,
                 f"rain_kn >= {kn_min:.3g} (the rain lands at up to {v:.3g} sqrt(g d); "
                 f"softer, its impacts would overlap by more than {RAIN_MAX_IMPACT:g} d)")
        # a wall value left at None is the particle value; 0 is not "unset"
        need(self.wall_kn is None or (real(self.wall_kn) and self.wall_kn > 0), "wall_kn",
             self.wall_kn, "a finite number > 0, or None for kn")
        need(self.wall_e_n is None or (real(self.wall_e_n) and 0 < self.wall_e_n <= 1),
             "wall_e_n", self.wall_e_n, "0 < wall_e_n <= 1, or None for e_n")
        need(self.wall_mu is None or (real(self.wall_mu) and self.wall_mu >= 0), "wall_mu",
             self.wall_mu, "a finite number >= 0, or None for mu")
        need(isinstance(self.seed, (int, np.integer)) and not isinstance(self.seed, bool)
             and self.seed >= 0, "seed", self.seed, "an integer >= 0")

        # geometry: the kernel needs a periodic period >= 2 (d_max + skin)
        skin = _skin(mat)
        need(real(self.W) and self.W >= 5 * dmax, "W", self.W,
             f">= 5 d_max = {5 * dmax:g} (a channel a few diameters wide)")
        h_min = max(5 * dmax, 2 * (dmax + skin))
        need(real(self.H) and self.H >= h_min, "H", self.H,
             f">= max(5 d_max, 2 (d_max + skin)) = {h_min:g} (a periodic height a few "
             "diameters tall)")
        need(real(self.B) and self.B >= 2 * (dmax + skin) + 0.5, "B", self.B,
             f">= {2 * (dmax + skin) + 0.5:g} (two interaction ranges)")
        # bins: two wall bins and at least one interior bin of ~bin_width (bin_edges() would
        # otherwise make one interior bin narrower than bin_width or, below half a bin, none:
        # the right-hand "wall bin" then spans the interior too)
        positive("bin_width")
        positive("wall_bin")
        interior = self.W - 2 * self.wall_bin
        need(interior >= self.bin_width, "W/wall_bin/bin_width",
             (self.W, self.wall_bin, self.bin_width),
             f"W >= 2 wall_bin + bin_width = {2 * self.wall_bin + self.bin_width:g}, i.e. "
             f"bin_width <= W - 2 wall_bin = {interior:g} (two wall bins and at least one "
             "interior bin)")

        need(real(self.phi_bar) and 0 < self.phi_bar <= RCP, "phi_bar", self.phi_bar,
             f"0 < phi_bar <= {RCP} (above random close packing the spheres cannot be packed; "
             "below it, prepare() refuses a phi_bar this channel's fill and release cannot "
             "pack)")
        vol = self.phi_bar * self.W * self.H * self.B
        v_mean = sd.mean_volume
        # the preparation's own count (to the nearest whole particle, at least 1) when small
        n = vol / v_mean if vol > 10 * v_mean else len(sd.diameters_for_volume(vol, self.seed))
        need(n >= 2, "phi_bar", self.phi_bar,
             f"a value that puts at least 2 particles in W H B = "
             f"{self.W * self.H * self.B:g} (this one gives {n:g})")

        # dt: the kernel refuses dt > t_c/10 of the run's law (stiffest, lightest pair) when
        # the run's simulation is built, i.e. after the pour; refuse it here instead
        dt = self.timestep
        need(dt is not None and real(dt) and dt > 0, "dt", self.dt,
             "a finite number > 0, or None for the material's rule")
        assert dt is not None
        t_c = mat.contact_time("lightest")
        need(dt <= t_c / 10, "dt", dt,
             f"<= t_c/10 = {t_c / 10:.4g} (t_c = {t_c:.4g}, the contact time of the lightest "
             f"pair, d = {sd.min:g}, at kn = {mat.kn_value:g}; beyond it the "
             "integration is inaccurate or unstable)")
        need(self.sample_every is None
             or (isinstance(self.sample_every, int) and self.sample_every >= 1), "sample_every",
             self.sample_every, "an integer >= 1, or None for no statistics")
        need(isinstance(self.window, int) and self.window >= 1, "window", self.window,
             "an integer >= 1")

    @property
    def timestep(self) -> float | None:
        """The run's dt: ``dt``, or the material's rule."""
        return self.dt if self.dt is not None else self.mat.dt()

    def size_dist(self) -> SizeDist:
        """The material's size distribution."""
        return self.mat.sizes

    @classmethod
    def from_spec(cls, params: Mapping[str, Any], seed: int = 0,
                  threads: int | None = None) -> Channel:
        """A channel from a TOML spec's ``params`` (the field names)."""
        check_run_keys(params, cls)
        return cls(**dict(params), seed=seed, threads=threads)

    def parameters(self) -> dict[str, Any]:
        """Every parameter (the material's fields flat, ``law`` as the kernel resolves it,
        ``dt`` the run's, ``n`` the particle count once prepared) and the preparation's record
        (``prep_*``)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)
               if f.name not in ("threads", "material")}
        out.update(self.mat.parameters())
        out.update(law=self.law.as_dict(), dt=self.timestep, n=self.prep_info.get("n"))
        out.update({f"prep_{k}": v for k, v in self.prep_info.items()})
        return out

    @property
    def law(self) -> ContactLaw:
        """The particles' contact law."""
        return self.mat.law()

    @property
    def wall_law(self) -> ContactLaw:
        """The walls' contact law."""
        law = self.law
        return ContactLaw(kn=self.wall_kn or law.kn, e_n=self.wall_e_n or law.e_n,
                          mu=law.mu if self.wall_mu is None else self.wall_mu,
                          kt=None,  # the kernel's default, 2/7 of the wall's kn (LawSpec)
                          xi_t_ratio=law.xi_t_ratio, form=law.form)

    def bin_edges(self) -> np.ndarray:
        """The bin edges across x (module docstring)."""
        interior = self.W - 2 * self.wall_bin
        n = max(int(round(interior / self.bin_width)), 0)
        inner = np.linspace(self.wall_bin, self.W - self.wall_bin, n + 1) if n else np.array(
            [self.wall_bin])
        return np.concatenate([[0.0], inner, [self.W]]) if n else np.array(
            [0.0, self.wall_bin, self.W])

    # -- preparation -----------------------------------------------------------------------
    def _relax_material(self, kn: float) -> Material:
        """The pour's and the relaxations' material: frictionless, Hooke, e_n = POUR_E_N, the
        kernel's k_t, at ``kn``."""
        return self.mat.with_(kn=kn, e_n=POUR_E_N, mu=0.0, kt_ratio=None, form="hooke")

    def _pour(self, say: _Stages) -> _Pour:
        """Stage 1, pour: random insertion at PHI_INSERT in a tall box on a floor, poured
        under gravity (soft, frictionless) until the bed settles."""
        d, vs, h_fill, x = self._column(PHI_INSERT)
        soft = self._relax_material(min(self.mat.kn_value, self.prep_kn))
        prep_law = soft.law()
        dt = soft.contact_time("lightest", d) / POUR_DT_DIVISOR
        sim = self._floor_sim(x, d, h_fill, self.B, prep_law, dt)
        say(f"inserted {len(d)} spheres at phi = {PHI_INSERT} in a {self.W:g} x {h_fill:.4g} x "
            f"{self.B:g} box; pouring (kn = {prep_law.kn:g}, frictionless, dt = {dt:.3g})")
        ke = self._settle(sim, d, h_fill, "the bed")
        return _Pour(d, sim.get_positions(), h_fill, vs, prep_law, dt, _floor_walls(self.W),
                     float(sim.time), sim.step, ke)

    def _floor_sim(self, x: np.ndarray, d: np.ndarray, h: float, depth: float,
                   law: ContactLaw, dt: float | None, wall_law: ContactLaw | None = None,
                   skin: float | None = None) -> Simulation:
        """A preparation's simulation: the spheres in a W x h x depth box (periodic along z
        only) on a floor (:func:`_floor_walls`), under gravity."""
        box = Box(length=(self.W, h, depth), periodic=(False, False, True))
        return Simulation(x, d, box, law, walls=_floor_walls(self.W), wall_law=wall_law,
                          gravity=self.gravity, dt=dt, threads=self.threads,
                          density=self.mat.density,
                          skin=self.mat.skin if skin is None else skin)

    def _column(self, phi: float, depth: float | None = None
                ) -> tuple[np.ndarray, float, float, np.ndarray]:
        """The run's spheres (phi_bar's count; in a slab of ``depth`` < B, the slab's) at
        random at volume fraction ``phi`` in a W x h x depth column above the floor:
        diameters, solid volume, h, positions."""
        depth = self.B if depth is None else depth
        vol_target = self.phi_bar * self.W * self.H * depth
        d = self.size_dist().diameters_for_volume(vol_target, self.seed)
        vs = solid_volume(d)
        h = vs / (self.W * depth * phi) + HEADROOM_DMAX * d.max()
        x = np.asarray(_core.insert_spheres(
            d, (0.0, 0.0, 0.0), (self.W, h, depth), (False, False, True), self.seed))
        return d, vs, h, x

    def _settle(self, sim: Simulation, d: np.ndarray, h: float, what: str,
                top_tol: float | None = None, check_time: float = SETTLE_CHECK_TIME) -> float:
        """Run the falling column of height ``h`` until it is at rest: kinetic energy per
        particle below ``settle_ke`` m g d after the fall time sqrt(2 h) and, with
        ``top_tol``, its top (highest sphere's top) within ``top_tol`` d of the last check
        (checks every ``check_time``); refused (naming settle_ke) past SETTLE_T_BASE +
        SETTLE_T_FALLS fall times. Returns the kinetic energy per particle."""
        m = sim.core.masses()
        t_fall = float(np.sqrt(2 * h))
        t_max = SETTLE_T_BASE + SETTLE_T_FALLS * t_fall
        check = max(int(check_time / sim.timestep), 1)
        ke, top_before = np.inf, np.inf
        while sim.time < t_max:
            sim.run(check, progress=False)
            ke = sim.energies()["kinetic_translational"] / len(d) / float(np.mean(m))
            if top_tol is None:
                if ke < self.settle_ke and sim.time > t_fall:
                    return float(ke)
                continue
            top = float(np.max(sim.get_positions()[:, 1] + d / 2))
            if ke < self.settle_ke and sim.time > t_fall and abs(top - top_before) < top_tol:
                return float(ke)
            top_before = top
        raise ParameterError(
            f"invalid settle_ke = {self.settle_ke}: {what} did not settle within "
            f"t = {t_max:.0f} sqrt(d/g) (kinetic energy per particle {ke:.2e} m g d); "
            "allowed a larger value"
        )

    def _squeeze(self, p: _Pour, x: np.ndarray) -> np.ndarray:
        """Stage 2a, squeeze: a bed taller than H is compressed affinely into [0, H) and relaxed
        without gravity (periodic in y); refuses a phi_bar whose bed stays overlapped."""
        d, r = p.d, p.d / 2
        top = float(np.max(x[:, 1] + r))
        ymax = self.H - SQUEEZE_TOP_MARGIN * d.max()
        x[:, 1] = r + (x[:, 1] - r) * (ymax - r.max()) / (np.max(x[:, 1]) - r.max())
        relaxed, overlap = self._relax_in_h(x, d, p.law, p.walls[:2], p.dt)
        if overlap >= PREP_MAX_OVERLAP:
            # jammed: the bed cannot hold phi_bar in this channel without overlaps that
            # a run would carry as a stiffness-set pressure (kn x overlap)
            raise ParameterError(
                f"invalid phi_bar = {self.phi_bar!r}: allowed a value this channel's fill "
                f"and release can pack (squeezed into H = {self.H:g}, the bed still "
                f"overlaps by {overlap:.3f} d >= {PREP_MAX_OVERLAP} d after relaxation; "
                f"the pour reached {p.vs / (self.W * self.B * top):.3f} up to its top): a "
                "lower phi_bar, or a wider channel")
        return relaxed

    def _relax_in_h(self, x: np.ndarray, d: np.ndarray, law: ContactLaw, walls: list[Wall],
                    dt: float) -> tuple[np.ndarray, float]:
        """Relax a bed in the run's box (periodic in y with period H), without gravity, in at
        most SQUEEZE_ROUNDS rounds of SQUEEZE_ROUND_STEPS steps, each ending at rest, until
        its largest overlap is below PREP_MAX_OVERLAP: the positions and that overlap."""
        box = Box(length=(self.W, self.H, self.B), periodic=(False, True, True))
        rel = Simulation(x, d, box, law, walls=walls, dt=dt, threads=self.threads,
                         density=self.mat.density, skin=self.mat.skin)
        overlap = float("inf")
        for _ in range(SQUEEZE_ROUNDS):
            rel.run(SQUEEZE_ROUND_STEPS, progress=False)
            rel.set_velocities(np.zeros_like(x))
            overlap = rel.diagnostics()["max_overlap"]
            if overlap < PREP_MAX_OVERLAP:
                break
        return rel.get_positions(), overlap

    def _relax(self, p: _Pour, x: np.ndarray) -> np.ndarray:
        """Stage 2b, relax: the soft pour leaves overlaps ~ load/prep_kn; relax them at the
        run's stiffness (frictionless, damped, same geometry and load) so the release does not
        start with a burst of stored elastic energy at large kn."""
        stiff = self._relax_material(self.mat.kn_value)
        stiff_sim = self._floor_sim(x, p.d, p.h_fill, self.B, stiff.law(),
                                    stiff.contact_time("lightest", p.d) / POUR_DT_DIVISOR)
        for _ in range(RELAX_ROUNDS):
            stiff_sim.run(RELAX_ROUND_STEPS, progress=False)
            stiff_sim.set_velocities(np.zeros_like(x))
            stiff_sim.set_angular_velocities(np.zeros_like(x))
        return stiff_sim.get_positions()

    def prepare(self, progress: bool | None = None) -> None:
        """Fill and release (see the module docstring) by ``preparation``: ``"rain"`` rains the
        particles with the run's laws onto a floor and settles them; ``"pour"`` pours them
        soft and frictionless, then squeezes (a bed taller than H) or relaxes (a soft pour at a
        stiffer run); both then release. Refuses (ParameterError naming ``phi_bar``, before
        the run's simulation exists) a phi_bar the preparation cannot pack in this channel.
        Does nothing if the channel is prepared already (or restored from a checkpoint)."""
        if self._sim is not None:
            return
        say = _Stages(progress)
        if self.preparation == "rain":
            self._prepare_rain(say)
        else:
            self._prepare_pour(say)

    @property
    def _soft_rain(self) -> bool:
        """Whether the rain is softer than the run (``rain_kn`` below kn)."""
        return self.rain_kn is not None and self.rain_kn < self.mat.kn_value

    def _rain_laws(self) -> tuple[ContactLaw, ContactLaw, float]:
        """The rain's particle law, wall law and dt: the run's, or with ``rain_kn`` softer
        (both stiffnesses scaled by rain_kn/kn, dt the rule's at rain_kn)."""
        dt = self.timestep
        assert dt is not None  # (validated)
        if not self._soft_rain:
            return self.law, self.wall_law, dt
        assert self.rain_kn is not None
        scale = self.rain_kn / self.mat.kn_value

        def softer(law: ContactLaw) -> ContactLaw:
            # the same restitution: a rate damping scales as sqrt(k m)
            return replace(law, kn=law.kn * scale if law.kn else None,
                           kt=law.kt * scale if law.kt else None,
                           xi_n=law.xi_n * np.sqrt(scale) if law.xi_n else None)

        return softer(self.law), softer(self.wall_law), dt / float(np.sqrt(scale))

    def _rain(self, say: _Stages) -> _Pour:
        """Rain, stage 1: a dilute random column (``rain_phi``) above a floor, released at once
        under gravity with the run's laws (particles and walls, the floor a wall) and dt, or
        softer (``rain_kn``, :meth:`_rain_laws`), until the bed is at rest: kinetic energy per
        particle below ``settle_ke`` m g d, after the fall time, and its top still within
        RAIN_TOP_TOL d of the last check. A soft rain's bed is then stiffened: the run's laws
        and dt on the same floor, from rest, settled by the same test."""
        tiles = self.rain_tiles
        depth = self.B / tiles
        d, vs, h_col, x = self._column(self.rain_phi, depth)
        law, wall_law, dt = self._rain_laws()
        # (the wider skin where the slab's period holds it: >= 2 (d_max + skin))
        skin = max(self.mat.skin or kernel_default_skin(),
                   min(RAIN_SKIN, 0.5 * depth - float(d.max()) - 1e-9))
        sim = self._floor_sim(x, d, h_col, depth, law, dt, wall_law, skin)
        say(f"inserted {len(d)} spheres at phi = {self.rain_phi:g} in a {self.W:g} x "
            f"{h_col:.4g} x {depth:g} column"
            f"{f' (1 of {tiles} slabs along z)' if tiles > 1 else ''}; raining (kn = {law.kn:g}"
            f"{' softer than the run' if self._soft_rain else ''}, dt = {dt:.3g})")
        ke = self._settle(sim, d, h_col, "the rained bed", top_tol=RAIN_TOP_TOL)
        t, steps, pos = float(sim.time), sim.step, sim.get_positions()
        if self._soft_rain:
            say(f"rained soft: at rest at t = {t:.1f} sqrt(d/g), {steps} steps; stiffening "
                f"to kn = {self.law.kn:g}")
            stiff = self._floor_sim(pos, d, h_col, depth, self.law, self.timestep,
                                    self.wall_law, skin)
            # a bed at rest: no fall to wait for, only the soft overlaps (load/rain_kn) to
            # spring back, within a few sound crossings (H/sqrt(kn) << 1): checked often
            ke = self._settle(stiff, d, 0.0, "the stiffened bed", top_tol=RAIN_TOP_TOL,
                              check_time=STIFFEN_CHECK_TIME)
            t, steps, pos = t + float(stiff.time), steps + stiff.step, stiff.get_positions()
        if tiles > 1:
            # the slab repeated along z (periodic there: the copies join without a seam)
            pos = np.concatenate([pos + np.array([0.0, 0.0, j * depth]) for j in range(tiles)])
            d, vs = np.tile(d, tiles), vs * tiles
        return _Pour(d, pos, h_col, vs, self.law, dt, _floor_walls(self.W), t, steps, ke)

    def _prepare_rain(self, say: _Stages) -> None:
        """000's fill and release: rain (:meth:`_rain`); a bed whose rough top rises above H
        but whose level (:meth:`_bed_level`) does not has the spheres above H across the seam
        relaxed into the bed's bottom; a bed whose level is above H is refused; release (the
        floor goes, Delta H = H - level stays empty)."""
        p = self._rain(say)
        settled = say(f"settled: kinetic energy per particle {p.ke:.2e} < settle_ke = "
                      f"{self.settle_ke:g} m g d, bed top still, at t = {p.time:.1f} "
                      f"sqrt(d/g), {p.steps} steps")
        top = float(np.max(p.x[:, 1] + p.d / 2))
        area = self.W * self.B
        level, phi_core = self._bed_level(p.x, p.d, top)
        room = self.H
        if level > room:
            # the largest phi_bar whose spheres this rain packs to a level <= room (an estimate:
            # the level scales with the solid volume; the rain's randomness, ~0.005 between
            # seeds, is larger)
            fits = np.floor(self.phi_bar * room / level * 1000) / 1000
            raise ParameterError(
                f"invalid phi_bar = {self.phi_bar!r}: allowed phi_bar <= {fits:.3f}, the "
                f"largest the rain packs in this channel (the settled bed's level is y = "
                f"{level:.3f} > H = {room:g}; its core packs "
                f"{phi_core:.4f}): a lower phi_bar, a taller H, or preparation = 'pour' "
                "(squeezed into H)")
        x, seam = p.x, 0
        if top > self.H:
            x, seam, overlap = self._close_seam(p, say)
            if overlap >= PREP_MAX_OVERLAP:
                raise ParameterError(
                    f"invalid phi_bar = {self.phi_bar!r}: allowed a value whose rained bed "
                    f"closes over its seam (its level {level:.3f} is below H = {self.H:g}, "
                    f"but its {seam} spheres across the seam still overlap by {overlap:.3f} d "
                    f">= {PREP_MAX_OVERLAP} d after relaxation): a lower phi_bar, or a "
                    "taller H")
        phi_bar = p.vs / (area * self.H)
        shift = float(np.max(np.linalg.norm(
            _min_image(x - p.x, self.H, self.B), axis=1))) if seam else 0.0
        done = say(f"released: {len(p.d)} spheres, phi_bar = {phi_bar:.4f}, bed level "
                   f"{level:.4g} (Delta H = {self.H - level:.3g}), top {top:.4g}"
                   + (f" ({seam} spheres across the seam grown back into place; the "
                      f"largest shift {shift:.3f} d)" if seam else ""))
        self._release(x, p.d, {
            "preparation": "rain",
            "n": int(len(p.d)),
            "phi_bar_achieved": phi_bar,
            "bed_top": top,
            "bed_level": level,
            "delta_H": self.H - level,
            "phi_bed": p.vs / (area * top),
            "phi_bed_core": phi_core,
            "seam_spheres": seam,
            "seam_shift": shift,
            "rain_phi": self.rain_phi,
            "rain_kn": self.law.kn if self.rain_kn is None else float(self.rain_kn),
            "rain_tiles": int(self.rain_tiles),
            "settle_time": p.time,
            "settle_ke": p.ke,
            "rain_seconds": settled,
            "seconds": done,
        })

    def _close_seam(self, p: _Pour, say: _Stages) -> tuple[np.ndarray, int, float]:
        """A bed whose level is below H but whose rough top is not: at the release its
        highest spheres cross the seam y = H = 0 onto the bed's bottom layer. They are grown
        back into place there: shrunk until no pair overlaps by more than SEAM_START_OVERLAP
        of its mean diameter, then grown in steps of SEAM_GROWTH of their radius, each
        followed by the relaxation of :meth:`_relax_in_h` (the run's stiffness, frictionless,
        no gravity, periodic in y with period H, at rest after each round). Returns the
        positions, the number of spheres grown and the largest overlap left."""
        from scipy.spatial import cKDTree

        x, d = p.x.copy(), p.d
        seam = np.flatnonzero(x[:, 1] + d / 2 > self.H)
        x[:, 1] = np.mod(x[:, 1], self.H)
        # the seam spheres' radii scaled down until no pair overlaps by more than
        # SEAM_START_OVERLAP of its (scaled) mean diameter (x is not periodic: a box wide
        # enough never wraps it)
        tree = cKDTree(x, boxsize=[self.W + 4.0 * d.max(), self.H, self.B])
        scale = np.ones(len(d))
        # (top > H: the seam holds at least one sphere, itself among its neighbours)
        near = tree.query_ball_point(x[seam], float(d.max()))
        i = np.repeat(seam, [len(n) for n in near])
        j = np.concatenate(near).astype(int)
        pairs = np.unique(np.stack([i, j], axis=1)[i != j], axis=0)
        dist = np.linalg.norm(_min_image(x[pairs[:, 1]] - x[pairs[:, 0]], self.H, self.B),
                              axis=1)
        for _ in range(50):
            ri = d[pairs[:, 0]] / 2 * scale[pairs[:, 0]]
            rj = d[pairs[:, 1]] / 2 * scale[pairs[:, 1]]
            bad = (ri + rj - dist) > SEAM_START_OVERLAP * (ri + rj)
            if not bad.any():
                break
            # both spheres of a bad pair shrink by f: (r_i + r_j) f (1 - a) <= dist
            f = dist[bad] / ((1 - SEAM_START_OVERLAP) * (ri[bad] + rj[bad]))
            f = np.clip(0.98 * f, SEAM_MIN_SCALE, 1.0)
            np.minimum.at(scale, pairs[bad, 0], f * scale[pairs[bad, 0]])
            np.minimum.at(scale, pairs[bad, 1], f * scale[pairs[bad, 1]])
            scale = np.maximum(scale, SEAM_MIN_SCALE)
        else:
            raise ParameterError(
                f"invalid phi_bar = {self.phi_bar!r}: allowed a value whose rained bed closes "
                f"over its seam at H = {self.H:g} (a sphere across it sits on another): a "
                "lower phi_bar, or a taller H")
        grown = np.flatnonzero(scale < 1.0)
        stages = int(np.ceil((1.0 - float(scale.min())) / SEAM_GROWTH)) + 1
        say(f"closing the seam: {seam.size} spheres above H = {self.H:g} cross it; they and "
            f"{grown.size - np.intersect1d(grown, seam).size} others they would overlap are "
            f"grown back from {float(scale.min()):.2f} of their size in {stages} stages")
        relax = self._relax_material(self.mat.kn_value)
        overlap = float("inf")
        s = scale[grown].copy()
        for _ in range(stages):
            dd = d.copy()
            dd[grown] = d[grown] * s
            # (the shrunk spheres are lighter: the step is their contact time's)
            dt = relax.contact_time("lightest", dd) / POUR_DT_DIVISOR
            x, overlap = self._relax_in_h(x, dd, relax.law(), _floor_walls(self.W)[:2], dt)
            s = np.minimum(s + SEAM_GROWTH, 1.0)
        return x, int(seam.size), overlap

    def _bed_level(self, x: np.ndarray, d: np.ndarray, top: float) -> tuple[float, float]:
        """The rained bed's level and its core's volume fraction: the core is the slab of
        centres RAIN_CORE_BOTTOM d_max above the floor to RAIN_CORE_TOP d_max below the top
        (away from the floor's layering and the rough top; in a bed too short for one, the
        centres above the floor layer), the level the height at which the spheres above the
        core's bottom would end at the core's fraction (a flat top of the same solid)."""
        y, dmax, area = x[:, 1], float(d.max()), self.W * self.B
        lo, hi = RAIN_CORE_BOTTOM * dmax, top - RAIN_CORE_TOP * dmax
        if hi - lo < dmax:
            lo, hi = 0.5 * dmax, top - 0.5 * dmax
        core = (y >= lo) & (y < hi)
        phi_core = solid_volume(d[core]) / (area * (hi - lo))
        return lo + solid_volume(d[y >= lo]) / (area * phi_core), float(phi_core)

    def _prepare_pour(self, say: _Stages) -> None:
        """The soft pour (:meth:`_pour`), then squeeze or relax, then release."""
        p = self._pour(say)
        settled = say(f"settled: kinetic energy per particle {p.ke:.2e} < settle_ke = "
                      f"{self.settle_ke:g} m g d (after t >= sqrt(2 h_fill)) at t = "
                      f"{p.time:.1f} sqrt(d/g), {p.steps} steps")
        x = p.x
        top = float(np.max(x[:, 1] + p.d / 2))
        compressed = top > self.H
        if compressed:
            x = self._squeeze(p, x)
        elif self.mat.kn_value > self.prep_kn:
            # (a bed squeezed into H was already relaxed without gravity)
            x = self._relax(p, x)
        vs = p.vs
        done = say(f"released: {len(p.d)} spheres, phi_bar = "
                   f"{vs / (self.W * self.H * self.B):.4f} "
                   f"({'squeezed into H' if compressed else 'bed top'} "
                   f"{min(top, self.H):.4g}); relaxation {say.elapsed - settled:.1f} s")
        self._release(x, p.d, {
            "preparation": "pour",
            "n": int(len(p.d)),
            "phi_bar_achieved": vs / (self.W * self.H * self.B),
            "bed_top": top,
            "compressed": bool(compressed),
            "settle_time": p.time,
            "settle_ke": p.ke,
            "pour_seconds": settled,
            "seconds": done,
        })

    def _release(self, x: np.ndarray, d: np.ndarray, prep_info: dict[str, Any]) -> None:
        """Stage 3, release: the run's simulation (periodic in y, walls, the run's law and dt)
        from prepared positions ``x``, at rest."""
        self._sim = Simulation(
            x, d, Box(length=(self.W, self.H, self.B), periodic=(False, True, True)), self.law,
            density=self.mat.density, walls=[Wall(0, 0.0, 1.0), Wall(0, self.W, -1.0)],
            wall_law=self.wall_law, gravity=self.gravity, dt=self.timestep,
            skin=self.mat.skin, threads=self.threads,
        )
        self.prep_info = dict(prep_info)
        self._add_samplers(self._sim.core)

    def prepare_from(self, other: Channel) -> None:
        """Start from the prepared (released, at rest) packing of ``other`` instead of pouring
        a new one: the same particles in the same place, with this channel's law, dt and
        sampling (e.g. one packing run at several kn). ``other`` must be prepared and not yet
        run, with the same geometry."""
        other.prepare()
        core = other.core
        for name in ("W", "H", "B"):
            if getattr(self, name) != getattr(other, name):
                raise ParameterError(
                    f"invalid {name} = {getattr(self, name)!r}: allowed {getattr(other, name)!r} "
                    "(the packing's value)")
        if self.mat.density != other.mat.density:
            raise ParameterError(f"invalid density = {self.mat.density!r}: allowed "
                                 f"{other.mat.density!r} (the packing's value)")
        if core.step != 0:
            raise ParameterError(
                f"invalid source channel at step {core.step}: allowed a freshly prepared one "
                "(step 0, at rest)")
        self._release(np.array(core.positions()), np.array(core.diameters()),
                      {**other.prep_info, "prepared_with_kn": other.mat.kn_value})

    def branch_from(self, checkpoint: str | os.PathLike[str]) -> None:
        """Start from the state saved in another channel's checkpoint (positions, velocities
        and spins, e.g. a steady flow at another k_n) with this channel's law, dt and
        sampling; time and statistics start at zero, tangential springs at zero. The
        geometry must be the checkpoint's."""
        if self._sim is not None:
            raise ConfigurationError("branch_from needs a channel not yet prepared")
        src = Simulation.from_checkpoint(checkpoint, threads=1)
        box = src.parameters()["box"]
        for i, name in enumerate(("W", "H", "B")):
            if abs(float(box["length"][i]) - getattr(self, name)) > 1e-9:
                raise ParameterError(
                    f"invalid {name} = {getattr(self, name)!r}: allowed "
                    f"{float(box['length'][i])!r} (the checkpoint's)")
        info = read_checkpoint_state(checkpoint, "channel")
        self._release(src.get_positions(), np.array(src.core.diameters()),
                      {**info, "branched_from": os.fspath(checkpoint),
                       "branched_at_time": float(src.time)})
        sim = self._simulation()
        sim.set_velocities(src.get_velocities())
        sim.set_angular_velocities(src.get_angular_velocities())

    def _add_samplers(self, core: _core.Sim) -> None:
        """The kernel's samplers of this scene (docs/columns.md): bins and series (none with
        ``sample_every = None``)."""
        if self.sample_every is None:
            return
        core.add_sampler("channel_bins", self.sample_every, window=self.window,
                         edges=[float(e) for e in self.bin_edges()])
        core.add_sampler("channel_series", self.sample_every)

    def _simulation(self) -> Simulation:
        if self._sim is None:
            raise ConfigurationError(
                "channel not prepared: call prepare() (or run(), or restore()) first")
        return self._sim

    @property
    def prepared(self) -> bool:
        """Whether the kernel simulation exists (after :meth:`prepare`, :meth:`run` or
        :meth:`restore`)."""
        return self._sim is not None

    @property
    def core(self) -> _core.Sim:
        """The kernel simulation of the prepared channel (after :meth:`prepare`, :meth:`run`
        or :meth:`restore`; before, a :class:`granflow.ConfigurationError`)."""
        return self._simulation().core

    @property
    def achieved_phi_bar(self) -> float:
        """(total particle volume) / (W H B) of the prepared packing (prepares if needed)."""
        self.prepare()
        return float(self.prep_info["phi_bar_achieved"])

    # -- protocol ----------------------------------------------------------------------------
    def run(self, steps: int, progress: bool | None = None,
            checkpoint: str | os.PathLike[str] | None = None,
            checkpoint_every: int | None = None) -> None:
        """Advance ``steps`` steps (preparing first if needed), sampling every
        ``sample_every`` steps; ``checkpoint`` and ``checkpoint_every`` as
        :class:`granflow.scenes.Scene` says."""
        self.prepare(progress=progress)
        core = self.core

        def advance(steps: int) -> None:
            run_chunked(core, steps, progress, self._simulation(),
                        after_chunk=lambda: self._tables.drain(core))

        run_with_checkpoints(self, steps, advance, checkpoint, checkpoint_every)

    def tables(self) -> dict[str, pa.Table]:
        """The sample tables by name (``bins``, ``series``; docs/columns.md)."""
        if self._sim is not None:
            self._tables.drain(self.core)
        return self._tables.tables()

    def load_tables(self, tables: Mapping[str, pa.Table]) -> None:
        """Start from tables written earlier (a resumed run)."""
        self._tables.load(tables)

    def summary(self) -> dict[str, Any]:
        """The paper's analysis (granflow.analysis.channel.summary) flattened to scalars:
        ``n``, ``state`` (:class:`granflow.states.FlowState`), ``phi_bar_achieved`` and each
        value with its ``<name>_se``."""
        from granflow.analysis import channel as ach
        from granflow.analysis.channel_profiles import flow_state
        from granflow.analysis.estimate import Estimate

        t = self.tables()
        out: dict[str, Any] = {"n": self.prep_info.get("n"),
                               "phi_bar_achieved": self.prep_info.get("phi_bar_achieved")}
        if "series" in t:
            fs = flow_state(t["series"], n_particles=self.prep_info.get("n"))
            out["state"] = FlowState(fs.state)
        if "bins" not in t or t["bins"].num_rows == 0:
            return out
        try:
            s = ach.summary(t["bins"], t.get("series"))
        except Exception as exc:  # too little data for the analysis: say so, keep the rest
            out["analysis_error"] = f"{type(exc).__name__}: {exc}"
            return out
        for k, v in s.items():
            if isinstance(v, Estimate):
                out[k], out[k + "_se"] = v
            elif isinstance(v, (int, float, str, bool)):
                out[k] = v
        return out

    def order_profile(self, edges: np.ndarray | None = None, cutoff: float | None = None
                      ) -> pl.DataFrame:
        """Bond-orientational order of the present configuration across x
        (:func:`granflow.analysis.order.bin_profile`: Q6, crystal-like fraction, coordination
        per bin), in ``edges`` (default :meth:`bin_edges`), bonds within ``cutoff`` (default
        :data:`granflow.analysis.order.CUTOFF`) times the pair's mean diameter; x bounded by the
        walls, y and z periodic. After :meth:`prepare`, :meth:`run` or :meth:`restore` (before, a
        :class:`granflow.ConfigurationError`)."""
        from granflow.analysis.order import CUTOFF, bin_profile

        sim = self._simulation()
        return bin_profile(sim.get_positions(), np.asarray(self.core.diameters()),
                           self.bin_edges() if edges is None else edges,
                           (self.W, self.H, self.B), (False, True, True), axis=0,
                           cutoff=CUTOFF if cutoff is None else cutoff)

    def save_checkpoint(self, path: str | os.PathLike[str]) -> None:
        """The kernel state and the preparation's record (:func:`write_checkpoint`)."""
        self.prepare()
        # closed windows go to the tables first: the checkpoint carries the open ones
        self._tables.drain(self.core)
        write_checkpoint(self, path, self.prep_info, self._simulation())

    def restore(self, path: str | os.PathLike[str]) -> None:
        """The state of a checkpoint written by :meth:`save_checkpoint`."""
        state = read_checkpoint_state(path, "channel")
        # (the samplers are added before the state is loaded: their open windows ride in it)
        self._sim = Simulation.from_checkpoint(path, threads=self.threads,
                                               configure=self._add_samplers)
        self.prep_info = dict(state)


def _skin(mat: Material) -> float:
    """The material's skin, for the geometry checks (unset: the kernel's default)."""
    return float(mat.skin) if mat.skin is not None else kernel_default_skin()

"""1-D continuum solutions for fully developed, gravity-driven granular flow in a vertical channel.

The channel has flat walls at ``x = 0`` and ``x = W``, gravity points along the channel and the
flow is symmetric about ``x = W/2``; only the half channel ``x in [x0, W/2]`` is solved, ``x``
measured from the wall.  The purpose is to predict DEM channel profiles (velocity ``u``, shear
rate, packing fraction ``phi``) from a rheology calibrated elsewhere (the stress-controlled cell,
paper 002), so the laws are written in 002's form:

* ``mu(I) = mu_s + A_mu I^a_mu`` (002 (4.2)) and ``phi(I) = phi_0 - A_phi I^a_phi`` (002 (4.7)),
  with the channel's variables ``mu = |sigma_xy| / sigma_xx`` and
  ``I = |du/dx| d / sqrt(sigma_xx / rho_p)``;
* momentum balance (paper 000, appendix B, (B1)-(B2)): ``sigma_xx`` is uniform across the channel
  and ``d sigma_xy / dx = -rho_p phi g`` with ``sigma_xy = 0`` on the centre line;
* two constitutive closures: the local mu(I) law (:func:`solve_local`) and the nonlocal granular
  fluidity model of Henann & Kamrin (PNAS 110, 6730, 2013) (:func:`solve_nonlocal`).

Assumptions, stated once here because every function relies on them:

* ``sigma_xx`` is uniform and is used as the pressure, both in ``I`` and in the local fluidity
  ``g_loc``; the other normal stresses (002's normal-stress differences) do not enter.
* ``phi`` is the local ``phi(I)`` in both models (the nonlocality is in the flow rule only);
  ``phi(I)`` is not extrapolated past the calibrated ``I_max``, and a channel whose stress
  ratio exceeds ``mu(I_max)`` is refused (ParameterError) rather than solved with an
  extrapolated ``mu(I)``.
* Whatever happens in the wall zone (slip, layering) enters only through boundary data at
  ``x0``: the velocity ``u_wall`` and, for the nonlocal model, the fluidity ``g_wall``.

Units: ``rho_p`` (particle density), ``g`` (gravity) and ``d`` (mean diameter) are parameters of
:class:`ChannelProblem`, 1 by default (the DEM units).

Modules: :mod:`.laws` (:class:`LocalLaw`), :mod:`.problem` (:class:`ChannelProblem`,
:class:`Profile`), :mod:`.local` (:func:`solve_local`), :mod:`.nonlocal_bvp`
(:func:`solve_nonlocal`), :mod:`.given_phi` (both models with phi(x) given, e.g. a DEM
run's), :mod:`.bands` (:func:`prediction_band`); and on them :mod:`.calibration` (the laws
fitted to cell runs), :mod:`.constants` (the constants fitted once, saved and loaded) and
:mod:`.channel_model` (the channel's DEM runs predicted and compared zone by zone),
:mod:`.cooperativity` (the nonlocal amplitude read off a DEM run's bulk, bin by bin),
:mod:`.wall_layer` (the wall layer's local laws per distance, with the bulk's model beyond)
and :mod:`.verdict` (the misfits with their SEs against the targets, and the answer). The
arithmetic of the law forms lives in :mod:`granflow.analysis.laws`, shared with the fits.
"""

from .bands import prediction_band
from .laws import MU_FORMS, LocalLaw
from .local import solve_local
from .nonlocal_bvp import solve_nonlocal
from .problem import PROFILE_FIELDS, ChannelProblem, Profile, plug_half_width

__all__ = [
    "MU_FORMS",
    "PROFILE_FIELDS",
    "LocalLaw",
    "ChannelProblem",
    "Profile",
    "solve_local",
    "solve_nonlocal",
    "prediction_band",
    "plug_half_width",
]

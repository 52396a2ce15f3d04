"""The made-up local law the continuum tests build their model channels with (one home for
test_cooperativity and test_wall_layer): 002's form (4.2), (4.7) with a flat phi(I)."""

from __future__ import annotations

from granflow.continuum import LocalLaw

MODEL_LAW = LocalLaw(mu_s=0.36, A_mu=0.7, a_mu=0.8, phi_0=0.6, A_phi=1e-12, a_phi=0.8,
                     I_min=1e-4, I_max=2.0)

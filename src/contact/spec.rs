//! [`LawSpec`]: the user-level parameters of one contact law, the only home of their defaults
//! and of their validation.
//!
//! Front ends (the Python bindings, benches, Rust callers) give what they know as a
//! [`LawInput`] of optional fields; [`LawSpec::resolve`] fills the defaults and validates once.
//! Everything downstream ([`crate::contact::Law`], the engine, the walls) takes a resolved spec
//! and does not check it again.

use crate::error::{Error, Result};

/// Default normal stiffness kn.
pub const DEFAULT_KN: f64 = 1e6;
/// Default normal restitution when neither e_n nor xi_n is given (000's value).
pub const DEFAULT_E_N: f64 = 0.82;
/// Default xi_t / xi_n (both papers).
pub const DEFAULT_XI_T_RATIO: f64 = 0.5;
/// Default Coulomb friction coefficient.
pub const DEFAULT_MU: f64 = 0.5;

/// Default tangential stiffness for a normal stiffness kn: kt = 2/7 kn (000 App. A).
pub fn default_kt(kn: f64) -> f64 {
    2.0 / 7.0 * kn
}

/// How the user specifies the normal damping.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Damping {
    /// Normal coefficient of restitution e_n in (0, 1]; the damping is derived per pair so that
    /// every pair, whatever its effective mass, rebounds with exactly e_n (linear law; Hertz via a
    /// velocity-independent dashpot, see [`crate::contact::Hertz`]).
    Restitution(f64),
    /// Damping rate xi_n (units 1/time) as in A1 / 2.17a: damping force = m_eff xi_n v_n.
    Rate(f64),
}

/// A contact law as a front end gives it: every field optional (None: the default).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LawInput {
    pub kn: Option<f64>,
    pub kt: Option<f64>,
    pub e_n: Option<f64>,
    pub xi_n: Option<f64>,
    pub xi_t_ratio: Option<f64>,
    pub mu: Option<f64>,
}

/// User-level parameters of one contact law (particle–particle or particle–wall), resolved:
/// every default filled and every value checked ([`LawSpec::resolve`]). The fields are public
/// for readers and tests; a spec changed by hand is not checked again.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LawSpec {
    /// Normal stiffness; default [`DEFAULT_KN`].
    pub kn: f64,
    /// Tangential stiffness; default 2/7 kn ([`default_kt`], 000 App. A).
    pub kt: f64,
    /// Normal damping; default restitution [`DEFAULT_E_N`] unless xi_n is given.
    pub damping: Damping,
    /// xi_t / xi_n; default [`DEFAULT_XI_T_RATIO`] (both papers).
    pub xi_t_ratio: f64,
    /// Coulomb friction coefficient mu (mu_p in 000, mu_s in 002); default [`DEFAULT_MU`].
    pub mu: f64,
}

impl LawSpec {
    /// Fill the defaults of the fields not given and validate the result, once. `prefix` names
    /// the law in errors (e.g. "wall_": "wall_kn").
    pub fn resolve(input: &LawInput, prefix: &str) -> Result<LawSpec> {
        let kn = input.kn.unwrap_or(DEFAULT_KN);
        let damping = match (input.e_n, input.xi_n) {
            (Some(e), None) => Damping::Restitution(e),
            (None, Some(x)) => Damping::Rate(x),
            (None, None) => Damping::Restitution(DEFAULT_E_N),
            (Some(e), Some(x)) => {
                return Err(Error::param(
                    format!("{prefix}e_n/xi_n"),
                    format!("both given (e_n = {e}, xi_n = {x})"),
                    "exactly one of e_n (restitution) or xi_n (damping rate)",
                ))
            }
        };
        let spec = LawSpec {
            kn,
            kt: input.kt.unwrap_or_else(|| default_kt(kn)),
            damping,
            xi_t_ratio: input.xi_t_ratio.unwrap_or(DEFAULT_XI_T_RATIO),
            mu: input.mu.unwrap_or(DEFAULT_MU),
        };
        spec.validate(prefix)?;
        Ok(spec)
    }

    /// Convenience for tests and examples: stiffness `kn`, restitution `e_n`, friction `mu`,
    /// the other fields at their defaults.
    ///
    /// # Panics
    /// If the values are invalid (use [`LawSpec::resolve`] to get the error instead).
    pub fn new(kn: f64, e_n: f64, mu: f64) -> Self {
        let input = LawInput {
            kn: Some(kn),
            e_n: Some(e_n),
            mu: Some(mu),
            ..LawInput::default()
        };
        match Self::resolve(&input, "") {
            Ok(s) => s,
            Err(e) => panic!("LawSpec::new: {e}"),
        }
    }

    /// Named values: kn, kt, e_n or xi_n, xi_t_ratio, mu (for front ends and records).
    pub fn entries(&self) -> [(&'static str, f64); 5] {
        let damping = match self.damping {
            Damping::Restitution(e) => ("e_n", e),
            Damping::Rate(x) => ("xi_n", x),
        };
        [
            ("kn", self.kn),
            ("kt", self.kt),
            damping,
            ("xi_t_ratio", self.xi_t_ratio),
            ("mu", self.mu),
        ]
    }

    /// Whether the law carries tangential history (mu > 0).
    pub fn frictional(&self) -> bool {
        self.mu > 0.0
    }

    /// The checks of every field; [`LawSpec::resolve`] runs them.
    pub fn validate(&self, prefix: &str) -> Result<()> {
        let name = |s: &str| format!("{prefix}{s}");
        crate::error::check_positive(&name("kn"), self.kn)?;
        if !(self.kt.is_finite() && self.kt >= 0.0) {
            return Err(Error::param(name("kt"), self.kt, "a finite number >= 0"));
        }
        match self.damping {
            Damping::Restitution(e) => {
                if !(e.is_finite() && e > 0.0 && e <= 1.0) {
                    return Err(Error::param(name("e_n"), e, "0 < e_n <= 1").with_hint(
                        "e_n = 0 would need infinite damping; the linear law is critically \
                         damped as e_n -> 0",
                    ));
                }
            }
            Damping::Rate(x) => {
                if !(x.is_finite() && x >= 0.0) {
                    return Err(Error::param(name("xi_n"), x, "a finite number >= 0"));
                }
            }
        }
        if !(self.xi_t_ratio.is_finite() && self.xi_t_ratio >= 0.0) {
            return Err(Error::param(
                name("xi_t_ratio"),
                self.xi_t_ratio,
                "a finite number >= 0",
            ));
        }
        if !(self.mu.is_finite() && self.mu >= 0.0) {
            return Err(Error::param(name("mu"), self.mu, "a finite number >= 0"));
        }
        Ok(())
    }

    /// zeta such that the per-pair damping rate is xi_n = zeta sqrt(kn/m_eff) for a given e_n:
    /// from e_n = exp(-xi_n t_c/2), t_c = pi / sqrt(kn/m_eff - xi_n^2/4) (000 App. A) it follows
    /// that zeta = 2|ln e| / sqrt(pi^2 + ln^2 e) (< 2, i.e. always under-damped).
    pub fn zeta(e_n: f64) -> f64 {
        let l = e_n.ln();
        2.0 * l.abs() / (std::f64::consts::PI.powi(2) + l * l).sqrt()
    }

    /// Contact duration of the linear law for a pair of effective mass m_eff.
    /// Errors if the pair is over-damped (no oscillation: the linear law has no t_c).
    pub fn contact_time(&self, m_eff: f64) -> Result<f64> {
        let w0sq = self.kn / m_eff;
        let xi = match self.damping {
            Damping::Restitution(e) => Self::zeta(e) * w0sq.sqrt(),
            Damping::Rate(x) => x,
        };
        let arg = w0sq - 0.25 * xi * xi;
        if arg <= 0.0 {
            return Err(Error::param(
                "xi_n",
                xi,
                format!(
                    "< 2 sqrt(kn/m_eff) = {:.6e} for the lightest pair (m_eff = {m_eff:.4e})",
                    2.0 * w0sq.sqrt()
                ),
            )
            .with_hint(
                "the linear spring-dashpot is over-damped there: it has no contact time and no \
                 restitution; give e_n instead or reduce xi_n",
            ));
        }
        Ok(std::f64::consts::PI / arg.sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolve_with_only_kn_gives_the_documented_defaults() {
        let kn = 3.5e5;
        let s = LawSpec::resolve(
            &LawInput {
                kn: Some(kn),
                ..LawInput::default()
            },
            "",
        )
        .unwrap();
        // the documented values, written out (not through the constants they should equal)
        assert_eq!(s.kn, 3.5e5);
        assert_eq!(s.kt, 2.0 / 7.0 * 3.5e5);
        assert_eq!(s.damping, Damping::Restitution(0.82));
        assert_eq!(s.xi_t_ratio, 0.5);
        assert_eq!(s.mu, 0.5);
        // nothing given at all: kn = 1e6 too
        let d = LawSpec::resolve(&LawInput::default(), "").unwrap();
        assert_eq!(d.kn, 1e6);
        assert_eq!(d.kt, 2.0 / 7.0 * 1e6);
        assert_eq!(d, LawSpec::new(1e6, 0.82, 0.5));
    }

    #[test]
    fn resolve_keeps_what_is_given() {
        let input = LawInput {
            kn: Some(2e5),
            kt: Some(1e5),
            xi_n: Some(30.0),
            xi_t_ratio: Some(0.25),
            mu: Some(0.0),
            e_n: None,
        };
        let s = LawSpec::resolve(&input, "").unwrap();
        assert_eq!(s.damping, Damping::Rate(30.0));
        assert_eq!((s.kt, s.xi_t_ratio, s.mu), (1e5, 0.25, 0.0));
        assert!(!s.frictional());
    }

    #[test]
    fn resolve_names_the_bad_field_with_its_prefix() {
        let bad = |input: LawInput, needle: &str| {
            let e = LawSpec::resolve(&input, "wall_").unwrap_err().to_string();
            assert!(e.contains(needle), "{e} lacks {needle}");
        };
        bad(
            LawInput {
                kn: Some(-1.0),
                ..LawInput::default()
            },
            "wall_kn",
        );
        bad(
            LawInput {
                e_n: Some(0.0),
                ..LawInput::default()
            },
            "wall_e_n",
        );
        bad(
            LawInput {
                e_n: Some(0.8),
                xi_n: Some(1.0),
                ..LawInput::default()
            },
            "wall_e_n/xi_n",
        );
        bad(
            LawInput {
                mu: Some(f64::NAN),
                ..LawInput::default()
            },
            "wall_mu",
        );
        bad(
            LawInput {
                kt: Some(-1.0),
                ..LawInput::default()
            },
            "wall_kt",
        );
    }
}

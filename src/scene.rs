//! Scenes as data, and the one place where engines are composed.
//!
//! A [`SceneSpec`] says what a scene is made of (particles, contact law, domain, walls, body
//! force, time step, skin); [`build`] picks the compile-time composition (form x friction x
//! domain x walls x body) once and returns it behind [`Simulation`]. Front ends (the Python
//! bindings, the benches, Rust programs) fill a spec and call [`build`]; one that needs the
//! concrete engine (a bench setting engine knobs) passes an [`EngineSink`] to [`build_with`],
//! which composes the same engine and hands it over by value.

use crate::components::{Body, Gravity, NoBody, NoWalls, Plane, PlaneWalls, Walls};
use crate::contact::{Coulomb, Form, Friction, Frictionless, Hertz, Hooke, LawSpec};
use crate::domain::PrCell;
use crate::domain::{Domain, OrthoBox};
use crate::engine::Engine;
use crate::error::{Error, Result};
use crate::particles::Particles;
use crate::sim::Simulation;
use crate::V3;

/// Default neighbour-list skin (in units of length, as the particle diameters).
pub const DEFAULT_SKIN: f64 = 0.3;

/// Normal form of the contact law (see [`crate::contact::Form`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FormKind {
    /// Linear spring-dashpot (a = 0).
    #[default]
    Hooke,
    /// Hertzian (a = 1/2).
    Hertz,
}

impl FormKind {
    /// "hooke" or "hertz".
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "hooke" => Ok(FormKind::Hooke),
            "hertz" => Ok(FormKind::Hertz),
            _ => Err(Error::param("form", name, "'hooke' or 'hertz'")),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            FormKind::Hooke => Hooke::NAME,
            FormKind::Hertz => Hertz::NAME,
        }
    }
}

/// The domain of a scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DomainSpec {
    /// Orthogonal box [lo, lo + length) with a periodic flag per axis ([`OrthoBox`]).
    Box {
        lo: V3,
        length: V3,
        periodic: [bool; 3],
    },
    /// The stress-controlled triclinic cell of 002 ([`PrCell`]): a cubic periodic cell of side
    /// `length`, imposed pressure `p_ext` and shear stress `tau_ext` (xy), cell mass `wg`.
    /// No walls and no body force.
    Cell {
        length: f64,
        p_ext: f64,
        tau_ext: f64,
        wg: f64,
    },
}

/// Everything a scene is made of.
#[derive(Clone, Debug)]
pub struct SceneSpec {
    pub particles: Particles,
    pub form: FormKind,
    /// Particle–particle law (resolved: [`LawSpec::resolve`]).
    pub law: LawSpec,
    pub domain: DomainSpec,
    /// Planar walls (box only, on non-periodic axes; at most `components::MAX_WALLS`).
    pub walls: Vec<Plane>,
    /// Particle–wall law; None: the particle–particle law.
    pub wall_law: Option<LawSpec>,
    /// Uniform body force per unit mass (box only).
    pub gravity: Option<V3>,
    /// Time step; None: t_c/50 of the stiffest, lightest pair.
    pub dt: Option<f64>,
    /// Neighbour-list skin.
    pub skin: f64,
}

impl SceneSpec {
    /// A scene of `particles` in `domain` with `law`: Hooke, no walls, no body force, the
    /// default dt and skin.
    pub fn new(particles: Particles, law: LawSpec, domain: DomainSpec) -> Self {
        SceneSpec {
            particles,
            form: FormKind::default(),
            law,
            domain,
            walls: Vec::new(),
            wall_law: None,
            gravity: None,
            dt: None,
            skin: DEFAULT_SKIN,
        }
    }

    /// The wall law in effect (the particles' law unless a wall law is given).
    pub fn effective_wall_law(&self) -> LawSpec {
        self.wall_law.unwrap_or(self.law)
    }

    /// Whether the composition carries tangential history: mu > 0 for the particles, or for
    /// walls that exist.
    pub fn frictional(&self) -> bool {
        self.law.frictional() || (!self.walls.is_empty() && self.effective_wall_law().frictional())
    }

    /// A short name of the domain ("box" or "cell").
    pub fn domain_name(&self) -> &'static str {
        match self.domain {
            DomainSpec::Box { .. } => "box",
            DomainSpec::Cell { .. } => "cell",
        }
    }
}

/// Receives the composed engine by value (see [`build_with`]).
pub trait EngineSink {
    type Output;
    fn take<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body>(
        self,
        engine: Engine<F, T, D, W, G>,
    ) -> Self::Output;
}

/// The sink of [`build`]: the engine behind the object-safe [`Simulation`].
struct Boxed;
impl EngineSink for Boxed {
    type Output = Box<dyn Simulation>;
    fn take<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body>(
        self,
        engine: Engine<F, T, D, W, G>,
    ) -> Box<dyn Simulation> {
        Box::new(engine)
    }
}

/// Compose the engine a spec describes.
pub fn build(spec: SceneSpec) -> Result<Box<dyn Simulation>> {
    build_with(spec, Boxed)
}

/// Compose the engine a spec describes and hand it to `sink`: the one place where the form,
/// friction, domain, walls and body force are chosen. Friction (tangential history) is
/// compiled in only when mu > 0 for the particles or the walls.
pub fn build_with<S: EngineSink>(spec: SceneSpec, sink: S) -> Result<S::Output> {
    check_walls(&spec)?;
    match (spec.form, spec.frictional()) {
        (FormKind::Hooke, true) => with_domain::<Hooke, Coulomb, S>(spec, sink),
        (FormKind::Hooke, false) => with_domain::<Hooke, Frictionless, S>(spec, sink),
        (FormKind::Hertz, true) => with_domain::<Hertz, Coulomb, S>(spec, sink),
        (FormKind::Hertz, false) => with_domain::<Hertz, Frictionless, S>(spec, sink),
    }
}

fn check_walls(spec: &SceneSpec) -> Result<()> {
    match spec.domain {
        DomainSpec::Box { periodic, .. } => {
            for w in &spec.walls {
                let Plane { axis, pos, sign } = *w;
                if axis > 2 || !(sign == 1.0 || sign == -1.0) || !pos.is_finite() {
                    return Err(Error::param(
                        "walls",
                        format!("({axis}, {pos}, {sign})"),
                        "(axis 0..2, position, sign +1 or -1)",
                    ));
                }
                if periodic[axis] {
                    return Err(Error::param(
                        "walls",
                        format!("a wall on periodic axis {axis}"),
                        "walls only on non-periodic axes",
                    ));
                }
            }
        }
        DomainSpec::Cell { .. } => {
            if !spec.walls.is_empty() {
                return Err(Error::param(
                    "walls",
                    spec.walls.len(),
                    "none in the stress-controlled cell",
                ));
            }
            if let Some(g) = spec.gravity {
                return Err(Error::param(
                    "gravity",
                    format!("{g:?}"),
                    "none in the stress-controlled cell",
                ));
            }
        }
    }
    Ok(())
}

fn with_domain<F: Form, T: Friction, S: EngineSink>(spec: SceneSpec, sink: S) -> Result<S::Output> {
    match spec.domain {
        DomainSpec::Box {
            lo,
            length,
            periodic,
        } => {
            let dom = OrthoBox::new(lo, length, periodic)?;
            with_walls::<F, T, S>(spec, dom, sink)
        }
        DomainSpec::Cell {
            length,
            p_ext,
            tau_ext,
            wg,
        } => {
            let p = &spec.particles;
            let mut cell = PrCell::new(length, p.len(), wg, p_ext, tau_ext)?;
            cell.d_max = 2.0 * p.max_radius();
            finish::<F, T, _, _, _, S>(spec, cell, NoWalls, NoBody, sink)
        }
    }
}

fn with_walls<F: Form, T: Friction, S: EngineSink>(
    mut spec: SceneSpec,
    dom: OrthoBox,
    sink: S,
) -> Result<S::Output> {
    match (spec.walls.is_empty(), spec.gravity) {
        (true, None) => finish::<F, T, _, _, _, S>(spec, dom, NoWalls, NoBody, sink),
        (true, Some(g)) => finish::<F, T, _, _, _, S>(spec, dom, NoWalls, Gravity(g), sink),
        (false, g) => {
            let planes = std::mem::take(&mut spec.walls);
            let w = PlaneWalls::<F, T>::new(planes, spec.effective_wall_law())?;
            match g {
                None => finish::<F, T, _, _, _, S>(spec, dom, w, NoBody, sink),
                Some(g) => finish::<F, T, _, _, _, S>(spec, dom, w, Gravity(g), sink),
            }
        }
    }
}

fn finish<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body, S: EngineSink>(
    spec: SceneSpec,
    domain: D,
    walls: W,
    body: G,
    sink: S,
) -> Result<S::Output> {
    let e: Engine<F, T, D, W, G> = Engine::new(
        spec.particles,
        spec.law,
        domain,
        walls,
        body,
        spec.dt,
        spec.skin,
    )?;
    Ok(sink.take(e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::LawInput;

    fn two_spheres() -> Particles {
        let x = vec![V3::new(2.0, 2.0, 2.0), V3::new(3.2, 2.0, 2.0)];
        Particles::new(x, &[1.0, 1.0], 1.0).unwrap()
    }

    fn bx(periodic: [bool; 3]) -> DomainSpec {
        DomainSpec::Box {
            lo: V3::zeros(),
            length: V3::new(5.0, 5.0, 5.0),
            periodic,
        }
    }

    #[test]
    fn build_composes_what_the_spec_says() {
        let law = LawSpec::resolve(&LawInput::default(), "").unwrap();
        let mut spec = SceneSpec::new(two_spheres(), law, bx([false, true, true]));
        spec.walls = Plane::pair_across(0, 0.0, 5.0);
        spec.gravity = Some(V3::new(0.0, -1.0, 0.0));
        spec.form = FormKind::Hertz;
        let s = build(spec).unwrap();
        let c = s.components().join("\n");
        assert!(c.contains("contact: hertz/coulomb"), "{c}");
        assert!(c.contains("walls: 2 planes"), "{c}");
        assert_eq!(s.law(), law);
        assert_eq!(s.wall_law(), Some(law));

        let frictionless = LawSpec::new(1e5, 0.9, 0.0);
        let s = build(SceneSpec::new(two_spheres(), frictionless, bx([true; 3]))).unwrap();
        let c = s.components().join("\n");
        assert!(c.contains("contact: hooke/frictionless"), "{c}");
        assert!(!c.contains("walls"), "{c}");
        assert_eq!(s.wall_law(), None);
    }

    #[test]
    fn build_refuses_walls_it_cannot_place() {
        let law = LawSpec::new(1e5, 0.9, 0.5);
        let mut spec = SceneSpec::new(two_spheres(), law, bx([true; 3]));
        spec.walls = Plane::pair_across(0, 0.0, 5.0);
        let e = build(spec).err().unwrap().to_string();
        assert!(e.contains("periodic axis 0"), "{e}");

        let cell = DomainSpec::Cell {
            length: 5.0,
            p_ext: 1.0,
            tau_ext: 0.0,
            wg: 1.0,
        };
        let mut spec = SceneSpec::new(two_spheres(), law, cell);
        spec.gravity = Some(V3::new(0.0, -1.0, 0.0));
        let e = build(spec).err().unwrap().to_string();
        assert!(e.contains("gravity"), "{e}");
    }
}

//! The parts a scene adds to the engine besides particles, law and domain: planar walls and a
//! body force. Each is a type parameter of [`crate::engine::Engine`]; `NoWalls` and `NoBody`
//! have `ON = false`, so a scene without them carries none of their code in its step.

use crate::contact::{Form, Friction, Law, LawSpec};
use crate::error::{Error, Result};
use crate::V3;

/// Most planar walls a scene can have (two side walls and a temporary floor).
pub const MAX_WALLS: usize = 3;

/// A planar wall: the plane x[axis] = pos, particles on the side `sign` (+1: x > pos).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub axis: usize,
    pub pos: f64,
    pub sign: f64,
}

impl Plane {
    /// The two side walls of a channel across `axis`: x = lo facing +, x = hi facing -.
    pub fn pair_across(axis: usize, lo: f64, hi: f64) -> Vec<Plane> {
        vec![
            Plane {
                axis,
                pos: lo,
                sign: 1.0,
            },
            Plane {
                axis,
                pos: hi,
                sign: -1.0,
            },
        ]
    }
}

/// Walls as a component. `NoWalls` compiles to nothing.
pub trait Walls<F: Form, T: Friction>: Clone + Send + Sync + 'static {
    const ON: bool;
    fn planes(&self) -> &[Plane];
    fn law(&self) -> Option<&Law<F, T>>;
}

#[derive(Clone, Copy, Debug, Default)]
pub struct NoWalls;
impl<F: Form, T: Friction> Walls<F, T> for NoWalls {
    const ON: bool = false;
    fn planes(&self) -> &[Plane] {
        &[]
    }
    fn law(&self) -> Option<&Law<F, T>> {
        None
    }
}

/// Flat frictional walls (planes of infinite mass) with their own law and per-particle history.
#[derive(Clone, Debug)]
pub struct PlaneWalls<F: Form, T: Friction> {
    pub planes: Vec<Plane>,
    pub law: Law<F, T>,
}

impl<F: Form, T: Friction> PlaneWalls<F, T> {
    pub fn new(planes: Vec<Plane>, params: LawSpec) -> Result<Self> {
        if planes.len() > MAX_WALLS {
            return Err(Error::param(
                "walls",
                planes.len(),
                format!("at most {MAX_WALLS}"),
            ));
        }
        Ok(PlaneWalls {
            planes,
            law: Law::new(params),
        })
    }
}

impl<F: Form, T: Friction> Walls<F, T> for PlaneWalls<F, T> {
    const ON: bool = true;
    fn planes(&self) -> &[Plane] {
        &self.planes
    }
    fn law(&self) -> Option<&Law<F, T>> {
        Some(&self.law)
    }
}

/// Uniform body force per unit mass (gravity) as a component.
pub trait Body: Clone + Send + Sync + 'static {
    const ON: bool;
    fn g(&self) -> V3;
}
#[derive(Clone, Copy, Debug, Default)]
pub struct NoBody;
impl Body for NoBody {
    const ON: bool = false;
    fn g(&self) -> V3 {
        V3::zeros()
    }
}
#[derive(Clone, Copy, Debug)]
pub struct Gravity(pub V3);
impl Body for Gravity {
    const ON: bool = true;
    fn g(&self) -> V3 {
        self.0
    }
}

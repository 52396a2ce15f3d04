//! granflow kernel: discrete-element simulation of dense granular flow.
//!
//! This crate knows nothing about Python (the bindings live in `bindings/`). Data flows one way:
//! parameters -> [`engine::Engine`] -> samples -> tables.
//!
//! A scene is composed at compile time: the engine is generic over its contact law (Hooke/Hertz,
//! frictional or not), its domain (periodic box, channel walls, triclinic cell) and its body force,
//! so a scene carries and executes only the parts it uses. [`scene::build`] is the one place
//! where a scene described as data ([`scene::SceneSpec`], with its contact law resolved by
//! [`contact::LawSpec`]) becomes such an engine.

pub mod checkpoint;
pub mod components;
pub mod contact;
pub mod domain;
pub mod engine;
pub mod error;
pub mod history;
pub mod insert;
pub mod neighbor;
pub mod particles;
pub mod probe;
pub mod rng;
pub mod sampling;
pub mod scene;
pub mod sim;
mod simd;
pub mod table;

pub use error::{Error, Result};

/// Three-vector of f64 (double precision throughout: stiff contacts need it).
pub type V3 = nalgebra::Vector3<f64>;
/// 3x3 tensor.
pub type M3 = nalgebra::Matrix3<f64>;

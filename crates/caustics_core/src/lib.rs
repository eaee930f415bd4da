//! # caustics_core
//!
//! The math of `bevy_caustics`, with no Bevy in it: optics, triangle meshes,
//! scenes, and the ground-truth photon tracer that every real-time technique
//! measures itself against. Everything here runs on the CPU and tests in seconds.

#![warn(missing_docs)]
#![allow(clippy::neg_cmp_op_on_partial_ord, reason = "`!(x > y)` is how the core says \"not greater, or NaN\": bad input must fall to the safe branch")]

pub mod bvh;
pub mod convolution;
pub mod estimate;
#[cfg(feature = "fuzz")]
pub mod fuzz;
pub mod hierarchical;
pub mod illumination_textures;
pub mod mesh;
pub mod metrics;
pub mod ocean;
pub mod optics;
pub mod params;
pub mod rng;
pub mod scene;
pub mod scenes;
pub mod technique;
pub mod tracer;
pub mod triangle_bvh;
pub mod view;
pub mod volumes;

pub use glam;

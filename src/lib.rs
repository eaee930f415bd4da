//! # bevy_caustics
//!
//! Real-time caustics for Bevy. Add [`CausticsPlugin`], put [`CausticGenerator`] on
//! specular meshes and [`CausticReceiver`] on the surfaces that should show their
//! light. The Bevy side lives in [`caustics_bevy`], the renderer-independent math and
//! the ground-truth photon tracer in [`caustics_core`].

pub use caustics_bevy::*;
pub use caustics_core;

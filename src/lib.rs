//! # bevy_caustics
//!
//! Real-time caustics for Bevy 0.19: the light a mirror or a glass or water surface
//! focuses onto diffuse ones. Add [`CausticsPlugin`], put [`CausticGenerator`] on
//! specular meshes, [`CausticReceiver`] on the surfaces that should show their light and
//! [`Caustics`] on the cameras that draw caustics. Bevy's own directional, point
//! and spot lights cast them. Each generator is drawn by one of four techniques, which
//! `Auto` picks from what the generator is ([`CausticTechniqueChoice`] says which and
//! why).
//!
//! ```no_run
//! use bevy::prelude::*;
//! use bevy_caustics::prelude::*;
//!
//! fn main() {
//!     App::new().add_plugins((DefaultPlugins, CausticsPlugin)).add_systems(Startup, setup).run();
//! }
//!
//! fn setup(mut commands: Commands, mut meshes: ResMut<Assets<Mesh>>, mut materials: ResMut<Assets<StandardMaterial>>) {
//!     // The floor shows the light; the glass ball 1 m above it focuses the sun.
//!     let floor = meshes.add(Plane3d::default().mesh().size(4.0, 4.0));
//!     commands.spawn((Mesh3d(floor), MeshMaterial3d(materials.add(Color::WHITE)), CausticReceiver));
//!     let ball = meshes.add(Sphere::new(0.3).mesh().uv(48, 24));
//!     let glass = materials.add(StandardMaterial { specular_transmission: 1.0, ior: 1.5, ..default() });
//!     commands.spawn((Mesh3d(ball), MeshMaterial3d(glass), Transform::from_xyz(0.0, 1.0, 0.0), CausticGenerator::refractive(1.5)));
//!     commands.spawn((DirectionalLight { illuminance: 10_000.0, ..default() }, Transform::default().looking_to(Vec3::NEG_Y, Vec3::Z)));
//!     // A camera without `Caustics` does no caustics work.
//!     commands.spawn((Camera3d::default(), Caustics::default(), Transform::from_xyz(0.0, 3.0, 3.0).looking_at(Vec3::ZERO, Vec3::Y)));
//! }
//! ```
//!
//! ## Cargo features
//!
//! | feature | default | what it builds |
//! |---|---|---|
//! | `warped-volumes` | yes | warped caustic volumes (Ernst et al. 2005) and their light shafts in a [`ParticipatingMedium`] |
//! | `hierarchical-maps` | yes | hierarchical caustic maps (Wyman 2008) |
//! | `illumination-textures` | yes | illumination textures (Iwasaki et al.) |
//! | `convolution` | yes | convolution caustics (Trendall & Stewart 2000) and `PoolRipples` |
//! | `ocean` | yes | the animated FFT `Ocean` |
//! | `egui` | no | the "Caustics" debug panel (`debug_panel`), with `reference` |
//! | `reference` | no | the ground-truth tracer as a caustics source (`reference`) and the live comparison against it (`comparison`) |
//! | `headless` | no | `headless::HeadlessRenderer`, rendering without a window for tests and tools |
//!
//! The library asks Bevy only for `bevy_render`, `bevy_core_pipeline`, `bevy_pbr`,
//! `bevy_asset` and `bevy_log`. It needs compute shaders and storage buffers: WebGL2 is
//! not supported.
//!
//! The Bevy side lives in [`caustics_bevy`], re-exported here; the renderer-independent
//! math and the ground-truth photon tracer in [`caustics_core`].
#![cfg_attr(docsrs, feature(doc_cfg))]
#![warn(missing_docs)]

pub use caustics_bevy::*;
pub use caustics_core;

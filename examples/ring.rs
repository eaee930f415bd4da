//! A polished metal ring on a wooden floor under a low sun: the cardioid caustic of
//! Ernst, Akenine-Möller & Jensen 2005, Fig. 1, drawn by warped caustic volumes.
//!
//! `cargo run --example ring` opens a window (or writes `target/ring.png` without a
//! display; `--headless --out PATH` to force it). `--segments N` sets the ring's
//! tessellation (default 64), `--constant` switches to constant intensity per caustic
//! triangle (the paper's comparison).

#[path = "support/mod.rs"]
mod support;

use bevy::camera::Exposure;
use bevy::prelude::*;
use bevy_caustics::prelude::*;

fn main() -> AppExit {
    let segments: usize = support::option("segments", 64);
    let intensity = if support::flag("constant") { VolumeIntensity::Constant } else { VolumeIntensity::Conserving };
    App::new()
        .add_plugins((support::plugins("ring", "ring", (800, 500), 6), CausticsPlugin))
        .add_systems(Startup, move |world: &mut World| support::ring_scene(world, segments, intensity))
        .add_systems(Startup, camera)
        .run()
}

/// Looking down at the ring, the sun behind it, with a sky for the metal to reflect.
fn camera(mut commands: Commands, mut images: ResMut<Assets<Image>>) {
    commands.spawn((
        support::sky(&mut images, 1000.0),
        Camera3d::default(),
        Caustics::default(),
        Exposure { ev100: 12.0 },
        Transform::from_xyz(-0.6, 2.6, 2.4).looking_at(Vec3::new(0.1, 0.0, 0.0), Vec3::Y),
    ));
}

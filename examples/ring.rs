//! A polished metal ring on a wooden floor under a low sun: the cardioid caustic of
//! Ernst, Akenine-Möller & Jensen 2005, Fig. 1, drawn by warped caustic volumes.
//!
//! `cargo run --example ring` opens a window (or writes `target/ring.png` without a
//! display; `--headless --out PATH` to force it). `--segments N` sets the ring's
//! tessellation (default 64), `--constant` switches to constant intensity per caustic
//! triangle (the paper's comparison).

#[path = "support/mod.rs"]
mod support;

use bevy::camera::{Exposure, RenderTarget};
use bevy::prelude::*;
use bevy_caustics::prelude::*;
use std::process::ExitCode;

fn main() -> ExitCode {
    support::exit_code("ring", run)
}

fn run() -> Result<(), String> {
    let args = support::Args::parse("ring", &["segments"], &["constant"])?;
    let segments: usize = args.number("segments", 64)?;
    let intensity = if args.has("constant") { VolumeIntensity::Constant } else { VolumeIntensity::Conserving };
    let spawn = move |world: &mut World, target: RenderTarget| {
        support::ring_scene(world, segments, intensity);
        let sky = support::sky(world, 1000.0);
        world.spawn((
            sky,
            Camera3d::default(),
            Caustics::default(),
            target,
            Exposure { ev100: 12.0 },
            Transform::from_xyz(-0.6, 2.6, 2.4).looking_at(Vec3::new(0.1, 0.0, 0.0), Vec3::Y),
        ));
    };
    support::show(&args, "ring", (800, 500), 6, spawn, || {})
}

//! `caustics bench --scene frame.json` on a frame saved by the live comparison (the
//! debug panel's "save frame", `tests/demo_comparison.rs`): a [`SceneView`]. Its view is
//! measured as the panel measured it (`caustics_bevy::comparison`), in a headless
//! renderer of this program with the scene rebuilt from the file: every technique
//! asked of every generator in turn, its caustic irradiance read back at each pixel
//! that sees a receiver, against the tracer's gather there, with the reference's own
//! noise. The panel's numbers and these agree within the two traces' noise
//! (`tests/comparison_frames.rs`). Writes `views.csv` and `views.md`.

use crate::images::{percentile_white, write_exr, write_png};
use crate::prepare_output;
use crate::render::typical_irradiance;
use bevy::prelude::{Camera3d, Entity, Time, Virtual, With};
use caustics_bevy::comparison::{ReferenceComparison, compare_headless};
use caustics_bevy::headless::HeadlessRenderer;
use caustics_bevy::reference::{ViewError, spawn_scene_view};
use caustics_core::glam::Vec3 as Rgb;
use caustics_core::view::SceneView;
use std::fmt::Write as _;
use std::path::Path;

/// Photons per light of a view's reference (a quick bench's, then a full one's): the
/// gather keeps every photon in memory, so fewer than a region's binned reference.
pub const VIEW_PHOTONS: [u64; 2] = [1 << 20, 1 << 23];

/// The photon stream of the bench's traces; the panel's is 0, so the two references
/// are independent.
pub const VIEW_SEED: u64 = 1;

/// One technique asked of every generator of a saved frame.
pub struct ViewRow {
    pub scene: String,
    pub technique: &'static str,
    /// What each generator drew with, and why.
    pub drawn: String,
    pub error: Option<ViewError>,
    /// The reference's own relative noise.
    pub noise: f32,
    pub adapter: String,
    /// The caustic passes' GPU time in the frame measured (ms; timestamp queries).
    pub gpu_ms: f64,
}

/// Measures the saved frame `view` (named `name`) with `photons` per light, and writes
/// into `dir/views/` each technique's caustic irradiance and the reference's, as
/// `<file stem>-<technique>.exr` (linear lux; the reference zero where no receiver is
/// measured) and `.png` (one exposure for all, from the reference).
pub fn measure(name: &str, view: &SceneView, photons: u64, dir: &Path) -> Result<Vec<ViewRow>, String> {
    let camera = &view.camera;
    let mut renderer = HeadlessRenderer::timed(camera.width, camera.height).map_err(|e| e.to_string())?;
    let target = renderer.render_target();
    let typical = typical_irradiance(&view.scene, camera.look_at);
    let world = renderer.world_mut();
    // The frame's pools are made again as they were at its moment: their clock stands still.
    world.resource_mut::<Time<Virtual>>().pause();
    spawn_scene_view(world, view, target, typical);
    // The meshes reach the GPU, the pools' water is made, and every technique has a
    // frame to start in.
    renderer.render(2).map_err(|e| e.to_string())?;
    let world = renderer.world_mut();
    let entity = world.query_filtered::<Entity, With<Camera3d>>().single(world).map_err(|e| e.to_string())?;
    eprintln!("{name}: every technique on the frame's view, against {photons} photons per light");
    compare_headless(&mut renderer, entity, (photons, VIEW_SEED))?;
    let adapter = renderer.adapter.name.clone();
    let comparison = renderer.world_mut().resource::<ReferenceComparison>();
    let noise = comparison.reference_noise.unwrap_or(f32::NAN);
    let to_core = |e: &bevy::math::Vec3| Rgb::from_array(e.to_array());
    let reference: Vec<Rgb> = comparison.reference.iter().map(|e| e.as_ref().map_or(Rgb::ZERO, to_core)).collect();
    let white = 2.5 * percentile_white(&reference, 0.5);
    let images = std::iter::once(("reference", reference))
        .chain(comparison.rows.iter().map(|row| (row.technique.label(), row.irradiance.iter().map(to_core).collect())));
    let stem = Path::new(name).file_stem().map_or_else(|| name.into(), |s| s.to_string_lossy());
    for (label, pixels) in images {
        let file = |extension: &str| dir.join("views").join(format!("{stem}-{}.{extension}", label.replace(' ', "-")));
        write_exr(&prepare_output(&file("exr"))?, camera.width, camera.height, &pixels)?;
        write_png(&file("png"), camera.width, camera.height, &pixels, white)?;
    }
    eprintln!("wrote {}", dir.join("views").join(format!("{stem}-*.exr and .png")).display());
    Ok(comparison
        .rows
        .iter()
        .map(|row| ViewRow {
            scene: name.to_string(),
            technique: row.technique.label(),
            drawn: row.drawn.join("; "),
            error: row.error,
            noise,
            adapter: adapter.clone(),
            gpu_ms: row.work.caustics_ms(),
        })
        .collect())
}

/// Writes `views.csv` and `views.md` into `dir`.
pub fn write(dir: &Path, rows: &[ViewRow]) -> Result<(), String> {
    let mut csv = String::from("scene,technique,drawn,pixels,relative_l2,relative_l1,reference_noise,gpu_adapter,gpu_caustics_ms\n");
    let mut md = String::from(
        "Saved frames, each technique asked of every generator and measured as the live comparison measures it: \
         relative L2 and L1 of the caustic irradiance at every pixel that sees a receiver, against the tracer's \
         gather there; the reference's own noise is the relative L2 its photons' randomness alone puts it off \
         the truth. GPU: the caustic passes' time in the frame measured (timestamp queries).\n\n\
         | frame | asked of every generator | drawn with | pixels | relative L2 | relative L1 | reference noise | GPU adapter | GPU caustics (ms) |\n\
         |---|---|---|---:|---:|---:|---:|---|---:|\n",
    );
    for r in rows {
        let (pixels, l2, l1) = r.error.map_or((0, f32::NAN, f32::NAN), |e| (e.pixels, e.l2, e.l1));
        let quote = |s: &str| format!("\"{}\"", s.replace('"', "\"\""));
        writeln!(csv, "{},{},{},{pixels},{l2:.6},{l1:.6},{:.6},{},{:.3}", quote(&r.scene), r.technique, quote(&r.drawn), r.noise, quote(&r.adapter), r.gpu_ms)
            .unwrap();
        writeln!(md, "| {} | {} | {} | {pixels} | {l2:.4} | {l1:.4} | {:.4} | {} | {:.3} |", r.scene, r.technique, r.drawn, r.noise, r.adapter, r.gpu_ms)
            .unwrap();
    }
    for (name, text) in [("views.csv", csv), ("views.md", md)] {
        let path = prepare_output(&dir.join(name))?;
        std::fs::write(&path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

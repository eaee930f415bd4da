//! The bench of hierarchical caustic maps (Wyman 2008): every gather of the paper's
//! Table 3 at 256² to 4096² photons on each built-in scene, with the photons each stage
//! processed (a count, the same on any hardware), each stage's time on the CPU twin and
//! the caustic irradiance's error against the reference tracer.
//!
//! The light maps and the photon buffer are made once per photon count and shared by
//! the gathers; each gather's run time is those stages' plus its own pyramid, traversal,
//! splats and resolve.

use crate::bench::{Errors, Measurement, cell_means, cell_sample_points, gpu_columns};
use crate::plot::{Axes, Series, plot_log_log};
use crate::render::Method;
use caustics_bevy::hierarchical_maps::HierarchicalMapsSettings;
use caustics_core::glam::Vec3;
use caustics_core::hierarchical::caustic_map::{self, CausticMap};
use caustics_core::hierarchical::hierarchy;
use caustics_core::hierarchical::{
    CausticMapSettings, Clustering, Gather, LevelOverflow, LightMaps, LightView, PhotonBuffer, PhotonMaterial, PhotonPaths, Splats, StageTimes, gather_into,
    light_intensity, trace_buffers,
};
use caustics_core::scene::{Light, Scene};
use caustics_core::scenes::BenchScene;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// One gather of the bench: a name, the traversal and the splats, and the CLI method
/// whose GPU passes the bench times for it (the plugin's presets).
pub struct Variant {
    pub name: &'static str,
    pub gather: Gather,
    pub splats: Splats,
    pub paths: PhotonPaths,
    /// Fresnel-reflected branches of traced paths.
    pub fresnel_branches: u32,
    pub gpu: Option<Method>,
}

impl Variant {
    /// The core's settings of this gather at `photons`² photons into a `map`² map.
    pub fn settings(&self, photons: u32, map: u32) -> CausticMapSettings {
        CausticMapSettings {
            photon_resolution: photons,
            map_resolution: map,
            gather: self.gather,
            splats: self.splats,
            paths: self.paths,
            fresnel_branches: self.fresnel_branches,
            ..CausticMapSettings::default()
        }
    }
}

/// The paper's constant splats: 3 texels across (Fig. 4's 3² splats).
const FIXED: Splats = Splats::Fixed { diameter: 3.0 };

/// Flat (every photon), hierarchical (§3.1), clustering at the last and at every level
/// (§3.2), and the full method — clustering at the last level with variable splats into
/// levels 0–3 (§3.3), splats past level 3 clamped into it (`maps-full`) or dropped as the
/// paper does (`maps-full-cap`); and the full method with photons traced through the
/// generators' triangles instead of the image-space pair, with the plugin's Fresnel
/// branches (`maps-traced`, past the paper).
pub const VARIANTS: [Variant; 7] = [
    Variant { name: "maps-flat", gather: Gather::Flat, splats: FIXED, paths: PhotonPaths::ImageSpace, fresnel_branches: 0, gpu: Some(Method::MapsFlat) },
    Variant {
        name: "maps-hierarchical",
        gather: Gather::Hierarchical { clustering: Clustering::Off },
        splats: FIXED,
        paths: PhotonPaths::ImageSpace,
        fresnel_branches: 0,
        gpu: None,
    },
    Variant {
        name: "maps-combine-last",
        gather: Gather::Hierarchical { clustering: Clustering::LastLevel },
        splats: FIXED,
        paths: PhotonPaths::ImageSpace,
        fresnel_branches: 0,
        gpu: None,
    },
    Variant {
        name: "maps-combine-all",
        gather: Gather::Hierarchical { clustering: Clustering::AllLevels },
        splats: FIXED,
        paths: PhotonPaths::ImageSpace,
        fresnel_branches: 0,
        gpu: None,
    },
    Variant {
        name: "maps-full",
        gather: Gather::Hierarchical { clustering: Clustering::LastLevel },
        splats: Splats::Variable { max_level: 3, overflow: LevelOverflow::Clamp },
        paths: PhotonPaths::ImageSpace,
        fresnel_branches: 0,
        gpu: Some(Method::MapsImageSpace),
    },
    Variant {
        name: "maps-full-cap",
        gather: Gather::Hierarchical { clustering: Clustering::LastLevel },
        splats: Splats::Variable { max_level: 3, overflow: LevelOverflow::Discard },
        paths: PhotonPaths::ImageSpace,
        fresnel_branches: 0,
        gpu: None,
    },
    Variant {
        name: "maps-traced",
        gather: Gather::Hierarchical { clustering: Clustering::LastLevel },
        splats: Splats::Variable { max_level: 3, overflow: LevelOverflow::Clamp },
        paths: PhotonPaths::Traced,
        fresnel_branches: HierarchicalMapsSettings::TRACED.fresnel_branches,
        gpu: Some(Method::Maps),
    },
];

/// The full method with traced paths: the plugin's default, what `Auto` draws closed
/// refractors with.
pub const TRACED: &Variant = &VARIANTS[6];

/// Caustic map side: one map for every photon count, so that the photon counts' effect
/// on noise shows.
pub const MAP_RESOLUTION: u32 = 1024;

/// Photon buffer sides, cheapest first.
pub fn photon_resolutions(quick: bool) -> Vec<u32> {
    if quick { vec![256, 512] } else { vec![256, 512, 1024, 2048, 4096] }
}

/// What one gather at one photon count processed and cost, summed over the light views.
struct StageRow {
    photons: u32,
    variant: &'static str,
    /// Photon buffer texels, and those that carry a caustic photon.
    texels: u64,
    valid: u64,
    processed: u64,
    splats: u64,
    clustered: u64,
    maps: f64,
    tracing: f64,
    pyramid: f64,
    gather: f64,
    splat: f64,
    /// Flux the paper's level cap drops, as a fraction of the flux splatted.
    capped: f64,
    errors: Errors,
}

/// One light view's stages that every gather shares.
struct Traced {
    view: LightView,
    intensity: f32,
    maps: LightMaps,
    /// The transmitted light's photon buffer, then the Fresnel branches'.
    buffers: Vec<PhotonBuffer>,
}

/// Runs every variant at every photon count on `scene`, adding its rows to `rows`
/// (with the plugin's GPU passes timed for the variants that have them, at the smallest
/// photon count only when `quick`, never when `cpu_only`); returns the Markdown table of
/// stages and writes `bench-<name>-maps.png` (photons processed against photon count)
/// into `out`.
pub fn bench_scene(
    name: &str,
    scene: &BenchScene,
    truth: &[f32],
    (quick, cpu_only, samples): (bool, bool, usize),
    out: &Path,
    rows: &mut Vec<Measurement>,
) -> Result<String, String> {
    let up = up(scene);
    let points: Vec<(Vec3, Vec3)> = cell_sample_points(&scene.region, samples).into_iter().map(|p| (p, up)).collect();
    let mut stages = Vec::new();
    for p in photon_resolutions(quick) {
        let mut buffers = Vec::new();
        for paths in [&VARIANTS[0], TRACED] {
            let settings = paths.settings(p, MAP_RESOLUTION);
            let (traced, maps_seconds, tracing_seconds) = trace_light_views(&scene.scene, &settings, &|_| true)?;
            eprintln!("{name:>8} caustic maps {p:>5}²: {} light views ray cast in {maps_seconds:.3} s", traced.len());
            eprintln!("{name:>8} caustic maps {p:>5}²: photon buffers traced ({:?}) in {tracing_seconds:.3} s", settings.paths);
            buffers.push((settings.paths, traced, maps_seconds, tracing_seconds));
        }
        for variant in &VARIANTS {
            let Some((_, traced, maps_seconds, tracing_seconds)) = buffers.iter().find(|b| b.0 == variant.paths) else { continue };
            let (maps_seconds, tracing_seconds) = (*maps_seconds, *tracing_seconds);
            let mut row = StageRow {
                photons: p,
                variant: variant.name,
                texels: 0,
                valid: 0,
                processed: 0,
                splats: 0,
                clustered: 0,
                maps: maps_seconds,
                tracing: tracing_seconds,
                pyramid: 0.0,
                gather: 0.0,
                splat: 0.0,
                capped: 0.0,
                errors: Errors { l2: 0.0, l1: 0.0 },
            };
            let mut irradiance = vec![0.0f32; points.len()];
            let (mut flux_in, mut flux_capped) = (0.0, 0.0);
            for t in traced {
                let g = gather_view(t, &variant.settings(p, MAP_RESOLUTION), &points, &mut irradiance);
                row.pyramid += g.seconds[0];
                row.gather += g.seconds[1];
                row.splat += g.seconds[2];
                row.texels += t.buffers.iter().map(|b| b.photons.len() as u64).sum::<u64>();
                row.valid += t.buffers.iter().map(|b| b.stats.caustic).sum::<u64>();
                row.processed += g.stats.total_processed();
                row.splats += g.stats.splats();
                row.clustered += g.stats.clustered_photons;
                flux_in += g.splat_stats.flux_in;
                flux_capped += g.splat_stats.flux_dropped_by_cap;
            }
            row.capped = if flux_in > 0.0 { flux_capped / flux_in } else { 0.0 };
            let image = cell_means(&irradiance, samples);
            row.errors = Errors::between(&image, truth);
            let seconds = row.maps + row.tracing + row.pyramid + row.gather + row.splat;
            eprintln!(
                "{name:>8} {:>18} {p:>5}²: {seconds:8.3} s, {} of {} photons processed, relative L2 {:.4}",
                variant.name, row.processed, row.texels, row.errors.l2
            );
            rows.push(Measurement {
                scene: name.into(),
                method: variant.name.into(),
                quality: format!("{p}²"),
                work: row.processed,
                seconds,
                // A quick run times the GPU at the smallest photon count only.
                gpu: variant
                    .gpu
                    .filter(|_| !cpu_only && (!quick || p == photon_resolutions(true)[0]))
                    .and_then(|method| gpu_columns(method, scene, Some((p, MAP_RESOLUTION)))),
                error: row.errors,
                error_vs_limit: None,
            });
            stages.push(row);
        }
    }
    plot_processed(&out.join(format!("bench-{name}-maps.png")), name, &stages)?;
    Ok(stage_table(name, &stages))
}

/// The receiver region's upward normal (its `edge_u × edge_v` may point either way).
fn up(scene: &BenchScene) -> Vec3 {
    let n = scene.region.normal();
    if n.y < 0.0 { -n } else { n }
}

/// Caustic irradiance per cell of `scene`'s region (the mean of `samples`² points) from
/// `scene`'s generators by the caustic maps' CPU twin under `settings`, and the
/// photons processed.
pub fn irradiance(scene: &BenchScene, settings: &CausticMapSettings, samples: usize) -> Result<(Vec<f32>, u64), String> {
    drawn_irradiance(scene, settings, samples, &|_| true)
}

/// [`irradiance`] from the generators `drawn(index)` picks; the others still shadow,
/// reflect and refract the photons that reach them along traced paths.
pub fn drawn_irradiance(scene: &BenchScene, settings: &CausticMapSettings, samples: usize, drawn: &dyn Fn(usize) -> bool) -> Result<(Vec<f32>, u64), String> {
    let up = up(scene);
    let points: Vec<(Vec3, Vec3)> = cell_sample_points(&scene.region, samples).into_iter().map(|p| (p, up)).collect();
    let (irradiance, processed) = drawn_irradiance_at(scene, settings, &points, drawn)?;
    Ok((cell_means(&irradiance, samples), processed))
}

/// Caustic irradiance at receiver points `(position, normal)` from `scene`'s
/// generators under `settings`, and the photons processed.
pub fn irradiance_at(scene: &BenchScene, settings: &CausticMapSettings, points: &[(Vec3, Vec3)]) -> Result<(Vec<f32>, u64), String> {
    drawn_irradiance_at(scene, settings, points, &|_| true)
}

/// [`irradiance_at`] from the generators `drawn(index)` picks.
fn drawn_irradiance_at(
    scene: &BenchScene,
    settings: &CausticMapSettings,
    points: &[(Vec3, Vec3)],
    drawn: &dyn Fn(usize) -> bool,
) -> Result<(Vec<f32>, u64), String> {
    let (traced, ..) = trace_light_views(&scene.scene, settings, drawn)?;
    let mut irradiance = vec![0.0f32; points.len()];
    let processed = traced.iter().map(|t| gather_view(t, settings, points, &mut irradiance).stats.total_processed()).sum();
    Ok((irradiance, processed))
}

/// Every light view of `scene` with its light maps (ray cast) and photon buffers under
/// `settings` for those views (`CausticMapSettings::for_views`, as the plugin plans
/// them; of the light the generators `drawn` picks meet first), and the seconds the
/// maps and the photon trace took.
fn trace_light_views(scene: &Scene, settings: &CausticMapSettings, drawn: &dyn Fn(usize) -> bool) -> Result<(Vec<Traced>, f64, f64), String> {
    let generators = scene.generator_bounds().ok_or("caustic maps: the scene has no generators")?;
    let receivers =
        scene.receivers.iter().map(|r| r.mesh.bounds()).reduce(|(a, b), (c, d)| (a.min(c), b.max(d))).ok_or("caustic maps: the scene has no receivers")?;
    let materials = PhotonMaterial::of_generators(&scene.generators, drawn);
    let clock = Instant::now();
    let lit: Vec<(&Light, LightView)> =
        scene.lights.iter().flat_map(|light| LightView::for_light(light, generators, receivers).into_iter().map(move |view| (light, view))).collect();
    let settings = &settings.for_views(lit.iter().map(|(_, view)| view));
    let mut views = Vec::new();
    for (light, view) in lit {
        let maps = LightMaps::ray_cast(scene, &view, settings.photon_resolution, settings.map_resolution);
        let intensity = light_intensity(light) * light.color.element_sum() / 3.0;
        views.push((view, light, intensity, maps));
    }
    let maps_seconds = clock.elapsed().as_secs_f64();
    let clock = Instant::now();
    let bvh = (settings.paths == PhotonPaths::Traced).then(|| caustics_core::triangle_bvh::InstancedBvh::of_scene(scene));
    let traced = views
        .into_iter()
        .map(|(view, light, intensity, maps)| {
            let buffers = trace_buffers(&maps, &view, &materials, light, settings, bvh.as_ref());
            Traced { view, intensity, maps, buffers }
        })
        .collect();
    Ok((traced, maps_seconds, clock.elapsed().as_secs_f64()))
}

/// What one gather of one light view did, and the seconds its pyramid, gather and
/// splats (with the resolve) took.
struct Gathered {
    stats: hierarchy::GatherStats,
    splat_stats: caustic_map::SplatStats,
    seconds: [f64; 3],
}

/// Gathers and splats one light view's photons by `variant` (into maps of the side its
/// light maps were cast at) and adds the resolved map's irradiance at `points`
/// (receivers facing `up`) into `irradiance`.
fn gather_view(t: &Traced, settings: &CausticMapSettings, points: &[(Vec3, Vec3)], irradiance: &mut [f32]) -> Gathered {
    let settings = &CausticMapSettings { map_resolution: t.maps.map_resolution, ..*settings };
    let mut map = CausticMap::for_splats(settings.splats, settings.map_resolution);
    let (mut stats, mut splat_stats) = (hierarchy::GatherStats::default(), caustic_map::SplatStats::default());
    let mut times = StageTimes::default();
    for photons in &t.buffers {
        stats.add(&gather_into(&mut map, photons, settings, &mut splat_stats, &mut times).2);
    }
    let clock = Instant::now();
    let resolved = map.resolve();
    times.splat += clock.elapsed().as_secs_f64();
    for (e, &(q, n)) in irradiance.iter_mut().zip(points) {
        *e += caustic_map::irradiance_at(&t.view, &t.maps, &resolved, settings.photon_resolution, t.intensity, q, n);
    }
    Gathered { stats, splat_stats, seconds: [times.pyramid, times.gather, times.splat] }
}

/// Photons processed against photons in the buffer, one line per gather.
fn plot_processed(path: &Path, scene: &str, stages: &[StageRow]) -> Result<(), String> {
    let series: Vec<Series> = VARIANTS[..4]
        .iter()
        .map(|v| Series {
            label: format!("{scene} / {}", v.name),
            points: stages.iter().filter(|r| r.variant == v.name).map(|r| (r.texels as f64, r.processed as f64)).collect(),
        })
        .chain(std::iter::once(Series {
            label: format!("{scene} / caustic photons"),
            points: stages.iter().filter(|r| r.variant == VARIANTS[0].name).map(|r| (r.texels as f64, r.valid.max(1) as f64)).collect(),
        }))
        .collect();
    const AXES: Axes = Axes { caption: "Caustic maps: photons processed by the gather", x: "photons in the buffer", y: "photons processed" };
    plot_log_log(&crate::prepare_output(path)?, &AXES, &series.iter().collect::<Vec<_>>())
}

fn stage_table(scene: &str, stages: &[StageRow]) -> String {
    let mut md = format!(
        "\nHierarchical caustic maps on the {scene} ({MAP_RESOLUTION}² caustic map), per photon count and gather: \
         photons in the buffer (all light views) and those carrying a caustic, nodes the gather processed \
         (every level), splats it handed on and photons inside clusters; seconds on the CPU twin for the light \
         maps (ray cast: a GPU rasterises them), tracing the photon buffer, the pyramid (none for the flat gather), \
         the gather, splats + resolve; the share of splatted flux the paper's level cap drops; relative L2 and L1 \
         against the reference.\n\n\
         | photons | gather | caustic photons | processed | splats | clustered | light maps (s) | trace (s) | pyramid (s) | gather (s) | splat (s) | capped | L2 | L1 |\n\
         |---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n"
    );
    for r in stages {
        writeln!(
            md,
            "| {}² | {} | {} | {} | {} | {} | {:.3} | {:.3} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} |",
            r.photons,
            r.variant,
            r.valid,
            r.processed,
            r.splats,
            r.clustered,
            r.maps,
            r.tracing,
            r.pyramid,
            r.gather,
            r.splat,
            r.capped,
            r.errors.l2,
            r.errors.l1
        )
        .unwrap();
    }
    md
}

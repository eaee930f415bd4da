//! `caustics bench`: every method at several quality settings on the built-in scenes,
//! timed, with its error against a high-photon-count reference. Writes
//! `bench.csv`, `bench.md`, `bench.png` (error against run time, log–log, all) and
//! `bench-<scene>.png` (one scene each). On the pool, `bench.md` also tabulates the
//! convolution form of Trendall & Stewart 2000 against their direct integral (eq. 2).

use crate::plot::{Series, plot_error_vs_time};
use crate::render::{GpuTimes, Method};
use crate::{prepare_output, progress};
use caustics_bevy::CausticQuality;
use caustics_core::convolution::{
    Boundary, ConvolutionCaustics, ConvolutionSettings, Heightfield, LobeAxis, MAX_EXPONENT, convolution_irradiance, direct_irradiance,
};
use caustics_core::estimate::{GridRegion, IrradianceGrid};
use caustics_core::glam::{Vec2, Vec3};
use caustics_core::metrics::{relative_l1, relative_l2};
use caustics_core::params::SpecularInteraction;
use caustics_core::scene::{LightKind, Scene};
use caustics_core::scenes::{BenchScene, wave_pool};
use caustics_core::technique::{GeneratorFacts, GeneratorShape, Technique, choose};
use caustics_core::tracer::{PhotonTracer, TraceSettings};
use caustics_core::volumes::{Footprint, IntensityMode, VolumeSettings, build_drawn_volumes};
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct BenchArgs {
    /// Folder for bench.csv, bench.md and bench.png.
    #[arg(long, default_value = "target/bench")]
    pub out: PathBuf,
    /// Fewer photons everywhere (a smoke run of the whole bench in seconds).
    #[arg(long)]
    pub quick: bool,
    /// Built-in scenes to run, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = crate::scenes::BUILT_IN.map(String::from))]
    pub scenes: Vec<String>,
    /// A scene of one's own (.gltf, .glb or .json), run after the built-in ones; repeat
    /// for more. `--scenes ''` runs only these. A frame saved by the live comparison
    /// (the debug panel's "save frame", `tests/demo_comparison.rs`) is measured from its camera,
    /// as the panel measures it, into `views.csv` and `views.md`.
    #[arg(long = "scene")]
    pub files: Vec<String>,
    /// Leave out the GPU runs (their columns say "CPU only").
    #[arg(long)]
    pub cpu_only: bool,
    /// Methods to run, comma-separated, by their names in the CSV (`auto`, `volumes`,
    /// `maps` for every caustic-map gather, `textures`..., `presets` for the quality
    /// presets and every technique at the plugin's defaults by the GPU passes); all
    /// when not given.
    #[arg(long, value_delimiter = ',')]
    pub methods: Vec<String>,
    /// The frame-cost bench instead: every technique on scenes of growing size in the
    /// headless renderer, GPU time and shader invocations per pass beside Bevy's main
    /// pass, and the plugin's CPU time per frame (`frames.csv`, `frames.md`,
    /// `frames-gpu.png`, `frames-cpu.png`). With
    /// `--quick`, the two smallest sizes of each.
    #[arg(long)]
    pub frames: bool,
    /// With `--frames`: a family stops growing once one of its frames took longer than
    /// this many seconds (wall time; a software adapter cannot render the largest
    /// sizes in reasonable time).
    #[arg(long, default_value_t = 60.0)]
    pub frame_budget: f64,
    /// With `--frames`: the view's size in pixels, `WIDTHxHEIGHT`.
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    pub frame_size: (u32, u32),
    /// With `--frames`: how the caustic volumes' shafts are integrated, `grid` (the
    /// default: one step a cell through the beam grid) or `exact` (through every
    /// volume an eye ray crosses).
    #[arg(long, default_value = "grid", value_parser = parse_shafts)]
    pub shafts: caustics_bevy::warped_volumes::ShaftIntegral,
    /// With `--frames`: the caustic volumes' `WarpedVolumesSettings::splat_pixels`, the
    /// most pixels a volume's shape covers for the surface pass to light it in its compute pass
    /// (0: every volume rasterised); the plugin's default when not given.
    #[arg(long)]
    pub splat_pixels: Option<u32>,
    /// With `--frames`: the families' scenes to run, comma-separated (`ocean`, `ring`,
    /// `glass ball`, `pool`, `rippled pool`, `moving occluder`); all when not given.
    #[arg(long, value_delimiter = ',')]
    pub frame_scenes: Vec<String>,
}

/// `grid` or `exact` as a [`caustics_bevy::warped_volumes::ShaftIntegral`].
fn parse_shafts(text: &str) -> Result<caustics_bevy::warped_volumes::ShaftIntegral, String> {
    use caustics_bevy::warped_volumes::ShaftIntegral;
    match text {
        "grid" => Ok(ShaftIntegral::Grid),
        "exact" => Ok(ShaftIntegral::Exact),
        _ => Err(format!("`{text}` is neither `grid` nor `exact`")),
    }
}

/// `1920x1080` as (1920, 1080).
fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text.split_once('x').ok_or_else(|| format!("{text}: expected WIDTHxHEIGHT"))?;
    let parse = |n: &str| n.trim().parse::<u32>().ok().filter(|&n| (16..=8192).contains(&n));
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!("{text}: each side from 16 to 8192 pixels")),
    }
}

impl BenchArgs {
    /// Whether the bench runs the method named `name` (`maps` names every gather).
    fn runs(&self, name: &str) -> bool {
        self.methods.is_empty() || self.methods.iter().any(|m| m == name || (m == "maps" && name.starts_with("maps")))
    }
}

/// One quality setting of one method on one scene.
pub struct Measurement {
    pub scene: String,
    pub method: String,
    pub quality: String,
    /// Photons (or other work items) the run processed.
    pub work: u64,
    /// The CPU twin's run time (the tracer's, for the reference).
    pub seconds: f64,
    /// The same method and quality by the plugin's GPU passes, where it has them.
    pub gpu: Option<GpuColumns>,
    /// Caustic irradiance on the scene's region against the reference.
    pub error: Errors,
    /// Against the method's own limit, which isolates the error of its approximations
    /// from its model's. The volumes: constant intensity on a 4× finer generator than
    /// the finest measured (the tessellation's error). The convolution: the direct
    /// integral of eq. 2 on the same heightfield and footprint with scattering on
    /// ([`Convolution`]; the error of the three-convolution expansion).
    pub error_vs_limit: Option<Errors>,
}

/// A GPU run's adapter and times, or why there are none.
pub struct GpuColumns {
    pub adapter: String,
    pub times: Option<GpuTimes>,
}

/// Runs `method` on the plugin's GPU passes for the bench's GPU columns (`maps`: the
/// caustic maps' photon buffer and map sides); a failure is reported and leaves them
/// empty.
pub fn gpu_columns(method: Method, scene: &BenchScene, maps: Option<(u32, u32)>) -> Option<GpuColumns> {
    match crate::render::gpu_run(method, scene, maps, None) {
        Ok(run) => Some(GpuColumns { adapter: run.adapter, times: run.times }),
        Err(e) => {
            eprintln!("{:>8} {method:?}: no GPU run: {e}", scene.name);
            None
        }
    }
}

/// Relative L2 (the figure of merit) and relative L1 (robust to the heavy tail of
/// point samples near a cusp) of an image against another.
#[derive(Clone, Copy)]
pub struct Errors {
    pub l2: f32,
    pub l1: f32,
}

impl Errors {
    pub fn between(image: &[f32], truth: &[f32]) -> Self {
        Self { l2: relative_l2(image, truth), l1: relative_l1(image, truth) }
    }
}

/// A caustics method the bench can run: it computes the caustic irradiance on the
/// scene's region at a given quality.
pub trait BenchMethod {
    fn name(&self) -> &'static str;
    /// Quality settings for a built-in scene, cheapest first; none where the method
    /// does not apply.
    fn qualities(&self, scene: &str, quick: bool) -> Vec<u64>;
    /// Irradiance per cell of the built-in scene `name` (mean of RGB, row-major), each
    /// cell the mean of `samples`² points where the method is evaluated at points, and
    /// the work done.
    fn run(&self, name: &str, scene: &BenchScene, quality: u64, samples: usize) -> Result<(Vec<f32>, u64), String>;
    /// How `quality` reads in the tables.
    fn quality_label(&self, quality: u64) -> String {
        quality.to_string()
    }
    /// The error against the method's own limit at `quality`, for methods whose limit
    /// is computed per quality; not timed.
    fn error_vs_own_limit(&self, _name: &str, _scene: &BenchScene, _quality: u64) -> Result<Option<Errors>, String> {
        Ok(None)
    }
}

/// The ground-truth tracer with `quality` photons per light.
pub struct ReferenceTracer;

impl BenchMethod for ReferenceTracer {
    fn name(&self) -> &'static str {
        "reference"
    }
    fn qualities(&self, _scene: &str, quick: bool) -> Vec<u64> {
        let top = if quick { 18 } else { 22 };
        (12..=top).step_by(2).map(|k| 1u64 << k).collect()
    }
    fn run(&self, _name: &str, scene: &BenchScene, photons: u64, _samples: usize) -> Result<(Vec<f32>, u64), String> {
        trace_grid(scene, photons, 2, &|_, _| {})
    }
}

/// Warped caustic volumes (Ernst et al. 2005), the CPU twin of the GPU pass, with the
/// generator tessellated `quality` cells (segments around the ring, grid cells per side
/// of the pool): volumes built and evaluated at every cell centre of the region.
pub struct WarpedVolumes {
    pub name: &'static str,
    pub intensity: IntensityMode,
}

/// Points per cell side at which the methods' CPU twins are evaluated in the bench:
/// the tracer bins flux per cell, so both estimate cell means. The volumes' pixels are
/// each the mean over their footprint (a `1/BENCH_SAMPLES` cell), so one a cell would
/// do for them; point samples needed this many and more at their focal lines (on the
/// pool at 256² water cells their L2 against the tracer read 0.239 from 4² samples a
/// cell, 0.152 from 8², 0.086 from 16²; the maps' 0.211, 0.214, 0.215: their splats
/// are already smooth).
pub const BENCH_SAMPLES: usize = 8;

/// Points per cell side of the GPU irradiance plane (pixels), of its twin and of a
/// quick bench.
pub const SUPERSAMPLE: usize = 4;

/// The three intensity modes: the plugin's default, the paper's, and constant.
pub const VOLUME_METHODS: [WarpedVolumes; 3] = [
    WarpedVolumes { name: "volumes", intensity: IntensityMode::Conserving },
    WarpedVolumes { name: "volumes-paper", intensity: IntensityMode::Interpolated },
    WarpedVolumes { name: "volumes-constant", intensity: IntensityMode::Constant },
];

impl BenchMethod for WarpedVolumes {
    fn name(&self) -> &'static str {
        self.name
    }
    fn qualities(&self, scene: &str, quick: bool) -> Vec<u64> {
        match (scene, quick) {
            ("ring" | "mirror_bunny", false) => vec![16, 32, 64, 128, 256, 512, 1024],
            ("ring" | "mirror_bunny", true) => vec![16, 64, 256, 1024],
            ("pool" | "roofed_pool" | "boxed_pool" | "ball_pool", false) => vec![16, 32, 64, 128, 256],
            ("pool" | "roofed_pool" | "boxed_pool" | "ball_pool", true) => vec![32, 128],
            // One bounce (§3.1) where the sphere bends light twice: measured to show it.
            ("sphere", false) => vec![16, 32, 64, 128],
            ("sphere", true) => vec![32],
            // A scene of one's own, as it is.
            _ => vec![0],
        }
    }
    fn run(&self, name: &str, scene: &BenchScene, quality: u64, samples: usize) -> Result<(Vec<f32>, u64), String> {
        Ok(volumes_irradiance(&tessellated(name, scene, quality as usize)?.scene, &scene.region, self.intensity, samples))
    }
}

/// A built-in scene at tessellation `cells` measured on `scene`'s region; tessellation
/// 0 is `scene` as it is (a scene of one's own has no other).
fn tessellated(name: &str, scene: &BenchScene, cells: usize) -> Result<BenchScene, String> {
    match cells {
        0 => Ok(scene.clone()),
        n => crate::scenes::tessellated(name, n).map(|t| BenchScene { region: scene.region, ..t }).ok_or_else(|| format!("{name}: no tessellation {n}")),
    }
}

/// The caustic irradiance per cell of `region` from every generator of `scene` by the
/// volumes' CPU twin at the plugin's defaults (the mean of `samples`² pixels a cell,
/// each the mean over its footprint), and the number of volumes.
pub fn volumes_irradiance(scene: &Scene, region: &GridRegion, intensity: IntensityMode, samples: usize) -> (Vec<f32>, u64) {
    drawn_volumes_irradiance(scene, region, intensity, samples, |_| true)
}

/// [`volumes_irradiance`] from the generators `drawn(index)` picks; the others shadow them.
fn drawn_volumes_irradiance(scene: &Scene, region: &GridRegion, intensity: IntensityMode, samples: usize, drawn: impl Fn(usize) -> bool) -> (Vec<f32>, u64) {
    let settings = VolumeSettings { intensity, ..VolumeSettings::default() };
    let set = build_drawn_volumes(scene, &settings, drawn);
    // The floor faces up (the region's `edge_u × edge_v` may point either way).
    let up = if region.normal().y < 0.0 { -region.normal() } else { region.normal() };
    let per_side = samples as f32;
    let footprint = Footprint { du: region.edge_u / (region.nu as f32 * per_side), dv: region.edge_v / (region.nv as f32 * per_side) };
    let pixels: Vec<_> = cell_sample_points(region, samples).into_iter().map(|p| (p, up, footprint)).collect();
    let irradiance: Vec<f32> = set.irradiance_over_at(&pixels, &settings).iter().map(|e| (e.x + e.y + e.z) / 3.0).collect();
    (cell_means(&irradiance, samples), set.volumes.len() as u64)
}

/// What a game gets by default: each generator drawn by the technique `Auto` picks for
/// it (`caustics_core::technique`, as the plugin picks), the techniques' caustics
/// added. Step `quality` of [`Auto::steps`] sets the tessellation of the scene's
/// tessellated generator (the volumes' quality) and the photons per light view of the
/// caustic maps (the full method).
pub struct Auto;

impl Auto {
    /// `(tessellation, photons per side)` per step; tessellation 0 keeps the scene's own.
    fn steps(scene: &str) -> [(usize, u32); 4] {
        match scene {
            "pool" | "roofed_pool" | "boxed_pool" | "ball_pool" => [(32, 256), (64, 512), (128, 1024), (256, 2048)],
            "sphere" => [(64, 256), (64, 512), (64, 1024), (64, 2048)],
            "ring" | "mirror_bunny" => [(64, 512), (128, 1024), (256, 2048), (1024, 4096)],
            _ => [(0, 256), (0, 512), (0, 1024), (0, 2048)],
        }
    }

    /// The caustic map side for `photons` per side: the bench's 1024², and 2048² for
    /// 4096² photons.
    fn map_side(photons: u32) -> u32 {
        crate::hierarchical::MAP_RESOLUTION.max(photons / 2)
    }
}

impl BenchMethod for Auto {
    fn name(&self) -> &'static str {
        "auto"
    }
    fn qualities(&self, _scene: &str, quick: bool) -> Vec<u64> {
        if quick { vec![0, 2] } else { vec![0, 1, 2, 3] }
    }
    fn run(&self, name: &str, scene: &BenchScene, quality: u64, samples: usize) -> Result<(Vec<f32>, u64), String> {
        let (tessellation, photons) = Self::steps(name)[quality as usize];
        let own = tessellated(name, scene, tessellation)?;
        let shapes: Vec<GeneratorShape> = own.scene.generators.iter().map(|g| GeneratorShape::of(&g.mesh, &g.interaction)).collect();
        let with_closed_refractor = shapes.contains(&GeneratorShape::ClosedRefractor);
        let mut choices = Vec::new();
        for (generator, &shape) in own.scene.generators.iter().zip(&shapes) {
            let facts = GeneratorFacts { shape, in_medium: false, sides: generator.sides(), with_closed_refractor };
            choices.push(choose(None, facts, |_| true).ok_or("auto: no technique draws a generator")?.technique);
        }
        let mut total = vec![0.0f32; scene.region.nu * scene.region.nv];
        let mut work = 0;
        let mut techniques = choices.clone();
        techniques.sort_by_key(|t| Technique::ALL.iter().position(|a| a == t));
        techniques.dedup();
        for technique in techniques {
            let drawn = |i: usize| choices[i] == technique;
            let group =
                Scene { generators: own.scene.generators.iter().enumerate().filter(|(i, _)| drawn(*i)).map(|(_, g)| g.clone()).collect(), ..own.scene.clone() };
            let (image, done) = match technique {
                Technique::WarpedVolumes => drawn_volumes_irradiance(&own.scene, &scene.region, IntensityMode::Conserving, samples, drawn),
                // The maps draw the light their generators meet first and follow it
                // through every generator, the other techniques' too.
                Technique::HierarchicalMaps => {
                    let followed = |i: &usize| drawn(*i) || shapes[*i].traced_through();
                    let generators: Vec<usize> = (0..choices.len()).filter(followed).collect();
                    let maps_scene = Scene { generators: generators.iter().map(|&i| own.scene.generators[i].clone()).collect(), ..own.scene.clone() };
                    let bench = BenchScene { scene: maps_scene, ..scene.clone() };
                    let settings = crate::hierarchical::TRACED.settings(photons, Self::map_side(photons));
                    crate::hierarchical::drawn_irradiance(&bench, &settings, samples, &|k| drawn(generators[k]))?
                }
                Technique::IlluminationTextures => {
                    crate::illumination::irradiance(&BenchScene { scene: group, ..scene.clone() }, &Default::default(), samples)?
                }
                other => return Err(format!("auto: the bench does not run {other}")),
            };
            total.iter_mut().zip(image).for_each(|(t, e)| *t += e);
            work += done;
        }
        Ok((total, work))
    }
    fn quality_label(&self, quality: u64) -> String {
        format!("step {quality}")
    }
}

/// `samples`² points spread evenly over each cell of the region, cell by cell.
pub fn cell_sample_points(region: &GridRegion, samples: usize) -> Vec<Vec3> {
    let (du, dv) = (region.edge_u / region.nu as f32, region.edge_v / region.nv as f32);
    (0..region.nv)
        .flat_map(|r| (0..region.nu).map(move |c| (r, c)))
        .flat_map(|(r, c)| {
            let corner = region.cell_center(r, c) - 0.5 * (du + dv);
            (0..samples * samples).map(move |k| {
                let (i, j) = ((k % samples) as f32 + 0.5, (k / samples) as f32 + 0.5);
                corner + du * (i / samples as f32) + dv * (j / samples as f32)
            })
        })
        .collect()
}

/// The mean of each cell's values at [`cell_sample_points`] (`per_side`² a cell).
pub fn cell_means(values: &[f32], per_side: usize) -> Vec<f32> {
    values.chunks(per_side * per_side).map(|cell| cell.iter().sum::<f32>() / cell.len() as f32).collect()
}

/// Pool caustics by convolution (Trendall & Stewart 2000 §4.1): the core's FFT form of
/// eq. 2 on the traced pool's own water surface ([`PoolWater`]), at the heightfield
/// resolutions and kernel radii of [`CONVOLUTION_GRIDS`], which `quality` indexes.
///
/// Against the reference, scattering off. The tracer's light goes straight along L̂t,
/// the limit n → ∞ of the lobe (L̂t·P̂)ⁿ (n = 0 is the opposite: a flat lobe spreading
/// each texel's light over the whole footprint). A footprint can only hold a lobe so
/// narrow, so each run takes the narrowest one its kernel holds to three standard
/// deviations: P̂_vⁿ ≈ exp(−nρ²/2d²) at ρ = r·cell gives n = 9 (d / r·cell)². The
/// expansion about the vertical (§4.1, `convolution-paper`) moves a lobe by
/// d L̂t,x / L̂t,v only to first order, so a lobe narrower than that shift (0.2 m under
/// the pool's sun, 20° off zenith) cannot land where the light does: the errors show
/// it. About the refracted sun (`convolution`) only the ripples' own bending is
/// expanded.
///
/// Against the direct integral, the form's own limit: scattering on, a = 50 and
/// n = 2a = 100, on the same heightfield and footprint, over the same region.
pub struct Convolution {
    name: &'static str,
    lobe_axis: LobeAxis,
}

/// The convolution form expanded about the refracted sun, and about the vertical (the paper's).
pub const CONVOLUTION_METHODS: [Convolution; 2] =
    [Convolution { name: "convolution", lobe_axis: LobeAxis::RefractedSun }, Convolution { name: "convolution-paper", lobe_axis: LobeAxis::Vertical }];

/// `(texels along a side of the pool's water, kernel radius r)`, cheapest first.
pub const CONVOLUTION_GRIDS: [(usize, usize); 8] = [(128, 4), (128, 8), (128, 16), (256, 8), (256, 16), (256, 32), (512, 16), (512, 32)];

/// The Gaussian lobe `a` and the cosine power `n = 2a` of "scattering on".
const SCATTERING_ON: (f32, f32) = (50.0, 100.0);

fn convolution_grid(quality: u64) -> Result<(usize, usize), String> {
    CONVOLUTION_GRIDS.get(quality as usize).copied().ok_or_else(|| format!("convolution: no grid {quality}"))
}

impl BenchMethod for Convolution {
    fn name(&self) -> &'static str {
        self.name
    }
    fn qualities(&self, scene: &str, quick: bool) -> Vec<u64> {
        match (scene, quick) {
            ("pool", false) => (0..CONVOLUTION_GRIDS.len() as u64).collect(),
            ("pool", true) => vec![1, 4],
            _ => vec![],
        }
    }
    fn run(&self, _name: &str, scene: &BenchScene, quality: u64, _samples: usize) -> Result<(Vec<f32>, u64), String> {
        let (texels, radius) = convolution_grid(quality)?;
        let water = PoolWater::new(scene, texels)?;
        let cell = water.heightfield.cell_size();
        let exponent = (9.0 * (water.settings.depth / (radius as f32 * cell)).powi(2)).min(MAX_EXPONENT);
        let settings = ConvolutionSettings { scattering: 0.5 * exponent, exponent, kernel_radius: radius, lobe_axis: self.lobe_axis, ..water.settings };
        let mut caustics = ConvolutionCaustics::new(&settings, texels, texels, cell).map_err(|e| e.to_string())?;
        let floor = caustics.irradiance(&water.heightfield).map_err(|e| e.to_string())?;
        Ok((water.on_region(&floor, &scene.region), (texels * texels) as u64))
    }
    fn quality_label(&self, quality: u64) -> String {
        convolution_grid(quality).map_or_else(|e| e, |(texels, radius)| format!("{texels}² r{radius}"))
    }
    fn error_vs_own_limit(&self, name: &str, scene: &BenchScene, quality: u64) -> Result<Option<Errors>, String> {
        let (texels, radius) = convolution_grid(quality)?;
        let water = PoolWater::new(scene, texels)?;
        let (scattering, exponent) = SCATTERING_ON;
        let settings = ConvolutionSettings { scattering, exponent, kernel_radius: radius, lobe_axis: self.lobe_axis, ..water.settings };
        let start = Instant::now();
        let direct = direct_irradiance(&water.heightfield, &settings).map_err(|e| e.to_string())?;
        let seconds = start.elapsed().as_secs_f64();
        let convolution = convolution_irradiance(&water.heightfield, &settings).map_err(|e| e.to_string())?;
        let region = &scene.region;
        let errors = Errors::between(&water.on_region(&convolution, region), &water.on_region(&direct, region));
        let label = self.quality_label(quality);
        eprintln!("{name:>8} {:>16} {label:>10}: {seconds:8.3} s direct integral, relative L2 {:.4} (scattering on)", self.name(), errors.l2);
        Ok(Some(errors))
    }
}

/// The traced pool's water as the convolution's input: the water mesh's heights at the
/// texel centres, which fall on its vertices (`texels` must divide its cells an even
/// number of times), over the mesh's whole square; the depth is their mean above the
/// floor, the rest level. The scene's sun, its irradiance and the water's IOR; ε = 0
/// (the traced water does not absorb). Walls: [`Boundary::Mirror`] at the mesh's edges.
/// The traced water has none, but the region lies 1 m inside them and no footprint
/// here reaches that far, so no light reaching the region meets one.
struct PoolWater {
    heightfield: Heightfield,
    /// World `(x, z)` of texel `(0, 0)`'s outer corner.
    origin: Vec2,
    /// The scene's light and water; lobe and kernel left to the caller.
    settings: ConvolutionSettings,
}

impl PoolWater {
    fn new(scene: &BenchScene, texels: usize) -> Result<Self, String> {
        let ([generator], [light]) = (scene.scene.generators.as_slice(), scene.scene.lights.as_slice()) else {
            return Err("convolution: the scene must have one water surface and one light".into());
        };
        let (SpecularInteraction::Refract { ior, .. }, LightKind::Directional { direction, irradiance }) = (generator.interaction, light.kind) else {
            return Err("convolution: the water must refract and the light must be directional".into());
        };
        let positions = generator.mesh.positions();
        let side = positions.len().isqrt();
        if side * side != positions.len() || side < 2 || (side - 1) % (2 * texels) != 0 {
            return Err(format!("convolution: {texels}² texel centres do not fall on the {side}² water vertices"));
        }
        let stride = (side - 1) / texels;
        let vertex = |column: usize, row: usize| positions[(row * stride + stride / 2) * side + column * stride + stride / 2];
        let floor = scene.region.origin.y;
        let above_floor: Vec<f32> = (0..texels).flat_map(|row| (0..texels).map(move |column| (column, row))).map(|(c, r)| vertex(c, r).y - floor).collect();
        let depth = (above_floor.iter().map(|&h| h as f64).sum::<f64>() / above_floor.len() as f64) as f32;
        let (first, last) = (positions[0], positions[side * side - 1]);
        let cell = (last.x - first.x) / texels as f32;
        let heights = above_floor.iter().map(|h| h - depth).collect();
        let heightfield = Heightfield::new(texels, texels, cell, heights).map_err(|e| e.to_string())?;
        let settings = ConvolutionSettings {
            ior,
            sun_direction: direction,
            sun_irradiance: irradiance * light.color.element_sum() / 3.0,
            depth,
            extinction: 0.0,
            boundary: Boundary::Mirror,
            ..ConvolutionSettings::default()
        };
        Ok(Self { heightfield, origin: Vec2::new(first.x, first.z), settings })
    }

    /// The floor irradiance below the texel centres, interpolated bilinearly to the
    /// region's sample points and averaged per cell, as the tracer bins flux per cell.
    fn on_region(&self, floor: &[f32], region: &GridRegion) -> Vec<f32> {
        let (texels, cell) = (self.heightfield.columns(), self.heightfield.cell_size());
        let last = (texels - 1) as f32;
        let samples: Vec<f32> = cell_sample_points(region, SUPERSAMPLE)
            .iter()
            .map(|p| {
                let u = ((p.x - self.origin.x) / cell - 0.5).clamp(0.0, last);
                let v = ((p.z - self.origin.y) / cell - 0.5).clamp(0.0, last);
                let (column, row) = ((u as usize).min(texels - 2), (v as usize).min(texels - 2));
                let (fu, fv) = (u - column as f32, v - row as f32);
                let at = |c: usize, r: usize| floor[r * texels + c];
                let near = at(column, row) + fu * (at(column + 1, row) - at(column, row));
                let far = at(column, row + 1) + fu * (at(column + 1, row + 1) - at(column, row + 1));
                near + fv * (far - near)
            })
            .collect();
        cell_means(&samples, SUPERSAMPLE)
    }
}

/// The convolution form against the direct integral of eq. 2 on the pool's water at
/// 128² texels, one of n (with a = n/2), depth, slope (the heights scaled) and sun
/// angle (in the pool's sun's azimuth) varied at a time about n = 100, the pool's
/// depth and waves and a vertical sun, then the sun again on waves a tenth as steep;
/// ε = 0; each footprint holds its lobe to three
/// standard deviations, r = ⌈3d / (√n·cell)⌉. Contrast is the direct pattern's relative
/// L2 against its mean, what a uniform floor would score. Over the whole heightfield.
fn convolution_vs_direct(scene: &BenchScene) -> Result<String, String> {
    let water = PoolWater::new(scene, 128)?;
    let (texels, cell) = (water.heightfield.columns(), water.heightfield.cell_size());
    let sun = water.settings.sun_unit();
    let azimuth = Vec2::new(sun.x, sun.z).normalize_or(Vec2::X);
    let (pool_depth, pool_sun) = (water.settings.depth, sun.y.abs().acos().to_degrees());
    let cases: Vec<(&str, f32, f32, f32, f32)> = [10.0, 30.0, 100.0, 300.0, 1000.0]
        .map(|n| ("n", n, pool_depth, 1.0, 0.0))
        .into_iter()
        .chain([0.2, 0.4, 1.6, 3.2].map(|depth| ("depth", 100.0, depth, 1.0, 0.0)))
        .chain([0.1, 0.3].map(|scale| ("slope", 100.0, pool_depth, scale, 0.0)))
        .chain([1.0, 2.0, 5.0, 10.0, pool_sun].map(|angle| ("sun", 100.0, pool_depth, 1.0, angle)))
        .chain([0.0, 1.0, 2.0, 5.0, 10.0].map(|angle| ("sun, slope", 100.0, pool_depth, 0.1, angle)))
        .collect();
    let mut md = format!(
        "\nConvolution form against the direct integral (Trendall & Stewart 2000, eq. 2) on the pool's water, \
         {texels}² texels of {:.1} cm, one setting varied at a time about n = 100 (a = n/2), depth {pool_depth:.2} m, \
         the pool's waves and a vertical sun, then the sun again on waves a tenth as steep; ε = 0; kernel radius r holds the lobe to 3σ. \
         Contrast: the direct pattern against its own mean (a uniform floor's error). Relative L2 and L1 of the form \
         expanded about the vertical (the paper's) and about the refracted sun.\n\n\
         | varied | n | depth (m) | max slope | sun (° off zenith) | r | contrast | vertical L2 | vertical L1 | refracted L2 | refracted L1 |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        100.0 * cell
    );
    for (varied, exponent, depth, slope_scale, sun_degrees) in cases {
        let heights = water.heightfield.heights().iter().map(|h| slope_scale * h).collect();
        let heightfield = Heightfield::new(texels, texels, cell, heights).map_err(|e| e.to_string())?;
        let (sin, cos) = sun_degrees.to_radians().sin_cos();
        let kernel_radius = (3.0 * depth / (exponent.sqrt() * cell)).ceil() as usize;
        let settings = ConvolutionSettings {
            scattering: 0.5 * exponent,
            exponent,
            depth,
            sun_direction: Vec3::new(sin * azimuth.x, -cos, sin * azimuth.y),
            kernel_radius,
            ..water.settings
        };
        let direct = direct_irradiance(&heightfield, &settings).map_err(|e| e.to_string())?;
        let [paper, refracted] = [LobeAxis::Vertical, LobeAxis::RefractedSun].map(|lobe_axis| {
            convolution_irradiance(&heightfield, &ConvolutionSettings { lobe_axis, ..settings })
                .map(|convolution| Errors::between(&convolution, &direct))
                .map_err(|e| e.to_string())
        });
        let (paper, refracted) = (paper?, refracted?);
        let mean = direct.iter().map(|&e| e as f64).sum::<f64>() / direct.len() as f64;
        let contrast = relative_l2(&vec![mean as f32; direct.len()], &direct);
        let max_slope = (0..texels * texels).map(|i| heightfield.slope(i % texels, i / texels, settings.boundary).length()).fold(0.0, f64::max);
        writeln!(
            md,
            "| {varied} | {exponent} | {depth:.2} | {max_slope:.2} | {sun_degrees:.1} | {kernel_radius} | {contrast:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
            paper.l2, paper.l1, refracted.l2, refracted.l1
        )
        .unwrap();
    }
    Ok(md)
}

/// Traces `photons` per light into the scene's grid, BVH build included.
fn trace_grid(scene: &BenchScene, photons: u64, seed: u64, progress: &(dyn Fn(u64, u64) + Sync)) -> Result<(Vec<f32>, u64), String> {
    let tracer = PhotonTracer::new(&scene.scene).map_err(|e| e.to_string())?;
    let mut grid = IrradianceGrid::new(scene.region);
    let settings = TraceSettings { photons_per_light: photons, seed, ..Default::default() };
    let stats = tracer.trace(&settings, &mut grid, progress);
    Ok((grid.irradiance_mean(), stats.photons))
}

pub fn run(args: BenchArgs) -> Result<(), String> {
    if args.frames {
        let scenes = |scene: &str| args.frame_scenes.is_empty() || args.frame_scenes.iter().any(|s| s == scene);
        let bench = crate::frames::FrameBench {
            sizes: args.quick.then_some(2),
            budget_s: args.frame_budget,
            view: args.frame_size,
            shafts: args.shafts,
            splat_pixels: args.splat_pixels,
        };
        return crate::frames::run(&args.out, |t, scene| args.runs(t) && scenes(scene), &bench);
    }
    let mut methods: Vec<&dyn BenchMethod> = vec![&ReferenceTracer];
    methods.extend(VOLUME_METHODS.iter().map(|m| m as &dyn BenchMethod));
    methods.extend(CONVOLUTION_METHODS.iter().map(|m| m as &dyn BenchMethod));
    methods.push(&Auto);
    methods.retain(|m| args.runs(m.name()));
    let mut notes = String::new();
    let reference_photons: u64 = if args.quick { 1 << 21 } else { 1 << 26 };
    let samples = if args.quick { SUPERSAMPLE } else { BENCH_SAMPLES };
    let mut rows = Vec::new();
    let mut scenes = Vec::new();
    for name in args.scenes.iter().filter(|n| !n.is_empty()) {
        let own = crate::scenes::built_in(name).ok_or_else(|| format!("unknown scene {name:?} (built-in: {})", crate::scenes::BUILT_IN.join(", ")))?;
        // The truth is the smooth surface: the reference traces a far finer generator
        // than any method here uses (the scene's own tessellation for the sphere).
        let fine = match name.as_str() {
            "pool" | "roofed_pool" | "boxed_pool" | "ball_pool" => crate::scenes::tessellated(name, 1024),
            "ring" | "mirror_bunny" => crate::scenes::tessellated(name, 4096),
            _ => None,
        };
        scenes.push((name.clone(), fine.unwrap_or_else(|| own.clone()), own));
    }
    let mut views = Vec::new();
    for file in &args.files {
        // The file's name, extension included: never a built-in scene's name.
        let name = std::path::Path::new(file).file_name().map_or_else(|| file.clone(), |s| s.to_string_lossy().into_owned());
        if let Some(view) = crate::scenes::open_scene_view(file)? {
            let photons = crate::views::VIEW_PHOTONS[usize::from(!args.quick)];
            views.extend(crate::views::measure(&name, &view, photons, &args.out).map_err(|e| format!("{file}: {e}"))?);
            continue;
        }
        let bench = BenchScene { name: name.clone(), ..crate::scenes::open(file, 128)?.bench };
        scenes.push((name, bench.clone(), bench));
    }
    if !views.is_empty() {
        crate::views::write(&args.out, &views)?;
    }
    if scenes.is_empty() {
        return Ok(());
    }
    for (name, scene, own) in &scenes {
        let label = format!("{name}: reference with {reference_photons} photons");
        let (truth, _) = trace_grid(scene, reference_photons, 1, &progress(&label))?;
        let volumes_run = VOLUME_METHODS.iter().any(|v| args.runs(v.name));
        let volumes_limit = match VOLUME_METHODS[2].qualities(name, args.quick).last() {
            Some(&finest) if finest > 0 && volumes_run => Some(VOLUME_METHODS[2].run(name, scene, 4 * finest, samples)?.0),
            _ => None,
        };
        for method in &methods {
            for quality in method.qualities(name, args.quick) {
                let start = Instant::now();
                let (image, work) = method.run(name, scene, quality, samples)?;
                let seconds = start.elapsed().as_secs_f64();
                let error = Errors::between(&image, &truth);
                let label = method.quality_label(quality);
                eprintln!("{name:>8} {:>16} {label:>10}: {seconds:8.3} s, relative L2 {:.4}", method.name(), error.l2);
                let is_volumes = VOLUME_METHODS.iter().any(|m| m.name == method.name());
                let error_vs_limit = match volumes_limit.as_ref().filter(|_| is_volumes) {
                    Some(limit) => Some(Errors::between(&image, limit)),
                    None => method.error_vs_own_limit(name, scene, quality)?,
                };
                // The GPU passes' cost: the default volumes (the other intensity modes
                // draw the same prisms) and Auto; a quick run times the cheapest quality.
                let timed = !args.cpu_only && (!args.quick || Some(&quality) == method.qualities(name, true).first());
                let gpu = match method.name() {
                    _ if !timed => None,
                    "volumes" => gpu_columns(Method::Volumes, &tessellated(name, scene, quality as usize)?, None),
                    "auto" => {
                        let (tessellation, photons) = Auto::steps(name)[quality as usize];
                        gpu_columns(Method::Auto, &tessellated(name, scene, tessellation)?, Some((photons, Auto::map_side(photons))))
                    }
                    _ => None,
                };
                rows.push(Measurement { scene: name.clone(), method: method.name().into(), quality: label, work, seconds, gpu, error, error_vs_limit });
            }
        }
        // Caustic maps run on the scene's own tessellation, measured on its region.
        let modes = (args.quick, args.cpu_only, samples);
        if args.runs("maps") {
            notes.push_str(&crate::hierarchical::bench_scene(name, own, &truth, modes, &args.out, &mut rows)?);
        }
        if name == "sphere" && args.runs("textures") {
            notes.push_str(&crate::illumination::bench_scenes(args.quick, args.cpu_only, &mut rows)?);
        }
        if !args.cpu_only && args.runs("presets") {
            notes.push_str(&presets_note(name, own, &truth));
        }
        if name == "pool" {
            let start = Instant::now();
            notes.push_str(&convolution_vs_direct(scene)?);
            eprintln!("{name:>8}: convolution against the direct integral tabulated in {:.3} s", start.elapsed().as_secs_f64());
        }
    }
    let throughput = photon_throughput(if args.quick { 1 << 20 } else { 1 << 23 })?;
    write_outputs(&args.out, &rows, throughput, &notes)
}

/// What a game gets, by the plugin's GPU passes on the scene as it is, against the
/// reference `truth`: `Auto` at each quality preset ([`CausticQuality`], `medium` the
/// defaults) and the illumination textures' presets on the glass sphere (the closed
/// refractor `Auto` gives the caustic maps); then every technique asked of every
/// generator at the plugin's defaults, where it applies to them all. Each row:
/// relative L2 and L1, and the GPU time of the technique's passes.
fn presets_note(name: &str, scene: &BenchScene, truth: &[f32]) -> String {
    let mut runs: Vec<(Method, &str, Option<CausticQuality>)> = CausticQuality::ALL.map(|q| (Method::Auto, "auto", Some(q))).into();
    if name == "sphere" {
        runs.extend(CausticQuality::ALL.map(|q| (Method::IlluminationTextures, "illumination textures", Some(q))));
    }
    runs.extend([
        (Method::Volumes, "warped volumes", None),
        (Method::Maps, "hierarchical maps", None),
        (Method::IlluminationTextures, "illumination textures", None),
        (Method::Convolution, "convolution", None),
    ]);
    let mut note = format!(
        "\n### Quality presets and plugin defaults on {name}\n\n| asked of every generator | settings | relative L2 | relative L1 | GPU ms (adapter) |\n|---|---|---:|---:|---|\n"
    );
    for (method, label, quality) in runs {
        let settings = quality.map_or("plugin defaults", CausticQuality::label);
        let row = match crate::render::gpu_run(method, scene, None, quality) {
            Ok(run) => {
                let image: Vec<f32> = run.irradiance.iter().map(|e| (e.x + e.y + e.z) / 3.0).collect();
                let error = Errors::between(&image, truth);
                let ms = run.times.map_or("no timestamps".into(), |t| format!("{:.1}", t.technique_ms));
                eprintln!("{name:>8} {label:>21} {settings:>15}: relative L2 {:.4}, {ms} ms", error.l2);
                format!("{:.4} | {:.4} | {ms} ({})", error.l2, error.l1, run.adapter)
            }
            // A technique that does not apply to some generator has no row.
            Err(_) if quality.is_none() => continue,
            Err(e) => format!("– | – | no GPU run: {e}"),
        };
        writeln!(note, "| {label} | {settings} | {row} |").unwrap();
    }
    note
}

/// Photons per second of the reference tracer on the 128 × 128-vertex rippled pool.
fn photon_throughput(photons: u64) -> Result<f64, String> {
    let scene = wave_pool(128, 128);
    let tracer = PhotonTracer::new(&scene.scene).map_err(|e| e.to_string())?;
    let mut grid = IrradianceGrid::new(scene.region);
    let settings = TraceSettings { photons_per_light: photons, ..Default::default() };
    let start = Instant::now();
    tracer.trace(&settings, &mut grid, &progress("throughput"));
    let rate = photons as f64 / start.elapsed().as_secs_f64();
    eprintln!("reference tracer: {:.2} M photons/s on {} threads (128×128 heightfield over a floor)", rate / 1e6, rayon::current_num_threads());
    Ok(rate)
}

/// Least-squares slope of log(error) against log(work): −½ for Monte Carlo.
fn convergence_slope(rows: &[&Measurement]) -> f64 {
    let pts: Vec<(f64, f64)> = rows.iter().map(|r| ((r.work as f64).ln(), (r.error.l2 as f64).ln())).collect();
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    sxy / sxx
}

/// The GPU columns of a row: the adapter (or why none), then the milliseconds of the
/// technique's passes and of all timed passes in its costliest frame.
fn gpu_cells(r: &Measurement) -> [String; 3] {
    match &r.gpu {
        None => ["CPU only".into(), String::new(), String::new()],
        Some(GpuColumns { adapter, times: None }) => [format!("{adapter}: no timestamp queries"), String::new(), String::new()],
        Some(GpuColumns { adapter, times: Some(t) }) => [adapter.clone(), format!("{:.3}", t.technique_ms), format!("{:.3}", t.timed_passes_ms)],
    }
}

/// Writes the tables and plots; `notes` go at the end of `bench.md`.
fn write_outputs(dir: &std::path::Path, rows: &[Measurement], throughput: f64, notes: &str) -> Result<(), String> {
    let csv_path = prepare_output(&dir.join("bench.csv"))?;
    let limit = |r: &Measurement, sep: &str| r.error_vs_limit.map_or(sep.to_string(), |e| format!("{:.4}{sep}{:.4}", e.l2, e.l1));
    let mut csv = String::from(
        "scene,method,quality,work,cpu_twin_seconds,relative_l2,relative_l1,relative_l2_vs_limit,relative_l1_vs_limit,\
         gpu_adapter,gpu_technique_ms,gpu_timed_passes_ms\n",
    );
    for r in rows {
        let (scene, method, quality, work, seconds, error) = (&r.scene, &r.method, &r.quality, r.work, r.seconds, r.error);
        let [adapter, technique, passes] = gpu_cells(r);
        let adapter = adapter.replace('"', "\"\"");
        writeln!(csv, "{scene},{method},{quality},{work},{seconds:.6},{:.6},{:.6},{},\"{adapter}\",{technique},{passes}", error.l2, error.l1, limit(r, ","))
            .unwrap();
    }
    std::fs::write(&csv_path, csv).map_err(|e| format!("cannot write {}: {e}", csv_path.display()))?;

    let mut md = String::from(
        "Quality: photons for the reference tracer, generator cells (segments around the ring, \
         grid cells per side of the pool) for the volumes, texels along a side of the pool's 4 m water and \
         kernel radius for the convolution, photons per light view for the caustic maps; work: photons, volumes, \
         texels, or the photons the caustic maps' gather processed; for auto, step 0–3 of rising tessellation \
         and photons (each scene's ladder, `Auto::steps`).\n\n\
         Relative L2 and L1 against the reference tracer (the convolution with the narrowest lobe its kernel holds); \
         also against the method's own limit: for the volumes constant intensity on a 4× finer generator than the \
         finest here, for the convolution the direct integral of eq. 2 with scattering on (a = 50, n = 100).\n\n\
         CPU twin (s): the method's CPU twin on this machine (the tracer's time for the reference). GPU (ms): \
         the plugin's passes for the same method and quality in the headless renderer, from timestamp queries \
         on the adapter named, in the frame where they cost most (the frame that made the maps or drew the \
         volumes): the technique's own passes, and every timed pass of that frame (Bevy's included); \
         \"CPU only\" where the bench runs no GPU pass for the row.\n\n\
         | scene | method | quality | work | CPU twin (s) | relative L2 | relative L1 | L2 vs limit | L1 vs limit | GPU adapter | GPU technique (ms) | GPU timed passes (ms) |\n\
         |---|---|---|---:|---:|---:|---:|---:|---:|---|---:|---:|\n",
    );
    for r in rows {
        let (scene, method, quality, work, seconds, error) = (&r.scene, &r.method, &r.quality, r.work, r.seconds, r.error);
        let (limit, [adapter, technique, passes]) = (limit(r, " | "), gpu_cells(r));
        writeln!(
            md,
            "| {scene} | {method} | {quality} | {work} | {seconds:.3} | {:.4} | {:.4} | {limit} | {adapter} | {technique} | {passes} |",
            error.l2, error.l1
        )
        .unwrap();
    }
    let mut series: Vec<(String, Series)> = Vec::new();
    md.push('\n');
    for r in rows {
        let key = format!("{} / {}", r.scene, r.method);
        if !series.iter().any(|(_, s)| s.label == key) {
            let group: Vec<&Measurement> = rows.iter().filter(|m| m.scene == r.scene && m.method == r.method).collect();
            if r.method == ReferenceTracer.name() {
                writeln!(md, "Convergence of {key}: error ∝ photons^{:.2}.  ", convergence_slope(&group)).unwrap();
            }
            let points = group.iter().map(|m| (m.seconds, m.error.l2 as f64)).collect();
            series.push((r.scene.clone(), Series { label: key, points }));
        }
    }
    md.push_str(&paper_claim(rows));
    md.push_str(notes);
    writeln!(md, "\nReference tracer throughput: {:.2} M photons/s on {} threads.", throughput / 1e6, rayon::current_num_threads()).unwrap();
    let md_path = dir.join("bench.md");
    std::fs::write(&md_path, md).map_err(|e| format!("cannot write {}: {e}", md_path.display()))?;
    let mut scenes: Vec<&String> = series.iter().map(|(scene, _)| scene).collect();
    scenes.dedup();
    for scene in scenes {
        let own: Vec<&Series> = series.iter().filter(|(s, _)| s == scene).map(|(_, s)| s).collect();
        plot_error_vs_time(&dir.join(format!("bench-{scene}.png")), &own)?;
    }
    let png_path = dir.join("bench.png");
    plot_error_vs_time(&png_path, &series.iter().map(|(_, s)| s).collect::<Vec<_>>())?;
    eprintln!("wrote {}, {} and {} (and one plot per scene)", csv_path.display(), md_path.display(), png_path.display());
    Ok(())
}

/// Ernst et al. §5: interpolation on a coarse ring matches the image quality of
/// constant intensity on a 16× finer one, in less time. Checked on this run's
/// numbers, against the reference and against the method's own limit.
fn paper_claim(rows: &[Measurement]) -> String {
    let find = |method: &str, quality: &str| rows.iter().find(|r| r.scene == "ring" && r.method == method && r.quality == quality);
    let Some(fine) = find("volumes-constant", "1024") else {
        return String::new();
    };
    let mut md = String::from("\nThe paper's claim (§5), on the ring: interpolated intensity at 64 segments against constant intensity at 1024.\n\n");
    for method in ["volumes", "volumes-paper"] {
        let Some(coarse) = find(method, "64") else { continue };
        let verdict = |a: f32, b: f32| if a <= 1.05 * b && coarse.seconds < fine.seconds { "holds" } else { "does not hold" };
        let compare = |against: &str, a: Option<Errors>, b: Option<Errors>| match (a, b) {
            (Some(a), Some(b)) => {
                format!("against {against}: L2 {:.4} vs {:.4} ({}), L1 {:.4} vs {:.4} ({})", a.l2, b.l2, verdict(a.l2, b.l2), a.l1, b.l1, verdict(a.l1, b.l1))
            }
            _ => format!("against {against}: not measured"),
        };
        writeln!(
            md,
            "- `{method}` at 64 in {:.3} s vs `volumes-constant` at 1024 in {:.3} s: {}; {}.",
            coarse.seconds,
            fine.seconds,
            compare("the reference", Some(coarse.error), Some(fine.error)),
            compare("the method's limit", coarse.error_vs_limit, fine.error_vs_limit),
        )
        .unwrap();
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pool_water_is_the_traced_mesh_at_its_texel_centres() {
        let scene = wave_pool(129, 32);
        let water = PoolWater::new(&scene, 32).unwrap();
        let (heightfield, depth) = (&water.heightfield, water.settings.depth);
        assert_eq!(heightfield.cell_size(), 0.125);
        let positions = scene.scene.generators[0].mesh.positions();
        // Texel (3, 5) has its centre on vertex (3·4 + 2, 5·4 + 2) of the 129² grid.
        let vertex = positions[22 * 129 + 14];
        let centre = water.origin + heightfield.cell_size() * Vec2::new(3.5, 5.5);
        assert!((Vec2::new(vertex.x, vertex.z) - centre).length() < 1e-5);
        assert!((heightfield.height(3, 5) + depth - vertex.y).abs() < 1e-5);
        assert!((depth - 0.8).abs() < 0.01, "{depth}");
        // A uniform floor stays uniform on the region; a ramp along x is sampled at the cells' centres.
        assert!(water.on_region(&[2.0; 32 * 32], &scene.region).iter().all(|&e| (e - 2.0).abs() < 1e-6));
        let ramp: Vec<f32> = (0..32 * 32).map(|i| (i % 32) as f32).collect();
        let on_region = water.on_region(&ramp, &scene.region);
        let x = scene.region.cell_center(0, 7).x;
        assert!((on_region[7] - ((x - water.origin.x) / 0.125 - 0.5)).abs() < 1e-4);
        // Texel centres between the vertices: refused.
        assert!(PoolWater::new(&scene, 128).is_err());
    }
}

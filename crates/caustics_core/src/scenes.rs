//! Procedural scenes built in code — the pool, the glass sphere, the metal ring —
//! and the JSON scene description used by `shared/reference`.

use crate::estimate::GridRegion;
use crate::mesh::TriMesh;
use crate::params::SpecularInteraction;
use crate::scene::{Generator, Light, LightKind, Receiver, Scene};
use glam::Vec3;
use serde::Deserialize;

/// A scene together with the receiver region on which its caustic is measured.
#[derive(Clone, Debug)]
pub struct BenchScene {
    /// Name the scene is reported under.
    pub name: String,
    /// The scene itself.
    pub scene: Scene,
    /// The receiver region its caustic is measured on.
    pub region: GridRegion,
}

/// One sinusoid of a heightfield: `a·sin(kx·x + kz·z + φ)`.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
pub struct Wave {
    /// x component of the wave vector (rad/m).
    pub kx: f32,
    /// z component of the wave vector (rad/m).
    pub kz: f32,
    /// Amplitude `a` (m).
    pub amplitude: f32,
    /// Phase `φ` (radians).
    pub phase: f32,
}

/// Water surface `y = height + Σ aᵢ sin(kxᵢ x + kzᵢ z + φᵢ)` on an `n × n` grid with the
/// analytic normals `(−∂y/∂x, 1, −∂y/∂z)`.
pub fn wave_heightfield(n: usize, size: f32, height: f32, waves: &[Wave]) -> TriMesh {
    // Analytic normals are never zero (their y is 1): only non-finite input can fail.
    try_wave_heightfield(n, size, height, waves).expect("finite waves make a finite heightfield")
}

/// [`wave_heightfield`], or why its waves make no mesh (a height or slope that is not
/// finite, a position past [`crate::mesh::MAX_COORDINATE`]).
pub fn try_wave_heightfield(n: usize, size: f32, height: f32, waves: &[Wave]) -> Result<TriMesh, crate::mesh::MeshError> {
    let h = |x: f32, z: f32| height + waves.iter().map(|w| w.amplitude * (w.kx * x + w.kz * z + w.phase).sin()).sum::<f32>();
    let nrm = |x: f32, z: f32| {
        let (mut dx, mut dz) = (0.0, 0.0);
        for w in waves {
            let c = w.amplitude * (w.kx * x + w.kz * z + w.phase).cos();
            dx += c * w.kx;
            dz += c * w.kz;
        }
        Vec3::new(-dx, 1.0, -dz)
    };
    TriMesh::heightfield(n, size, h, nrm)
}

/// The waves of the reference pool (`shared/reference/wave_pool_scene.json`).
pub const POOL_WAVES: [Wave; 2] = [Wave { kx: 8.0, kz: 0.0, amplitude: 0.07, phase: 0.0 }, Wave { kx: 0.0, kz: 9.0, amplitude: 0.05, phase: 0.7 }];

/// The rippled pool of `shared/reference` with an `n × n` water grid: directional
/// light along (0.3, −1, −0.2) with irradiance 1, water IOR 1.333 at y ≈ 0.8, floor
/// y = 0 measured over x, z ∈ [−1, 1] on `cells × cells` cells.
pub fn wave_pool(n: usize, cells: usize) -> BenchScene {
    let waves = POOL_WAVES;
    let desc = SceneDescription {
        name: "wave_pool".into(),
        light: LightDescription { kind: "directional".into(), direction: [0.3, -1.0, -0.2], irradiance: 1.0 },
        generators: vec![GeneratorDescription {
            shape: "heightfield".into(),
            material: "glass".into(),
            ior: 1.333,
            n,
            size: 4.0,
            height: 0.8,
            waves: waves.iter().map(|w| [w.kx, w.kz, w.amplitude, w.phase]).collect(),
            double_sided: false,
        }],
        receiver: ReceiverDescription { y: 0.0, size: 2.0 },
        max_depth: 3,
    };
    desc.build(cells).expect("the built-in pool description is valid")
}

/// A glass sphere (IOR 1.5, radius 0.5) 1 m above a floor, lit by a point light
/// straight above: the bright focal spot under a glass ball.
pub fn glass_sphere(segments: usize) -> BenchScene {
    let scene = Scene {
        lights: vec![Light::white(LightKind::Point { position: Vec3::new(0.0, 4.0, 0.0), intensity: 10.0 })],
        generators: vec![Generator::new(
            TriMesh::uv_sphere(Vec3::new(0.0, 1.0, 0.0), 0.5, segments / 2, segments),
            SpecularInteraction::Refract { ior: 1.5, dispersion: None },
        )],
        receivers: vec![floor(4.0)],
    };
    BenchScene { name: "glass_sphere".into(), scene, region: GridRegion::horizontal(-1.0, -1.0, 0.0, 2.0, 128) }
}

/// A glass ball (IOR 1.5, radius 0.2, `segments` around) 1.5 m over a Stanford bunny
/// 0.48 m tall on a floor, under a point light above and a little aside: the paper's
/// Fig. 1, a caustic and a shadow on a curved receiver. The ball focuses about 0.3 m
/// below its centre, 0.7 m above the bunny's back; its light spreads over the bunny
/// and the floor around. Its region
/// is read projected (`IrradianceGrid::projected`, `estimate::surface_samples`): the
/// flux landed over each cell at every height. The bunny is flat-shaded, so that a
/// technique's cosine at the surface is the one the tracer's photons meet.
pub fn glass_ball_over_bunny(segments: usize) -> BenchScene {
    let bunny = TriMesh::from_obj(include_str!("../../../assets/models/bunny.obj")).expect("the bunny asset parses (tested)");
    let place = glam::Affine3A::from_scale(Vec3::splat(0.05));
    let scene = Scene {
        lights: vec![Light::white(LightKind::Point { position: Vec3::new(0.3, 4.0, 0.2), intensity: 10.0 })],
        generators: vec![Generator::new(
            TriMesh::uv_sphere(Vec3::new(0.0, 1.5, 0.0), 0.2, segments / 2, segments),
            SpecularInteraction::Refract { ior: 1.5, dispersion: None },
        )],
        receivers: vec![floor(4.0), Receiver { mesh: bunny.transformed(&place).faceted(), albedo: Vec3::splat(0.8) }],
    };
    BenchScene { name: "ball_bunny".into(), scene, region: GridRegion::horizontal(-0.5, -0.5, 0.0, 1.0, 128) }
}

/// A solid mirror ring (inner radius 1, 5 cm thick, height 0.3) on a floor under a low
/// directional light: the cardioid of Ernst et al. 2005, Fig. 1.
pub fn metal_ring(segments: usize) -> BenchScene {
    let scene = Scene {
        lights: vec![Light::white(LightKind::Directional { direction: Vec3::new(1.0, -0.45, 0.0), irradiance: 1.0 })],
        generators: vec![Generator::new(TriMesh::solid_ring(Vec3::ZERO, 1.0, 1.05, 0.3, segments), SpecularInteraction::Reflect)],
        receivers: vec![floor(4.0)],
    };
    BenchScene { name: "metal_ring".into(), scene, region: GridRegion::horizontal(-1.0, -1.0, 0.0, 2.0, 128) }
}

/// The rippled pool of [`wave_pool`] with a roof over half of it: a grey slab 1.6 m up
/// over x < 0, past the water's edges, which shadows that half of the water (the
/// sunlight slants 17° off zenith towards +x, so the shadow reaches x ≈ 0.3 on the floor).
pub fn roofed_pool(n: usize, cells: usize) -> BenchScene {
    let mut bench = wave_pool(n, cells);
    let roof = TriMesh::quad(Vec3::new(-1.5, 1.6, 0.0), Vec3::Z * 2.5, Vec3::X * 1.5);
    bench.scene.receivers.push(Receiver { mesh: roof, albedo: Vec3::splat(0.5) });
    bench.name = "roofed_pool".into();
    bench
}

/// The rippled pool of [`wave_pool`] with a grey box 0.5 m tall standing on its floor
/// over x, z ∈ [−0.3, 0.2]: the box's top takes the water's caustics, and the floor
/// beside it on the far side from the sun (x > 0.2, z < 0.2) lies in its caustic
/// shadow, about 0.1 m wide.
pub fn boxed_pool(n: usize, cells: usize) -> BenchScene {
    let mut bench = wave_pool(n, cells);
    let block = TriMesh::cuboid(Vec3::new(-0.3, 0.0, -0.3), Vec3::new(0.2, 0.5, 0.2));
    bench.scene.receivers.push(Receiver { mesh: block, albedo: Vec3::splat(0.5) });
    bench.name = "boxed_pool".into();
    bench
}

/// A square floor `size` wide at y = 0, facing up, light grey.
pub fn floor(size: f32) -> Receiver {
    Receiver { mesh: TriMesh::quad(Vec3::ZERO, Vec3::Z * (0.5 * size), Vec3::X * (0.5 * size)), albedo: Vec3::splat(0.8) }
}

/// The finest heightfield a scene description may ask for: 4096² cells, 34 M triangles.
pub const MAX_DESCRIPTION_GRID: usize = 4096;

/// The scene description format of `shared/reference/*_scene.json`.
#[derive(Clone, Debug, Deserialize)]
pub struct SceneDescription {
    /// The scene's name.
    pub name: String,
    /// The one light.
    pub light: LightDescription,
    /// The specular heightfields.
    pub generators: Vec<GeneratorDescription>,
    /// The floor and the square measured on it.
    pub receiver: ReceiverDescription,
    /// Most specular interactions a traced branch may have
    /// ([`crate::tracer::TraceSettings::max_depth`]).
    pub max_depth: u32,
}

/// The light of a scene description: a directional one.
#[derive(Clone, Debug, Deserialize)]
pub struct LightDescription {
    /// The light's type; only `"directional"` is supported.
    #[serde(rename = "type")]
    pub kind: String,
    /// The way the light travels `[x, y, z]`; any non-zero length.
    pub direction: [f32; 3],
    /// Irradiance on a plane perpendicular to the beam.
    pub irradiance: f32,
}

/// A generator of a scene description: a heightfield of waves.
#[derive(Clone, Debug, Deserialize)]
pub struct GeneratorDescription {
    /// Only `"heightfield"` is supported.
    pub shape: String,
    /// `"glass"` (refracts with `ior`) or `"mirror"`.
    pub material: String,
    /// Index of refraction of `"glass"`.
    pub ior: f32,
    /// Vertices along each side of the heightfield, 1 to [`MAX_DESCRIPTION_GRID`].
    pub n: usize,
    /// Side of the square heightfield, centred on the origin (m).
    pub size: f32,
    /// Rest height `y` of the surface (m).
    pub height: f32,
    /// `[kx, kz, amplitude, phase]` per wave.
    pub waves: Vec<[f32; 4]>,
    /// glTF's `doubleSided` ([`crate::scene::Sides`]); one-sided when left out.
    #[serde(default)]
    pub double_sided: bool,
}

/// The receiver of a scene description: a floor, and the square measured on it.
#[derive(Clone, Debug, Deserialize)]
pub struct ReceiverDescription {
    /// Height of the floor (m).
    pub y: f32,
    /// Side of the measured square, centred on the origin.
    pub size: f32,
}

impl SceneDescription {
    /// Parses the JSON text of a scene description.
    pub fn from_json(text: &str) -> Result<Self, String> {
        serde_json::from_str(text).map_err(|e| format!("scene description does not parse: {e}"))
    }

    /// Builds the scene, with its measured region cut into `cells × cells`.
    pub fn build(&self, cells: usize) -> Result<BenchScene, String> {
        if self.light.kind != "directional" {
            return Err(format!("light type {:?} is not supported (only \"directional\")", self.light.kind));
        }
        let light = Light::white(LightKind::Directional { direction: Vec3::from_array(self.light.direction), irradiance: self.light.irradiance });
        let generators = self
            .generators
            .iter()
            .map(|g| {
                if g.shape != "heightfield" {
                    return Err(format!("generator shape {:?} is not supported (only \"heightfield\")", g.shape));
                }
                let interaction = match g.material.as_str() {
                    "glass" => SpecularInteraction::Refract { ior: g.ior, dispersion: None },
                    "mirror" => SpecularInteraction::Reflect,
                    m => return Err(format!("generator material {m:?} is not supported (\"glass\" or \"mirror\")")),
                };
                if !(1..=MAX_DESCRIPTION_GRID).contains(&g.n) {
                    return Err(format!("heightfield n = {} is out of range (1 to {MAX_DESCRIPTION_GRID} cells a side)", g.n));
                }
                let waves: Vec<Wave> = g.waves.iter().map(|&[kx, kz, amplitude, phase]| Wave { kx, kz, amplitude, phase }).collect();
                let mesh = try_wave_heightfield(g.n, g.size, g.height, &waves).map_err(|e| format!("the heightfield's waves make no mesh: {e}"))?;
                Ok(Generator { mesh, interaction, double_sided: g.double_sided })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let half = 0.5 * self.receiver.size;
        let mut floor = floor(8.0 * self.receiver.size);
        floor.mesh = floor.mesh.transformed(&glam::Affine3A::from_translation(Vec3::Y * self.receiver.y));
        let scene = Scene { lights: vec![light], generators, receivers: vec![floor] };
        scene.validate().map_err(|e| e.to_string())?;
        Ok(BenchScene { name: self.name.clone(), scene, region: GridRegion::horizontal(-half, -half, self.receiver.y, self.receiver.size, cells) })
    }
}

//! ECS churn on lavapipe: for 500 frames, random spawns, despawns and mutations of
//! generators (every technique), receivers, media, lights, `Ocean`, `PoolRipples`, their
//! meshes and settings — invalid values included, and back. No panic; every few frames a
//! frame is read back (a wgpu validation error stops Bevy's rendering, and the readback
//! with it) and the caustic irradiance buffer holds finite values; an invalid generator
//! or medium carries `InvalidCausticParams` the frame after it broke and loses it the
//! frame after it was fixed (as `components.rs` documents). Once everything is despawned,
//! the GPU memory the device holds returns to what it held before the first spawn,
//! measured from wgpu's allocator report, allocation by allocation. The moving water is
//! drawn with Bevy's transmission, so that the pass dimming a medium behind it runs in
//! some of the frames read back (checked).
//!
//! One test function: a process holds one Bevy app with a render device at a time.

mod support;

use bevy::prelude::*;
use bevy_caustics::convolution::{DropPebble, PoolRipples};
use bevy_caustics::headless::HeadlessRenderer;
use bevy_caustics::hierarchical_maps::HierarchicalMapsSettings;
use bevy_caustics::illumination_textures::IlluminationTexturesSettings;
use bevy_caustics::ocean::Ocean;
use bevy_caustics::{CausticGenerator, CausticReceiver, CausticTechnique, Caustics, GeneratorInteraction, InvalidCausticParams, ParticipatingMedium};
use caustics_core::rng::Pcg32;
use std::collections::BTreeMap;
use support::render;

const FRAMES: u32 = 500;
const SIZE: u32 = 32;
/// Every this many frames a frame is read back and checked.
const READBACK_EVERY: u32 = 25;
/// The most entities alive at once (lights count), so that a frame stays cheap on a
/// software rasteriser.
const MOST_ALIVE: usize = 14;

const TECHNIQUES: [CausticTechnique; 5] = [
    CausticTechnique::Auto,
    CausticTechnique::WarpedVolumes,
    CausticTechnique::HierarchicalMaps,
    CausticTechnique::IlluminationTextures,
    CausticTechnique::Convolution,
];

/// Indices of refraction a generator gets, the edge cases of the core's checks among them.
const IORS: [f32; 6] = [1.0, 1.0 + 1e-7, 1.333, 1.5, 2.42, 4.0];

/// A value that breaks an entity's settings, and the settings to put back.
#[derive(Clone)]
enum Broken {
    Generator(CausticGenerator),
    Medium(ParticipatingMedium),
    Ocean(Ocean),
    Pool(PoolRipples),
}

struct Churn {
    rng: Pcg32,
    alive: Vec<Entity>,
    broken: Vec<(Entity, Broken)>,
    /// Entities that must carry `InvalidCausticParams` after this frame, and those that
    /// must not.
    expect_marked: Vec<Entity>,
    expect_clear: Vec<Entity>,
    receiver_material: Handle<StandardMaterial>,
    glass: Handle<StandardMaterial>,
    /// Bevy's transmission, on the moving water: what is seen through it behind a
    /// medium goes through the plugin's pass that dims it.
    water: Handle<StandardMaterial>,
}

impl Churn {
    fn uniform(&mut self) -> f32 {
        self.rng.next_f32()
    }

    fn below(&mut self, n: usize) -> usize {
        (self.rng.next_u32() as usize) % n
    }

    fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.below(items.len())]
    }

    fn position(&mut self) -> Vec3 {
        Vec3::new(self.uniform() * 4.0 - 2.0, 0.2 + self.uniform() * 2.0, self.uniform() * 4.0 - 2.0)
    }

    fn generator(&mut self) -> CausticGenerator {
        let interaction = if self.uniform() < 0.3 {
            GeneratorInteraction::Reflect
        } else {
            let dispersion = (self.uniform() < 0.2).then_some(Vec2::new(1.5, 0.004));
            GeneratorInteraction::Refract { ior: self.pick(&IORS), dispersion }
        };
        CausticGenerator { interaction, technique: self.pick(&TECHNIQUES), double_sided: self.uniform() < 0.5 }
    }

    /// A generator's mesh: a ball, a ring, a plane, or a modeller's mistake (zero-area
    /// and sliver triangles, duplicated vertices, NaN normals).
    fn mesh(&mut self) -> Mesh {
        match self.below(4) {
            0 => Sphere::new(0.1 + 0.5 * self.uniform()).mesh().ico(1).expect("a small icosphere"),
            1 => Torus::new(0.3, 0.5).mesh().minor_resolution(6).major_resolution(12).build(),
            2 => Plane3d::default().mesh().size(1.0, 1.0).subdivisions(3).build(),
            _ => {
                let positions = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1e-9, 0.0, 1e-9]];
                let normals = vec![[0.0, 1.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]];
                Mesh::new(bevy::mesh::PrimitiveTopology::TriangleList, default())
                    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
                    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
                    .with_inserted_indices(bevy::mesh::Indices::U32(vec![0, 2, 1, 3, 4, 5, 1, 1, 2]))
            }
        }
    }

    fn spawn(&mut self, world: &mut World) {
        let position = self.position();
        let entity = match self.below(8) {
            0 | 1 => {
                let mesh = world.resource_mut::<Assets<Mesh>>().add(self.mesh());
                let generator = self.generator();
                world.spawn((Mesh3d(mesh), MeshMaterial3d(self.glass.clone()), generator, Transform::from_translation(position))).id()
            }
            2 => {
                let mesh = world.resource_mut::<Assets<Mesh>>().add(Plane3d::default().mesh().size(8.0, 8.0));
                world.spawn((Mesh3d(mesh), MeshMaterial3d(self.receiver_material.clone()), CausticReceiver)).id()
            }
            3 => {
                let medium =
                    ParticipatingMedium { scattering: 0.3 * self.uniform(), absorption: Vec3::splat(0.1) * self.uniform(), asymmetry: 0.9 * self.uniform() };
                world.spawn((medium, Transform::from_scale(Vec3::splat(6.0)))).id()
            }
            4 => self.spawn_light(world, position),
            5 => {
                let ocean = Ocean { resolution: self.pick(&[8, 16, 32]), size: 4.0, on_gpu: self.uniform() < 0.7, ..default() };
                let generator = CausticGenerator { technique: self.pick(&TECHNIQUES), ..CausticGenerator::refractive(1.333) };
                world.spawn((ocean, generator, MeshMaterial3d(self.water.clone()), Transform::from_xyz(0.0, 1.0, 0.0))).id()
            }
            6 => {
                let columns = self.pick(&[8, 24, 48]);
                let pool = PoolRipples { columns, rows: columns, cell_size: 4.0 / columns as f32, ..default() };
                let generator = CausticGenerator { technique: self.pick(&TECHNIQUES), ..CausticGenerator::refractive(1.333) };
                world.spawn((pool, generator, MeshMaterial3d(self.water.clone()), Transform::from_xyz(0.0, 1.0, 0.0))).id()
            }
            _ => {
                world.write_message(DropPebble { position, strength: 0.05 * (self.uniform() - 0.5) });
                return;
            }
        };
        self.alive.push(entity);
    }

    /// A light: the sun from any side (grazing included), a point light anywhere (inside
    /// a generator, on a receiver) or a spot; from dark to blinding.
    fn spawn_light(&mut self, world: &mut World, position: Vec3) -> Entity {
        let power = self.pick(&[0.0, 1.0, 1e4, 1e8]);
        let direction = Vec3::new(self.uniform() - 0.5, -self.uniform(), self.uniform() - 0.5).try_normalize().unwrap_or(Vec3::NEG_Y);
        match self.below(3) {
            0 => world
                .spawn((DirectionalLight { illuminance: power, shadow_maps_enabled: true, ..default() }, Transform::default().looking_to(direction, Vec3::X)))
                .id(),
            1 => world.spawn((PointLight { intensity: power, shadow_maps_enabled: true, ..default() }, Transform::from_translation(position))).id(),
            _ => world
                .spawn((
                    SpotLight { intensity: power, shadow_maps_enabled: true, ..default() },
                    Transform::from_translation(position).looking_to(direction, Vec3::X),
                ))
                .id(),
        }
    }

    fn despawn(&mut self, world: &mut World) {
        if self.alive.is_empty() {
            return;
        }
        let index = self.below(self.alive.len());
        let entity = self.alive.swap_remove(index);
        self.broken.retain(|(e, _)| *e != entity);
        world.despawn(entity);
    }

    /// Breaks one live entity's settings (a generator's IOR below 1 or NaN, a medium's
    /// negative scattering, an ocean of resolution 3, a pool of no texels), or changes
    /// something valid: its technique, its transform (a zero scale included), its mesh.
    fn mutate(&mut self, world: &mut World) {
        if self.alive.is_empty() {
            return;
        }
        let index = self.below(self.alive.len());
        let entity = self.alive[index];
        let roll = self.uniform();
        let mut entity_mut = world.entity_mut(entity);
        if roll < 0.4 && !self.broken.iter().any(|(e, _)| *e == entity) {
            let saved = if let Some(mut generator) = entity_mut.get_mut::<CausticGenerator>() {
                let saved = Broken::Generator(generator.clone());
                generator.interaction = GeneratorInteraction::Refract { ior: if roll < 0.2 { 0.5 } else { f32::NAN }, dispersion: None };
                self.expect_marked.push(entity);
                Some(saved)
            } else if let Some(mut medium) = entity_mut.get_mut::<ParticipatingMedium>() {
                let saved = Broken::Medium(*medium);
                medium.scattering = -1.0;
                self.expect_marked.push(entity);
                Some(saved)
            } else {
                None
            };
            // A generator that is also an ocean or a pool breaks its water next time.
            if let Some(saved) = saved {
                self.expect_clear.retain(|e| *e != entity);
                self.broken.push((entity, saved));
            } else if let Some(mut ocean) = entity_mut.get_mut::<Ocean>() {
                self.broken.push((entity, Broken::Ocean(ocean.clone())));
                ocean.resolution = 3;
            } else if let Some(mut pool) = entity_mut.get_mut::<PoolRipples>() {
                self.broken.push((entity, Broken::Pool(pool.clone())));
                pool.columns = 0;
            }
        } else if roll < 0.55 {
            if let Some(mut generator) = entity_mut.get_mut::<CausticGenerator>() {
                generator.technique = TECHNIQUES[(roll * 1000.0) as usize % TECHNIQUES.len()];
            }
        } else if roll < 0.75 {
            let scale = if roll < 0.6 { 0.0 } else { 0.5 + roll };
            let translation = self.position();
            let mut entity_mut = world.entity_mut(entity);
            // Bevy's own lights cannot take a zero scale (their direction becomes NaN).
            let light = entity_mut.contains::<DirectionalLight>() || entity_mut.contains::<SpotLight>();
            if let Some(mut transform) = entity_mut.get_mut::<Transform>() {
                transform.scale = if light { Vec3::ONE } else { Vec3::splat(scale) };
                transform.translation = translation;
            }
        } else if let Some(Mesh3d(handle)) = world.get::<Mesh3d>(entity).cloned() {
            // The mesh rewritten in place (NaN positions among them), replaced, or taken away.
            if roll < 0.85 {
                if let Some(mut mesh) = world.resource_mut::<Assets<Mesh>>().get_mut(&handle)
                    && let Some(bevy::mesh::VertexAttributeValues::Float32x3(positions)) = mesh.attribute_mut(Mesh::ATTRIBUTE_POSITION)
                {
                    positions[0][1] = if roll < 0.8 { f32::NAN } else { 0.3 };
                }
            } else if roll < 0.93 {
                let mesh = world.resource_mut::<Assets<Mesh>>().add(self.mesh());
                world.entity_mut(entity).insert(Mesh3d(mesh));
            } else if world.get::<Ocean>(entity).is_none() && world.get::<PoolRipples>(entity).is_none() {
                world.entity_mut(entity).remove::<Mesh3d>();
            }
        }
    }

    /// Puts one broken entity's settings back.
    fn fix(&mut self, world: &mut World) {
        let Some((entity, saved)) = self.broken.pop() else { return };
        self.expect_marked.retain(|e| *e != entity);
        let mut entity_mut = world.entity_mut(entity);
        match saved {
            Broken::Generator(generator) => {
                entity_mut.insert(generator);
                self.expect_clear.push(entity);
            }
            Broken::Medium(medium) => {
                entity_mut.insert(medium);
                self.expect_clear.push(entity);
            }
            Broken::Ocean(ocean) => {
                entity_mut.insert(ocean);
            }
            Broken::Pool(pool) => {
                entity_mut.insert(pool);
            }
        }
    }
}

/// The GPU memory the device holds (bytes by allocation label), after enough frames for
/// dropped resources to be freed and Bevy's texture cache to let unused textures go.
fn settled_memory(renderer: &mut HeadlessRenderer) -> BTreeMap<String, u64> {
    render(renderer, 8);
    renderer.gpu_memory().expect("Vulkan's allocator reports its allocations")
}

fn total(memory: &BTreeMap<String, u64>) -> u64 {
    memory.values().sum()
}

#[test]
fn five_hundred_frames_of_churn_leave_no_panic_and_no_gpu_memory_behind() {
    let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    // Maps and textures small enough for a software rasteriser to churn through 500
    // frames in CI; what is churned is the entities, not the resolution.
    renderer.world_mut().insert_resource(HierarchicalMapsSettings { photon_resolution: 64, map_resolution: 128, ..default() });
    renderer.world_mut().insert_resource(IlluminationTexturesSettings { texture_size: 64, ..default() });
    let target = renderer.render_target();
    let camera = renderer.world_mut().spawn(support::top_down_camera(target, 6.0, SIZE, Vec3::ZERO)).id();
    let baseline = settled_memory(&mut renderer);

    let world = renderer.world_mut();
    let receiver_material = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial::default());
    let glass = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgba(0.9, 0.95, 1.0, 0.2),
        alpha_mode: AlphaMode::Blend,
        ..default()
    });
    let water = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { specular_transmission: 0.9, ior: 1.333, ..default() });
    let mut churn = Churn {
        rng: Pcg32::for_photon(13, 0, 0),
        alive: Vec::new(),
        broken: Vec::new(),
        expect_marked: Vec::new(),
        expect_clear: Vec::new(),
        receiver_material,
        glass,
        water,
    };
    let mut most_memory = 0;
    let mut dimmed_behind_water = 0;
    for frame in 0..FRAMES {
        let world = renderer.world_mut();
        for _ in 0..1 + churn.below(3) {
            let roll = churn.uniform();
            if roll < 0.35 && churn.alive.len() < MOST_ALIVE {
                churn.spawn(world);
            } else if roll < 0.55 {
                churn.despawn(world);
            } else if roll < 0.85 {
                churn.mutate(world);
            } else {
                churn.fix(world);
            }
        }
        if churn.uniform() < 0.05 {
            let mut settings = world.get_mut::<Caustics>(camera).expect("the camera");
            settings.shafts = !settings.shafts;
            settings.intensity = if settings.intensity == 1.0 { f32::NAN } else { 1.0 };
        }
        renderer.app.update();
        let world = renderer.world_mut();
        for entity in churn.expect_marked.drain(..) {
            if let Ok(entity_ref) = world.get_entity(entity) {
                assert!(entity_ref.contains::<InvalidCausticParams>(), "frame {frame}: {entity} was broken and is not marked invalid");
            }
        }
        for entity in churn.expect_clear.drain(..) {
            if let Ok(entity_ref) = world.get_entity(entity) {
                let still_broken = churn.broken.iter().any(|(e, _)| *e == entity);
                assert!(still_broken || !entity_ref.contains::<InvalidCausticParams>(), "frame {frame}: {entity} was fixed and is still marked invalid");
            }
        }
        if frame % READBACK_EVERY == READBACK_EVERY - 1 {
            render(&mut renderer, 0);
            let irradiance = renderer.caustic_irradiance(camera).unwrap_or_else(|e| panic!("frame {frame}: {e}"));
            let bad = irradiance.iter().find(|e| !e.is_finite() || e.min_element() < 0.0);
            assert!(bad.is_none(), "frame {frame}: a caustic pixel holds {bad:?}");
            dimmed_behind_water += renderer.pass_report().passes.iter().any(|(p, _)| *p == "medium_behind_transmission") as u32;
            let memory = total(&renderer.gpu_memory().expect("an allocator report"));
            most_memory = most_memory.max(memory);
            eprintln!(
                "frame {frame}: {} entities alive, {:.1} MiB of GPU memory, passes {:?}",
                churn.alive.len(),
                memory as f64 / 1048576.0,
                renderer.pass_report()
            );
        }
    }

    assert!(dimmed_behind_water > 0, "no frame read back dimmed a medium behind the transmissive water");
    for entity in churn.alive.drain(..) {
        renderer.world_mut().despawn(entity);
    }
    let after = settled_memory(&mut renderer);
    let mib = |bytes: u64| bytes as f64 / 1048576.0;
    eprintln!(
        "GPU memory: {:.2} MiB before the first spawn, at most {:.2} MiB during the churn, {:.2} MiB once everything was despawned",
        mib(total(&baseline)),
        mib(most_memory),
        mib(total(&after))
    );
    // The plugin labels every buffer and texture it makes `caustic_…`; Bevy keeps the
    // capacity its own buffers grew to (instances, bins, views, shadow maps) for reuse.
    let ours = |memory: &BTreeMap<String, u64>| -> BTreeMap<String, u64> {
        memory.iter().filter(|(label, _)| label.starts_with("caustic_")).map(|(l, b)| (l.clone(), *b)).collect()
    };
    let (ours_before, ours_after) = (ours(&baseline), ours(&after));
    eprintln!("the plugin's own: {} bytes before the first spawn, {} bytes once everything was despawned", total(&ours_before), total(&ours_after));
    let labels: std::collections::BTreeSet<&String> = baseline.keys().chain(after.keys()).collect();
    for label in labels {
        let (before, now) = (baseline.get(label).unwrap_or(&0), after.get(label).unwrap_or(&0));
        if before != now {
            eprintln!("  {label}: {before} → {now} bytes");
        }
    }
    assert_eq!(ours_after, ours_before, "the plugin's GPU memory did not return to its baseline");
}

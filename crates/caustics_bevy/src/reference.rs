//! The ground-truth tracer as a caustics source for a Bevy view: meshes between the
//! two worlds, core scenes as Bevy entities, and the tracer's caustic irradiance at the surface each pixel of a camera
//! sees, ready for [`crate::InjectedIrradiance`]. The demo and `caustics render
//! --renderer bevy` show reference caustics through the plugin's own composite this way.

use crate::read_scene::{
    AnyLight, LightComponents, MeshComponents, OccluderComponents, bevy_mesh, blocks_caustic_light, core_light, core_mesh, to_core, to_core_affine,
};
use crate::{CausticGenerator, CausticReceiver, CausticTechnique, Caustics, GeneratorInteraction, InjectedIrradiance, ParticipatingMedium};
use bevy::camera::{Exposure, RenderTarget};
use bevy::prelude::*;
use caustics_core::bvh::Surface;
use caustics_core::estimate::PhotonMap;
use caustics_core::glam;
use caustics_core::params::SpecularInteraction;
use caustics_core::scene::{LightKind, Scene};
use caustics_core::tracer::PhotonTracer;
use caustics_core::view::{MediumView, PinholeCamera, PoolView, SceneView};
use rayon::prelude::*;
use std::f32::consts::PI;

/// A core vector as Bevy's.
fn to_bevy(v: glam::Vec3) -> Vec3 {
    Vec3::from_array(v.to_array())
}

/// Caustic irradiance at the first receiver each pixel's ray meets, passing straight
/// through generators — the surface the composite shades, since Bevy draws
/// generators without refraction. Row-major, zero where no receiver is seen.
pub fn view_irradiance(tracer: &PhotonTracer, photons: &PhotonMap, camera: &PinholeCamera) -> Vec<Vec3> {
    view_irradiance_on(tracer, photons, camera, |_| true).into_iter().map(|e| e.unwrap_or(Vec3::ZERO)).collect()
}

/// [`view_irradiance`] on the receivers `shown` (by index in the scene) only: `None`
/// where a pixel sees no receiver, or one that is not shown (an occluder, say).
pub fn view_irradiance_on(tracer: &PhotonTracer, photons: &PhotonMap, camera: &PinholeCamera, shown: impl Fn(usize) -> bool + Sync) -> Vec<Option<Vec3>> {
    view_gather(tracer, camera, shown, |p, n| to_bevy(photons.irradiance_at(p, n)))
}

/// `gather(point, normal)` at the first receiver each pixel's ray meets, passing
/// straight through generators, where that receiver is `shown`.
fn view_gather<T: Send>(
    tracer: &PhotonTracer,
    camera: &PinholeCamera,
    shown: impl Fn(usize) -> bool + Sync,
    gather: impl Fn(glam::Vec3, glam::Vec3) -> T + Sync,
) -> Vec<Option<T>> {
    (0..camera.width * camera.height)
        .into_par_iter()
        .map(|i| {
            let (mut origin, dir) = camera.ray(i % camera.width, i / camera.width);
            // A few generator layers at most (both faces of a closed glass object).
            for _ in 0..8 {
                let hit = tracer.bvh().intersect(origin, dir, 0.0, f32::INFINITY)?;
                let p = origin + dir * hit.t;
                if let Surface::Receiver(index) = hit.surface {
                    return shown(index as usize).then(|| gather(p, hit.geometric_normal));
                }
                origin = p + dir * (1e-4 * (1.0 + p.abs().max_element()));
            }
            None
        })
        .collect()
}

/// The scene the caustics plugin sees in a world ([`scene_from_world`]).
pub struct WorldScene {
    /// The core crate's scene: generators, receivers, lights, media.
    pub scene: Scene,
    /// How many of its receivers are [`CausticReceiver`]s: they come first.
    pub shown: usize,
    /// The entity each of its generators comes from.
    pub generators: Vec<Entity>,
    /// What was left out, and why.
    pub skipped: Vec<String>,
}

/// The scene the caustics plugin sees in `world` now, as the core crate's: every
/// valid, visible [`CausticGenerator`] (whatever its technique), the visible
/// [`CausticReceiver`]s with their `StandardMaterial` base colour as albedo, then every
/// other mesh that blocks caustic light ([`blocks_caustic_light`]) as a receiver too,
/// and every visible light. A mesh that is not loaded or that the core refuses is left
/// out and named in [`WorldScene::skipped`].
pub fn scene_from_world(world: &mut World) -> WorldScene {
    use caustics_core::scene::{Generator, Receiver};
    let mut scene = Scene::default();
    let mut skipped = Vec::new();
    let mut generators = world.query_filtered::<(Entity, &CausticGenerator, MeshComponents), Without<crate::InvalidCausticParams>>();
    let mut meshes_of = world.query_filtered::<(Entity, OccluderComponents, Option<&MeshMaterial3d<StandardMaterial>>), Without<CausticGenerator>>();
    let mut lights = world.query_filtered::<LightComponents, AnyLight>();
    let moving = moving_meshes(world);
    let meshes = world.resource::<Assets<Mesh>>();
    let materials = world.resource::<Assets<StandardMaterial>>();
    let mut core =
        |entity: Entity, mesh: &Mesh3d, transform: &GlobalTransform| match moving.get(&entity).or_else(|| meshes.get(&mesh.0)).map(|m| core_mesh(m, transform))
        {
            Some(Ok(mesh)) => Some(mesh),
            Some(Err(e)) => {
                skipped.push(format!("{entity}: {e}"));
                None
            }
            None => {
                skipped.push(format!("{entity}: its mesh is not loaded"));
                None
            }
        };
    let mut generator_entities = Vec::new();
    for (entity, generator, (mesh, transform, visible, _)) in generators.iter(world) {
        if let Some(mesh) = visible.get().then(|| core(entity, mesh, transform)).flatten() {
            scene.generators.push(Generator { mesh, interaction: generator.specular_interaction(), double_sided: generator.double_sided });
            generator_entities.push(entity);
        }
    }
    let mut occluders = Vec::new();
    for (entity, ((mesh, transform, visible, _), receiver, no_shadows), material) in meshes_of.iter(world) {
        if !blocks_caustic_light(visible, receiver, no_shadows) {
            continue;
        }
        let Some(mesh) = core(entity, mesh, transform) else { continue };
        let c = material.and_then(|m| materials.get(&m.0)).map_or(LinearRgba::WHITE, |m| m.base_color.to_linear());
        let receiver_of = Receiver { mesh, albedo: glam::Vec3::new(c.red, c.green, c.blue) };
        if receiver {
            scene.receivers.push(receiver_of);
        } else {
            occluders.push(receiver_of);
        }
    }
    let shown = scene.receivers.len();
    scene.receivers.extend(occluders);
    for (directional, point, spot, transform, visible) in lights.iter(world) {
        if let Some(light) = visible.get().then(|| core_light(directional, point, spot, transform)).flatten() {
            scene.lights.push(light);
        }
    }
    WorldScene { scene, shown, generators: generator_entities, skipped }
}

/// What `camera` shows of `world` now, as a saved frame keeps it: [`scene_from_world`]'s
/// scene, with its pools' water and impulses ([`PoolView`]) and its visible, valid
/// media ([`MediumView`]), and what was left out.
pub fn frame_of_world(world: &mut World, camera: PinholeCamera) -> (SceneView, Vec<String>) {
    let WorldScene { scene, shown, generators, skipped } = scene_from_world(world);
    let pools = generators.iter().enumerate().filter_map(|(index, &entity)| pool_view(world, entity, index)).collect();
    let mut media = world.query_filtered::<(&ParticipatingMedium, &GlobalTransform, &InheritedVisibility), Without<crate::InvalidCausticParams>>();
    let media = media
        .iter(world)
        .filter(|(_, _, visible)| visible.get())
        .map(|(medium, transform, _)| MediumView { transform: to_core_affine(&transform.affine()), coefficients: medium.coefficients() })
        .collect();
    (SceneView { scene, shown, camera, pools, media }, skipped)
}

/// A core affine transform as a Bevy `Transform`.
fn transform_of(a: &glam::Affine3A) -> Transform {
    Transform::from_matrix(Mat4::from_cols_array(&glam::Mat4::from(*a).to_cols_array()))
}

/// The meshes the GPU moves, as of now: each rippling pool's water
/// (`PoolSurface::mesh_at`) and each ocean whose waves the GPU evaluates. Their mesh
/// assets are not rewritten while they move.
fn moving_meshes(world: &mut World) -> bevy::platform::collections::HashMap<Entity, Mesh> {
    let mut meshes = bevy::platform::collections::HashMap::default();
    let Some(time) = world.get_resource::<Time>().map(Time::elapsed_secs) else {
        return meshes;
    };
    #[cfg(feature = "convolution")]
    {
        let mut pools = world.query::<(Entity, &crate::convolution::PoolSurface)>();
        meshes.extend(pools.iter(world).filter_map(|(entity, surface)| Some((entity, surface.mesh_at(time).ok()?))));
    }
    #[cfg(feature = "ocean")]
    {
        let mut oceans = world.query_filtered::<(Entity, &crate::Ocean), With<crate::mesh_vertices::MovesOnGpu>>();
        let seas = oceans.iter(world).filter_map(|(entity, ocean)| {
            let spectrum = caustics_core::ocean::OceanSpectrum::new(&ocean.settings()).ok()?;
            Some((entity, bevy_mesh(&spectrum.evaluate(time * ocean.time_scale).mesh())))
        });
        meshes.extend(seas);
    }
    meshes
}

/// The pool on `entity` with water, as the frame's generator `index`.
#[cfg(feature = "convolution")]
fn pool_view(world: &World, entity: Entity, index: usize) -> Option<PoolView> {
    let pool = world.get::<crate::PoolRipples>(entity)?;
    let surface = world.get::<crate::convolution::PoolSurface>(entity)?;
    let transform = world.get::<GlobalTransform>(entity)?;
    Some(pool.to_view(index, transform, surface, world.get_resource::<Time>()?.elapsed_secs()))
}

#[cfg(not(feature = "convolution"))]
fn pool_view(_: &World, _: Entity, _: usize) -> Option<PoolView> {
    None
}

/// The ground truth of a view ([`trace_view`]).
#[derive(Clone, Debug, Default)]
pub struct TracedView {
    /// The caustic irradiance at the surface each pixel sees, on a shown receiver.
    pub irradiance: Vec<Option<Vec3>>,
    /// The relative L2 by which the photons' randomness alone puts `irradiance` off
    /// the truth (the kernel's blur not counted), of the mean of RGB over the measured
    /// pixels. `irradiance` is the mean `(a + b)/2` of two independent traces of half
    /// the photons each; `(a − b)/2` has the same variance and a mean of zero, so
    /// `‖a − b‖ / ‖a + b‖` estimates it. Two traces of the same view from other photon
    /// streams differ by about √2 times this.
    pub noise: f32,
}

/// The ground truth of a view: `scene` traced with `photons` per light, in two halves
/// from photon streams `2·seed` and `2·seed + 1` ([`TracedView::noise`]), gathered
/// with a kernel of `radius` metres at the surface each pixel of `camera` sees, on the
/// first `shown` receivers only (as [`scene_from_world`] orders them).
/// `progress(done, total)` is called between batches of photons.
pub fn trace_view(
    scene: &Scene,
    shown: usize,
    camera: &PinholeCamera,
    (photons, seed): (u64, u64),
    radius: f32,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<TracedView, String> {
    use caustics_core::estimate::PhotonList;
    use caustics_core::tracer::TraceSettings;
    let tracer = PhotonTracer::new(scene).map_err(|e| e.to_string())?;
    let half = photons.div_ceil(2);
    let halves = [0, 1].map(|h| {
        let mut list = PhotonList::default();
        let settings = TraceSettings { photons_per_light: half, seed: 2 * seed + h, ..default() };
        tracer.trace(&settings, &mut list, &|done, total| progress(h * total + done, 2 * total));
        PhotonMap::new(list.0, radius)
    });
    let pairs = view_gather(&tracer, camera, |i| i < shown, |p, n| halves.each_ref().map(|m| to_bevy(m.irradiance_at(p, n))));
    let grey = |e: Vec3| f64::from(e.element_sum() / 3.0);
    let (mut apart, mut sum) = (0.0f64, 0.0f64);
    for [a, b] in pairs.iter().flatten() {
        apart += grey(*a - *b).powi(2);
        sum += grey(*a + *b).powi(2);
    }
    let noise = if sum > 0.0 { (apart / sum).sqrt() as f32 } else { 0.0 };
    Ok(TracedView { irradiance: pairs.into_iter().map(|p| p.map(|[a, b]| 0.5 * (a + b))).collect(), noise })
}

/// A view's caustic irradiance against [`trace_view`]'s, as the bench measures a
/// region: relative L2 (the figure of merit) and relative L1 (robust to the few pixels
/// at a focus or cusp that dominate L2) of the mean of RGB, over the pixels that see a
/// shown receiver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewError {
    /// Relative L2.
    pub l2: f32,
    /// Relative L1.
    pub l1: f32,
    /// Pixels measured.
    pub pixels: usize,
}

/// [`ViewError`] of `image` against `reference`; `None` when no pixel sees a shown
/// receiver.
pub fn view_error(image: &[Vec3], reference: &[Option<Vec3>]) -> Option<ViewError> {
    use caustics_core::metrics::{relative_l1, relative_l2};
    let mean = |e: Vec3| (e.x + e.y + e.z) / 3.0;
    let (a, b): (Vec<f32>, Vec<f32>) = image.iter().zip(reference).filter_map(|(e, r)| Some((mean(*e), mean((*r)?)))).unzip();
    (!b.is_empty()).then(|| ViewError { l2: relative_l2(&a, &b), l1: relative_l1(&a, &b), pixels: b.len() })
}

/// The pinhole camera that matches a Bevy perspective camera at `transform`.
pub fn pinhole(transform: &Transform, fov_y: f32, width: u32, height: u32) -> PinholeCamera {
    PinholeCamera {
        position: to_core(transform.translation),
        look_at: to_core(transform.translation + transform.forward().as_vec3()),
        up: to_core(transform.up().as_vec3()),
        fov_y,
        width,
        height,
    }
}

/// Spawns `scene` into `world`: receivers with their albedo and [`CausticReceiver`],
/// generators as glass or mirror, the lights (core intensities per steradian become
/// Bevy's lumens, ×4π), and an HDR camera at `camera` rendering into `target`. With
/// `injected` irradiance (one value per pixel, e.g. the tracer's), the camera shows
/// that and the generators are plain meshes; without, the generators get
/// [`CausticGenerator`] and the plugin's techniques draw the caustics live. The
/// receivers from `shown` on only block light ([`spawn_scene_content`]). Ambient
/// light is switched off, and exposure set so that `typical` lux on a white receiver
/// comes out at mid grey.
pub fn spawn_scene(world: &mut World, (scene, shown): (&Scene, usize), camera: &PinholeCamera, target: RenderTarget, injected: Option<&[Vec3]>, typical: f32) {
    let injected = injected.map(|irradiance| {
        let image = crate::pixels::irradiance_image(camera.width, camera.height, irradiance);
        world.resource_mut::<Assets<Image>>().add(image)
    });
    spawn_scene_content(world, scene, shown, injected.is_none().then_some(CausticTechnique::Auto));
    let mut camera = world.spawn((
        Camera3d::default(),
        Caustics::default(),
        target,
        exposure_for(typical),
        Projection::from(PerspectiveProjection { fov: camera.fov_y, ..default() }),
        Transform::from_translation(to_bevy(camera.position)).looking_at(to_bevy(camera.look_at), to_bevy(camera.up)),
    ));
    if let Some(injected) = injected {
        camera.insert(InjectedIrradiance(injected));
    }
}

/// A core generator as Bevy draws it (glass or a mirror, one- or double-sided) and
/// as the plugin's [`CausticGenerator`] asking for `Auto`.
fn generator_of(generator: &caustics_core::scene::Generator) -> (StandardMaterial, CausticGenerator) {
    let (material, component) = match generator.interaction {
        SpecularInteraction::Reflect => (StandardMaterial { metallic: 1.0, perceptual_roughness: 0.02, ..default() }, CausticGenerator::mirror()),
        SpecularInteraction::Refract { ior, dispersion } => (
            StandardMaterial { base_color: Color::srgba(0.9, 0.95, 1.0, 0.2), alpha_mode: AlphaMode::Blend, perceptual_roughness: 0.02, ior, ..default() },
            CausticGenerator {
                interaction: GeneratorInteraction::Refract { ior, dispersion: dispersion.map(|d| Vec2::new(d.a, d.b)) },
                ..CausticGenerator::refractive(ior)
            },
        ),
    };
    let double_sided = generator.double_sided;
    let material = StandardMaterial { double_sided, cull_mode: (!double_sided).then_some(bevy::render::render_resource::Face::Back), ..material };
    (material, CausticGenerator { technique: CausticTechnique::Auto, double_sided, ..component })
}

/// Spawns a saved frame as [`spawn_scene`] does, with its camera, every generator
/// asking `Auto`, its media, and its pools as pools ([`crate::PoolRipples`] started
/// with [`crate::PoolImpulses`]) where the plugin has them, else as their meshes.
pub fn spawn_scene_view(world: &mut World, view: &SceneView, target: RenderTarget, typical: f32) {
    let pools: &[PoolView] = if cfg!(feature = "convolution") { &view.pools } else { &[] };
    let is_pool = |index: usize| pools.iter().any(|p| p.generator == index);
    let generators = view.scene.generators.iter().enumerate().filter(|(i, _)| !is_pool(*i)).map(|(_, g)| g.clone()).collect();
    let scene = Scene { generators, ..view.scene.clone() };
    spawn_scene(world, (&scene, view.shown), &view.camera, target, None, typical);
    #[cfg(feature = "convolution")]
    for pool in pools {
        let (_, generator) = generator_of(&view.scene.generators[pool.generator]);
        world.spawn((
            crate::PoolRipples::from_view(pool),
            crate::PoolImpulses { impulses: pool.impulses.clone(), time: pool.time },
            generator,
            transform_of(&pool.transform),
        ));
    }
    for medium in &view.media {
        let c = medium.coefficients;
        world.spawn((ParticipatingMedium { scattering: c.scattering, absorption: c.absorption, asymmetry: c.asymmetry }, transform_of(&medium.transform)));
    }
}

/// The exposure at which `typical` lux on a white receiver comes out at mid grey:
/// exposure = 1 / (1.2 · 2^ev100), and white at `typical` lux has radiance typical/π.
pub fn exposure_for(typical: f32) -> Exposure {
    let exposure = 0.18 * PI / typical.max(1e-6);
    Exposure { ev100: (1.0 / (1.2 * exposure)).log2() }
}

/// Spawns `scene`'s receivers, generators and lights into `world` (see
/// [`spawn_scene`]), with ambient light off. The first `shown` receivers get
/// [`CausticReceiver`]; the rest only block light, as meshes that cast shadows do in a
/// game ([`scene_from_world`] reads them back in that order). With a `technique`, each
/// generator gets a [`CausticGenerator`] asking for it; without, generators are plain
/// meshes.
pub fn spawn_scene_content(world: &mut World, scene: &Scene, shown: usize, technique: Option<CausticTechnique>) {
    for (index, receiver) in scene.receivers.iter().enumerate() {
        let mesh = world.resource_mut::<Assets<Mesh>>().add(bevy_mesh(&receiver.mesh));
        let a = receiver.albedo;
        let material = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
            base_color: Color::linear_rgb(a.x, a.y, a.z),
            perceptual_roughness: 0.9,
            ..default()
        });
        let mut entity = world.spawn((Mesh3d(mesh), MeshMaterial3d(material)));
        if index < shown {
            entity.insert(CausticReceiver);
        }
    }
    for generator in &scene.generators {
        // Centred on its own origin, as a game's object is: the illumination textures
        // keep their tables in the object's frame.
        let (lo, hi) = generator.mesh.bounds();
        let centre = 0.5 * (lo + hi);
        let local = generator.mesh.transformed(&glam::Affine3A::from_translation(-centre));
        let mesh = world.resource_mut::<Assets<Mesh>>().add(bevy_mesh(&local));
        let (material, component) = generator_of(generator);
        let material = world.resource_mut::<Assets<StandardMaterial>>().add(material);
        let mut entity = world.spawn((Mesh3d(mesh), MeshMaterial3d(material), Transform::from_translation(to_bevy(centre))));
        if let Some(technique) = technique {
            entity.insert(CausticGenerator { technique, ..component });
        }
    }
    for light in &scene.lights {
        let color = Color::linear_rgb(light.color.x, light.color.y, light.color.z);
        // Bevy's lights end somewhere: a core light without a range gets 100 m, whose
        // window is within 2·10⁻⁶ of one inside 10 m.
        let range = if light.range.is_finite() { light.range } else { 100.0 };
        match light.kind {
            LightKind::Directional { direction, irradiance } => world.spawn((
                DirectionalLight { illuminance: irradiance, color, shadow_maps_enabled: true, ..default() },
                Transform::default().looking_to(to_bevy(direction), Vec3::Y),
            )),
            LightKind::Point { position, intensity } => world.spawn((
                PointLight { intensity: 4.0 * PI * intensity, color, range, shadow_maps_enabled: true, ..default() },
                Transform::from_translation(to_bevy(position)),
            )),
            LightKind::Spot { position, direction, intensity, inner_angle, outer_angle } => world.spawn((
                SpotLight { intensity: 4.0 * PI * intensity, color, range, inner_angle, outer_angle, shadow_maps_enabled: true, ..default() },
                Transform::from_translation(to_bevy(position)).looking_to(to_bevy(direction), Vec3::Y),
            )),
        };
    }
    // Core scenes are lit by their lights alone.
    world.insert_resource(bevy::light::GlobalAmbientLight { brightness: 0.0, ..default() });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mesh entity as the plugin's systems leave it: placed and visible (or not).
    fn place(world: &mut World, mesh: Mesh, at: Vec3, visible: bool) -> EntityWorldMut<'_> {
        let mesh = world.resource_mut::<Assets<Mesh>>().add(mesh);
        let visibility = if visible { InheritedVisibility::VISIBLE } else { InheritedVisibility::HIDDEN };
        world.spawn((Mesh3d(mesh), GlobalTransform::from_translation(at), visibility))
    }

    #[test]
    fn the_world_becomes_the_scene_the_techniques_see_and_its_view_is_measured_on_receivers_only() {
        let mut world = World::new();
        world.insert_resource(Assets::<Mesh>::default());
        world.insert_resource(Assets::<StandardMaterial>::default());
        let grey = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial { base_color: Color::linear_rgb(0.5, 0.5, 0.5), ..default() });
        place(&mut world, Plane3d::new(Vec3::Y, Vec2::splat(2.0)).mesh().build(), Vec3::ZERO, true).insert((CausticReceiver, MeshMaterial3d(grey)));
        // An occluder on the floor's left half, a hidden receiver, a glass ball over the right half.
        place(&mut world, Cuboid::new(1.0, 0.2, 4.0).mesh().build(), Vec3::new(-1.0, 0.1, 0.0), true);
        place(&mut world, Plane3d::new(Vec3::Y, Vec2::splat(9.0)).mesh().build(), Vec3::Y * 0.05, false).insert(CausticReceiver);
        place(&mut world, Sphere::new(0.3).mesh().ico(3).expect("an icosphere"), Vec3::new(1.0, 0.8, 0.0), true).insert(CausticGenerator::refractive(1.5));
        world.spawn((
            DirectionalLight { illuminance: 1000.0, ..default() },
            GlobalTransform::from(Transform::default().looking_to(Vec3::NEG_Y, Vec3::Z)),
            InheritedVisibility::VISIBLE,
        ));

        let WorldScene { scene, shown, skipped, .. } = scene_from_world(&mut world);
        assert!(skipped.is_empty(), "{skipped:?}");
        assert_eq!((scene.generators.len(), scene.receivers.len(), shown, scene.lights.len()), (1, 2, 1, 1));
        assert_eq!(scene.receivers[0].albedo, glam::Vec3::splat(0.5));
        assert!(matches!(scene.lights[0].kind, LightKind::Directional { irradiance: 1000.0, .. }));

        // Straight down on the floor: the occluder's pixels are not measured, the floor's are.
        let camera = PinholeCamera { position: glam::Vec3::Y * 4.0, look_at: glam::Vec3::ZERO, up: glam::Vec3::Z, fov_y: 0.9, width: 48, height: 48 };
        let traced = trace_view(&scene, shown, &camera, (1 << 18, 0), 0.05, &|_, _| {}).expect("a valid scene");
        let reference = traced.irradiance;
        // The noise it reports is how far a trace of other photons lands from it.
        let other = trace_view(&scene, shown, &camera, (1 << 18, 1), 0.05, &|_, _| {}).expect("a valid scene");
        let grey = |v: &[Option<Vec3>]| v.iter().flatten().map(|e| (e.x + e.y + e.z) / 3.0).collect::<Vec<f32>>();
        let apart = caustics_core::metrics::relative_l2(&grey(&other.irradiance), &grey(&reference));
        let expected = (traced.noise.powi(2) + other.noise.powi(2)).sqrt();
        eprintln!("two traces {apart:.4} apart; their own noise {:.4} and {:.4}", traced.noise, other.noise);
        assert!((apart / expected - 1.0).abs() < 0.15, "two traces {apart} apart, their noise {} and {}", traced.noise, other.noise);
        let measured = reference.iter().filter(|e| e.is_some()).count();
        assert!((48 * 48 / 4..48 * 48 * 3 / 4).contains(&measured), "{measured} of {} pixels on the floor", 48 * 48);
        // The ball's light lands under it, on the floor.
        assert!(reference.iter().flatten().any(|e| e.x > 1000.0), "a focus brighter than the light");
        let same: Vec<Vec3> = reference.iter().map(|e| e.unwrap_or(Vec3::splat(1e9))).collect();
        assert_eq!(view_error(&same, &reference), Some(ViewError { l2: 0.0, l1: 0.0, pixels: measured }), "pixels off the receivers do not count");
        assert_eq!(view_error(&vec![Vec3::ZERO; same.len()], &reference), Some(ViewError { l2: 1.0, l1: 1.0, pixels: measured }));
        assert_eq!(view_error(&same, &vec![None; same.len()]), None);
    }
}

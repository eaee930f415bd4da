//! Caustics under a real game's views, on a scene with a known answer: a flat plate of
//! IOR 1 bends and reflects nothing, so its caustic on the floor is exactly the floor's
//! direct light as Bevy draws it (see `gpu_lights.rs`). The plate is invisible to the
//! cameras and casts no shadow, so wherever caustics are shown the floor is twice as
//! bright as Bevy alone makes it.
//!
//! - Split screen: two cameras side by side on one target, each with its viewport,
//!   each get the caustics a lone camera gets; a camera that did not opt in with
//!   `Caustics` gets none, and nothing is added to it.
//! - `Caustics::intensity` scales what a view shows.
//! - `DistanceFog` dims caustics as bevy_pbr dims the floor's own light.
//! - A `ParticipatingMedium` between eye and floor dims them by exp(−σₜ ℓ).
//! - An `ExtendedMaterial` receiver shows them with its base colour.

mod support;

use bevy::camera::visibility::RenderLayers;
use bevy::camera::{RenderTarget, Viewport};
use bevy::core_pipeline::prepass::{DepthPrepass, NormalPrepass};
use bevy::light::{GlobalAmbientLight, NotShadowCaster};
use bevy::pbr::{DistanceFog, ExtendedMaterial, FogFalloff, MaterialExtension, MaterialPlugin};
use bevy::prelude::*;
use bevy::render::render_resource::AsBindGroup;
use bevy_caustics::headless::{HeadlessRenderer, RenderedImage};
use bevy_caustics::irradiance::CausticReceiverMaterialPlugin;
use bevy_caustics::read_scene::bevy_mesh;
use bevy_caustics::{CausticGenerator, CausticReceiver, CausticTechnique, Caustics, ParticipatingMedium, PoolRipples};
use caustics_core::mesh::TriMesh;
use caustics_core::metrics::relative_l2;
use support::{render, render_caustics, render_without_caustics};

/// Pixels per view side, and metres a view spans.
const SIZE: u32 = 64;
const VIEW: f32 = 2.0;
/// The point light: 20 cd at 2 m, range 20 m.
const LIGHT: Vec3 = Vec3::new(0.1, 2.0, -0.05);

/// The floor (a receiver, `material`), the IOR-1 plate over it (its caustics drawn
/// by `technique`) and the point light; for the convolution, a still 2 m pool of water
/// over the floor under a sun instead.
fn spawn_scene(world: &mut World, material: impl Bundle, technique: CausticTechnique) {
    world.insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
    world.insert_resource(ClearColor(Color::BLACK));
    let floor = world.resource_mut::<Assets<Mesh>>().add(Plane3d::new(Vec3::Y, Vec2::splat(4.0)).mesh());
    world.spawn((Mesh3d(floor), material, CausticReceiver));
    if technique == CausticTechnique::Convolution {
        let pool = PoolRipples { columns: 48, rows: 48, cell_size: 2.0 / 48.0, depth: 0.5, kernel_radius: 4, ..default() };
        let water = CausticGenerator { technique, ..CausticGenerator::refractive(1.333) };
        world.spawn((pool, water, RenderLayers::layer(1), Transform::from_xyz(0.1, 0.5, -0.05)));
        let sun = DirectionalLight { illuminance: 10.0, shadow_maps_enabled: false, ..default() };
        world.spawn((sun, Transform::default().looking_to(Vec3::new(0.3, -1.0, -0.2), Vec3::Y)));
        return;
    }
    let plate = TriMesh::heightfield(97, 3.0, |_, _| 1.0, |_, _| caustics_core::glam::Vec3::Y).unwrap();
    let plate = world.resource_mut::<Assets<Mesh>>().add(bevy_mesh(&plate));
    let generator = CausticGenerator { technique, ..CausticGenerator::refractive(1.0) };
    world.spawn((Mesh3d(plate), generator, RenderLayers::layer(1), NotShadowCaster, Transform::from_xyz(0.013, 0.0, 0.007)));
    let light = PointLight { intensity: 4.0 * std::f32::consts::PI * 20.0, range: 20.0, shadow_maps_enabled: false, ..default() };
    world.spawn((light, Transform::from_translation(LIGHT)));
}

/// A matte white `StandardMaterial`.
fn matte(world: &mut World) -> MeshMaterial3d<StandardMaterial> {
    let matte = StandardMaterial { perceptual_roughness: 1.0, reflectance: 0.0, ..default() };
    MeshMaterial3d(world.resource_mut::<Assets<StandardMaterial>>().add(matte))
}

/// A top-down camera over `centre` without caustics (support's camera, which opts in,
/// less its `Caustics`).
fn plain_camera(world: &mut World, target: RenderTarget, centre: Vec3) -> Entity {
    let camera = world.spawn(support::top_down_camera(target, VIEW, SIZE, centre)).id();
    world.entity_mut(camera).remove::<(Caustics, DepthPrepass, NormalPrepass)>();
    camera
}

/// The world point a view over `centre` sees at its pixel `(x, y)`.
fn floor_point(centre: Vec3, x: u32, y: u32) -> Vec3 {
    let s = VIEW / SIZE as f32;
    centre + Vec3::new((x as f32 + 0.5 - SIZE as f32 / 2.0) * s, 0.0, (y as f32 + 0.5 - SIZE as f32 / 2.0) * s)
}

/// Whether the point light reaches `p` within 25° of the floor's normal, where Bevy's
/// Burley diffuse is Lambert's to 10⁻⁵.
fn near_normal(p: Vec3) -> bool {
    (LIGHT - p).normalize().y > 25f32.to_radians().cos()
}

/// The red channel of the pixels `x0..x0 + SIZE` of each row: one view of a target.
fn view_pixels(image: &RenderedImage, x0: u32) -> Vec<f32> {
    (0..SIZE).flat_map(|y| (0..SIZE).map(move |x| (x0 + x, y))).map(|(x, y)| image.pixel(x, y).x).collect()
}

/// Caustic radiance over Bevy's direct radiance at the pixels where both are exact, and
/// the relative L2 difference of `caustic` from `scale ·` the direct light there.
fn against_direct(caustic: &[f32], direct: &[f32], centre: Vec3, scale: f32) -> (f32, usize) {
    let (ours, bevy): (Vec<f32>, Vec<f32>) =
        (0..SIZE * SIZE).filter(|&i| near_normal(floor_point(centre, i % SIZE, i / SIZE))).map(|i| (caustic[i as usize], scale * direct[i as usize])).unzip();
    (relative_l2(&ours, &bevy), ours.len())
}

fn difference(a: &[f32], b: &[f32]) -> Vec<f32> {
    a.iter().zip(b).map(|(a, b)| a - b).collect()
}

#[test]
fn split_screen_cameras_each_get_a_lone_cameras_caustics_and_only_when_they_opt_in() {
    // Volumes draw prisms into the buffer; the maps and the pool draw fullscreen
    // projections. The plate's against Bevy's direct light too (measured 2.7·10⁻³ for
    // the volumes, 1.1·10⁻³ for the maps: 5·10⁻³ holds both with a margin for
    // adapters that round differently); the pool's against a lone camera only.
    split_screen(CausticTechnique::WarpedVolumes, Some(5e-3));
    split_screen(CausticTechnique::HierarchicalMaps, Some(5e-3));
    split_screen(CausticTechnique::Convolution, None);
}

/// The split-screen test with the caustics drawn by `technique`, which match Bevy's
/// direct light to `direct_tolerance` (relative L2) where the scene has that answer.
fn split_screen(technique: CausticTechnique, direct_tolerance: Option<f32>) {
    let centres = [Vec3::new(-0.3, 0.0, 0.1), Vec3::new(0.35, 0.0, -0.2)];

    // The lone cameras: one full target each.
    let lone: Vec<Vec<f32>> = centres
        .iter()
        .map(|&centre| {
            let mut renderer = HeadlessRenderer::new(SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
            let target = renderer.render_target();
            let material = matte(renderer.world_mut());
            spawn_scene(renderer.world_mut(), material, technique);
            renderer.world_mut().spawn(support::top_down_camera(target, VIEW, SIZE, centre));
            let direct = view_pixels(&render_without_caustics(&mut renderer, 3), 0);
            let caustic = difference(&view_pixels(&render_caustics(&mut renderer, 2), 0), &direct);
            assert!(caustic.iter().sum::<f32>() > 0.0, "{technique:?}: no caustics for the lone camera over {centre}");
            if let Some(tolerance) = direct_tolerance {
                let (error, pixels) = against_direct(&caustic, &direct, centre, 1.0);
                eprintln!("{technique:?}, lone camera over {centre}: caustic against Bevy's direct light, relative L2 {error:.2e} on {pixels} pixels");
                assert!(pixels > 1000 && error < tolerance, "{technique:?}, lone camera over {centre}: relative L2 {error} on {pixels} pixels");
            }
            caustic
        })
        .collect();

    // Split screen: the left half opts in, the right half does not, yet.
    let mut renderer = HeadlessRenderer::new(2 * SIZE, SIZE).unwrap_or_else(|e| panic!("{e}"));
    let target = renderer.render_target();
    let material = matte(renderer.world_mut());
    spawn_scene(renderer.world_mut(), material, technique);
    let viewport = |x: u32| Some(Viewport { physical_position: UVec2::new(x, 0), physical_size: UVec2::splat(SIZE), ..default() });
    let world = renderer.world_mut();
    let left = world.spawn(support::top_down_camera(target.clone(), VIEW, SIZE, centres[0])).id();
    world.entity_mut(left).insert(Camera { viewport: viewport(0), order: 0, ..default() });
    let right = plain_camera(world, target, centres[1]);
    world.entity_mut(right).insert(Camera { viewport: viewport(SIZE), order: 1, clear_color: ClearColorConfig::None, ..default() });

    let without = render_without_caustics(&mut renderer, 3);
    let with = render_caustics(&mut renderer, 2);
    let left_caustic = difference(&view_pixels(&with, 0), &view_pixels(&without, 0));
    let right_caustic = difference(&view_pixels(&with, SIZE), &view_pixels(&without, SIZE));
    let vs_lone = relative_l2(&left_caustic, &lone[0]);
    let (vs_bevy, _) = against_direct(&left_caustic, &view_pixels(&without, 0), centres[0], 1.0);
    eprintln!("{technique:?}, left half: against the lone camera {vs_lone:.2e}, against Bevy's direct light {vs_bevy:.2e}");
    assert!(vs_lone < 2e-3, "{technique:?}, left half: {vs_lone} against the lone camera");
    assert!(direct_tolerance.is_none_or(|t| vs_bevy < t), "{technique:?}, left half: {vs_bevy} against Bevy");
    let stray = right_caustic.iter().fold(0f32, |m, c| m.max(c.abs()));
    assert!(stray < 1e-4, "{technique:?}: the right camera did not opt in, yet shows caustics up to {stray}");
    let entity = renderer.world_mut().entity(right);
    assert!(!entity.contains::<DepthPrepass>() && !entity.contains::<NormalPrepass>(), "the plugin added prepasses to a camera that did not opt in");

    // The right half opts in at half intensity.
    renderer.world_mut().entity_mut(right).insert(Caustics { intensity: 0.5, ..default() });
    let with = render(&mut renderer, 2);
    let right_caustic = difference(&view_pixels(&with, SIZE), &view_pixels(&without, SIZE));
    let left_caustic = difference(&view_pixels(&with, 0), &view_pixels(&without, 0));
    let halved: Vec<f32> = lone[1].iter().map(|c| 0.5 * c).collect();
    let vs_lone = relative_l2(&right_caustic, &halved);
    let (vs_bevy, _) = against_direct(&right_caustic, &view_pixels(&without, SIZE), centres[1], 0.5);
    eprintln!("{technique:?}, right half at intensity ½: against the lone camera {vs_lone:.2e}, against half Bevy's direct light {vs_bevy:.2e}");
    assert!(vs_lone < 2e-3, "{technique:?}, right half: {vs_lone} against the lone camera");
    assert!(direct_tolerance.is_none_or(|t| vs_bevy < t), "{technique:?}, right half: {vs_bevy} against half Bevy's direct light");
    assert!(relative_l2(&left_caustic, &lone[0]) < 2e-3, "{technique:?}: the left half changed when the right one opted in");
}

#[derive(Asset, AsBindGroup, Reflect, Debug, Clone, Default)]
struct Tint {
    #[uniform(100)]
    unused: f32,
}

impl MaterialExtension for Tint {}

type TintedMaterial = ExtendedMaterial<StandardMaterial, Tint>;

#[test]
fn fog_media_and_extended_materials_dim_caustics_as_they_dim_bevys_light() {
    let centre = Vec3::new(0.05, 0.0, 0.0);
    let plugins = (MaterialPlugin::<TintedMaterial>::default(), CausticReceiverMaterialPlugin::<TintedMaterial>::default());
    let mut renderer = HeadlessRenderer::with_plugins(SIZE, SIZE, plugins).unwrap_or_else(|e| panic!("{e}"));
    let target = renderer.render_target();
    let material = matte(renderer.world_mut());
    spawn_scene(renderer.world_mut(), material, CausticTechnique::Auto);
    let camera = renderer.world_mut().spawn(support::top_down_camera(target, VIEW, SIZE, centre)).id();
    let direct = view_pixels(&render_without_caustics(&mut renderer, 3), 0);
    let caustic = difference(&view_pixels(&render_caustics(&mut renderer, 2), 0), &direct);
    let (error, _) = against_direct(&caustic, &direct, centre, 1.0);
    assert!(error < 5e-3, "without fog: relative L2 {error}");

    // Exponential fog: bevy_pbr keeps exp(−ρ d) of a surface's light, d from the
    // camera's position (5 m above the floor's centre) to the point.
    let density = 0.15;
    renderer.world_mut().entity_mut(camera).insert(DistanceFog { falloff: FogFalloff::Exponential { density }, ..default() });
    let fogged_direct = view_pixels(&render_without_caustics(&mut renderer, 2), 0);
    let fogged_caustic = difference(&view_pixels(&render_caustics(&mut renderer, 2), 0), &fogged_direct);
    let eye = centre + 5.0 * Vec3::Y;
    let expected: Vec<f32> = (0..SIZE * SIZE).map(|i| caustic[i as usize] * (-density * eye.distance(floor_point(centre, i % SIZE, i / SIZE))).exp()).collect();
    let error = relative_l2(&fogged_caustic, &expected);
    let unfogged = relative_l2(&fogged_caustic, &caustic);
    eprintln!("exponential fog: caustic against exp(−ρd) of the unfogged one {error:.2e} (unfogged caustic: {unfogged:.2e} off)");
    assert!(error < 3e-3 && unfogged > 0.4, "fog: {error} against exp(−ρd), {unfogged} against no fog");
    renderer.world_mut().entity_mut(camera).remove::<DistanceFog>();

    // An absorbing medium 1 m thick between the camera and the plate (no scattering,
    // so no shafts): the caustic seen through it is exp(−σₐ · 1 m) of itself. Bevy's
    // own light does not know the medium.
    let absorption = 0.5f32;
    let medium = ParticipatingMedium { scattering: 0.0, absorption: Vec3::splat(absorption), asymmetry: 0.0 };
    let slab = renderer.world_mut().spawn((medium, Transform::from_xyz(0.0, 2.5, 0.0).with_scale(Vec3::new(10.0, 1.0, 10.0)))).id();
    let through = difference(&view_pixels(&render(&mut renderer, 2), 0), &direct);
    let expected: Vec<f32> = caustic.iter().map(|c| c * (-absorption).exp()).collect();
    let error = relative_l2(&through, &expected);
    eprintln!("through 1 m of σa = {absorption}/m: caustic against exp(−σa) of the clear one {error:.2e}");
    assert!(error < 3e-3, "medium: {error} against exp(−σa ℓ)");
    renderer.world_mut().despawn(slab);

    // A receiver with an ExtendedMaterial of base colour ½: Bevy lights it at half, and
    // so do the caustics once the plugin reads that material.
    let world = renderer.world_mut();
    let base = StandardMaterial { base_color: Color::linear_rgb(0.5, 0.5, 0.5), perceptual_roughness: 1.0, reflectance: 0.0, ..default() };
    let tinted = world.resource_mut::<Assets<TintedMaterial>>().add(ExtendedMaterial { base, extension: Tint::default() });
    let floor = world.query_filtered::<Entity, With<CausticReceiver>>().single(world).unwrap();
    world.entity_mut(floor).remove::<MeshMaterial3d<StandardMaterial>>().insert(MeshMaterial3d(tinted));
    let tinted_direct = view_pixels(&render_without_caustics(&mut renderer, 3), 0);
    let tinted_caustic = difference(&view_pixels(&render_caustics(&mut renderer, 2), 0), &tinted_direct);
    let (error, pixels) = against_direct(&tinted_caustic, &tinted_direct, centre, 1.0);
    let (bevy_half, _) = against_direct(&tinted_direct, &direct, centre, 0.5);
    eprintln!(
        "ExtendedMaterial of base ½: caustic against Bevy's direct light {error:.2e} on {pixels} pixels (Bevy's own: {bevy_half:.2e} from half the white floor's)"
    );
    assert!(bevy_half < 5e-3, "Bevy does not light the tinted floor at half: {bevy_half}");
    assert!(error < 5e-3, "ExtendedMaterial receiver: {error} against Bevy's direct light");
}

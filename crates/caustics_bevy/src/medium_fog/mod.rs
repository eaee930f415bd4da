//! A [`ParticipatingMedium`] drawn by Bevy's own volumetric fog as well: the medium
//! keeps a `FogVolume` of the same box (the unit cube of the same transform) and
//! coefficients, so that Bevy dims everything seen through it by exp(−σₜ ℓ) and
//! scatters the shadow-mapped directional lights in it, while the plugin adds only the
//! caustic light: the surface caustics it composites are dimmed once, by Bevy's fog,
//! and the shafts, already dimmed along the eye ray, are added after it.
//!
//! Bevy 0.19 draws no fog at all without a camera that has `VolumetricFog` and a light
//! that has `VolumetricLight`: while a medium is in the scene, every 3D camera and
//! every directional light that has none gets one from the plugin (taken back when
//! the last medium goes). Point and spot lights are left as the game set them: Bevy
//! marches them without a phase function. Bevy attenuates the light on its way into
//! the fog by a constant, exp(−σₜ R) with R the box's half-diagonal, whatever the
//! point: the fog's `light_intensity` cancels it, which leaves the light unattenuated
//! inside the box (exact for a thin medium, or one the light enters through a
//! generator, whose light the plugin carries).
//!
//! Bevy's fog has one transmittance for all channels: it takes σₐ's least channel, and
//! [`tint`] multiplies in the colour of the rest. Where a transmissive surface is in
//! front (water seen from above), Bevy's fog ends its march at the surface and Bevy's
//! transmission shows an undimmed copy of what lies behind: [`behind_transmission`]
//! dims that copy by the media behind the surface.

mod behind_transmission;
mod dim;
mod tint;

use crate::components::{InvalidCausticParams, ParticipatingMedium};
use bevy::light::{FogVolume, VolumetricFog, VolumetricLight};
use bevy::prelude::*;

/// On a medium's entity: its `FogVolume` is the plugin's, taken away with the medium.
#[derive(Component)]
pub struct MediumFogVolume;

/// On a camera or light: the plugin gave it `VolumetricFog` or `VolumetricLight` for
/// the media, taken back when the last one goes.
#[derive(Component)]
pub struct AddedForMedia;

/// The march of the fog the plugin gives a camera: no ambient term (the plugin's media
/// scatter only the lights), no jitter (the image stays still), Bevy's 64 steps.
pub fn medium_fog() -> VolumetricFog {
    VolumetricFog { ambient_intensity: 0.0, jitter: 0.0, ..default() }
}

pub(crate) fn build(app: &mut App) {
    let cpu = crate::CausticCpuTime::of(app).main;
    app.add_systems(
        PostUpdate,
        (crate::cpu_time::timed(&cpu, keep_fog_volumes), crate::cpu_time::timed(&cpu, give_fog_to_views)).chain().in_set(crate::CausticSystems::ReadScene),
    );
    dim::build(app);
    behind_transmission::build(app);
    tint::build(app);
}

/// What Bevy's fog draws of a medium: density, σₐ's grey part, σₛ, g, the light
/// intensity that cancels Bevy's constant attenuation of the light into the box, and
/// the light tint (linear RGB) that colours the light it scatters.
type FogCoefficients = [f32; 8];

/// The coefficients of `medium` in a box placed by `transform`. Bevy's fog has one
/// transmittance for all channels, so it takes σₐ's least channel; [`tint`] dims by
/// the rest. Light that Bevy scatters at distance s along the eye ray should reach the
/// eye dimmed by exp(−σₜ,c s) per channel, but Bevy dims it by exp(−σₜ,min s): the tint
/// σₜ,min/σₜ,c makes what it gathers along a ray that ends deep in the medium (the
/// water's haze) exact, ∫ σₛ E e^{−σₜ,c s} ds = σₛ E/σₜ,c, and tints the faint haze of
/// a short path too deeply, by up to that factor as the path goes to nothing.
fn fog_coefficients(medium: &ParticipatingMedium, transform: &GlobalTransform) -> FogCoefficients {
    let half_diagonal = (transform.affine().matrix3 * Vec3A::splat(0.5)).length();
    let grey = medium.absorption.min_element();
    let extinction = medium.coefficients().extinction();
    let light_intensity = ((medium.scattering + grey) * half_diagonal).min(80.0).exp();
    let tint = Vec3::select(extinction.cmpgt(Vec3::ZERO), (medium.scattering + grey) / extinction, Vec3::ONE);
    [1.0, grey, medium.scattering, medium.asymmetry, light_intensity, tint.x, tint.y, tint.z]
}

/// The coefficients `fog` draws.
fn coefficients_of(fog: &FogVolume) -> FogCoefficients {
    let tint = fog.light_tint.to_linear();
    [fog.density_factor, fog.absorption, fog.scattering, fog.scattering_asymmetry, fog.light_intensity, tint.red, tint.green, tint.blue]
}

/// `fog` drawing `coefficients`; its fog colour and texture stay.
fn set_coefficients(fog: &mut FogVolume, coefficients: FogCoefficients) {
    let [density, absorption, scattering, asymmetry, light_intensity, red, green, blue] = coefficients;
    [fog.density_factor, fog.absorption, fog.scattering, fog.scattering_asymmetry, fog.light_intensity] =
        [density, absorption, scattering, asymmetry, light_intensity];
    fog.light_tint = Color::linear_rgb(red, green, blue);
}

/// The media, with their fog volumes and whether they are invalid.
type Media =
    (Entity, &'static ParticipatingMedium, &'static GlobalTransform, &'static InheritedVisibility, Option<&'static mut FogVolume>, Has<InvalidCausticParams>);

/// Keeps each visible, valid medium's `FogVolume` in step with it, and takes away the
/// plugin's fog where the medium went, turned invalid or is hidden (Bevy's fog draws
/// every `FogVolume`, hidden or not).
fn keep_fog_volumes(
    mut commands: Commands,
    mut media: Query<Media>,
    kept: Query<(), With<MediumFogVolume>>,
    mut removed: RemovedComponents<ParticipatingMedium>,
) {
    for entity in removed.read() {
        if kept.contains(entity)
            && let Ok(mut entity) = commands.get_entity(entity)
        {
            entity.remove::<(FogVolume, MediumFogVolume)>();
        }
    }
    for (entity, medium, transform, visible, fog, invalid) in &mut media {
        if invalid || !visible.get() {
            if kept.contains(entity) {
                commands.entity(entity).remove::<(FogVolume, MediumFogVolume)>();
            }
            continue;
        }
        let coefficients = fog_coefficients(medium, transform);
        match fog {
            Some(mut fog) => {
                if coefficients_of(&fog) != coefficients {
                    set_coefficients(&mut fog, coefficients);
                }
            }
            None => {
                let mut fog = FogVolume::default();
                set_coefficients(&mut fog, coefficients);
                commands.entity(entity).insert((fog, MediumFogVolume));
            }
        }
    }
}

/// While a medium is drawn, gives every 3D camera `VolumetricFog` and every
/// directional light `VolumetricLight` where they have none; takes them back when no
/// medium is left.
fn give_fog_to_views(
    mut commands: Commands,
    media: Query<(), (With<ParticipatingMedium>, With<FogVolume>)>,
    cameras: Query<Entity, (With<Camera3d>, Without<VolumetricFog>)>,
    lights: Query<Entity, (With<DirectionalLight>, Without<VolumetricLight>)>,
    given_fog: Query<Entity, (With<AddedForMedia>, With<VolumetricFog>)>,
    given_light: Query<Entity, (With<AddedForMedia>, With<VolumetricLight>)>,
) {
    if media.is_empty() {
        for entity in &given_fog {
            commands.entity(entity).remove::<(VolumetricFog, AddedForMedia)>();
        }
        for entity in &given_light {
            commands.entity(entity).remove::<(VolumetricLight, AddedForMedia)>();
        }
        return;
    }
    for entity in &cameras {
        commands.entity(entity).insert((medium_fog(), AddedForMedia));
    }
    for entity in &lights {
        commands.entity(entity).insert((VolumetricLight, AddedForMedia));
    }
}

//! Main world: what of Bevy's lights the caustics follow. Directional, point and spot
//! lights cast caustics with their colour, intensity, spot cone and `range` (Bevy's
//! window on the inverse square, `caustics_core::scene::Light::range_attenuation`),
//! and the visibility that hides them. Two things are not followed, and say so once
//! per light: a `RectLight` casts no caustics (area lights are not modelled), and a
//! light's `RenderLayers` do not limit its caustics to the cameras on those layers.

use bevy::camera::visibility::RenderLayers;
use bevy::light::RectLight;
use bevy::platform::collections::HashSet;
use bevy::prelude::*;

use crate::read_scene::AnyLight;

/// Warns once per light about what the caustics do not follow of it.
pub fn warn_unsupported_lights(
    rect_lights: Query<Entity, With<RectLight>>,
    layered: Query<(Entity, &RenderLayers), AnyLight>,
    mut warned: Local<HashSet<Entity>>,
) {
    for entity in &rect_lights {
        if warned.insert(entity) {
            warn!("bevy_caustics: RectLight {entity} casts no caustics: area lights are not supported");
        }
    }
    for (entity, layers) in &layered {
        if *layers != RenderLayers::default() && warned.insert(entity) {
            warn!("bevy_caustics: light {entity} has RenderLayers {layers:?}: its caustics show in every camera, not only those on its layers");
        }
    }
}

//! Quality presets over the techniques' settings: [`CausticQuality`].

use bevy::ecs::component::Mutable;
use bevy::prelude::*;

/// One knob for every technique's cost and accuracy. Insert it as a resource and the
/// plugin sets the fields that trade cost for accuracy in each technique's settings
/// resource (the caustic volumes' shafts, the caustic maps' photon buffer and maps,
/// the illumination textures' planes) whenever it is inserted or changed, leaving
/// their other fields (modes, caches) as they are; a field set by hand afterwards keeps
/// its value until the preset changes again. `Medium` is the settings' defaults.
/// `docs/cli-and-performance.md` ("Quality presets and the plugin's defaults") has
/// each preset's cost and error, measured by `caustics bench --methods presets`. A
/// rippling pool's convolution takes its quality from its own `PoolRipples`
/// (`columns`, `kernel_radius`), which no preset touches.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Reflect)]
#[reflect(Resource)]
pub enum CausticQuality {
    /// About half the GPU memory and work of `Medium`, softer caustics.
    Low,
    /// The settings' defaults.
    #[default]
    Medium,
    /// Finer photon buffers, maps, planes and shaft grids.
    High,
}

impl CausticQuality {
    /// The three presets, cheapest first.
    pub const ALL: [Self; 3] = [Self::Low, Self::Medium, Self::High];

    /// `low`, `medium` or `high`.
    pub fn label(self) -> &'static str {
        match self {
            Self::Low => "low",
            Self::Medium => "medium",
            Self::High => "high",
        }
    }

    /// The value for this preset among `[low, medium, high]`.
    #[cfg(any(feature = "warped-volumes", feature = "illumination-textures", feature = "hierarchical-maps"))]
    pub(crate) fn pick<T>(self, [low, medium, high]: [T; 3]) -> T {
        match self {
            Self::Low => low,
            Self::Medium => medium,
            Self::High => high,
        }
    }
}

/// A technique's settings that [`CausticQuality`] sets.
pub trait QualityPreset: Resource<Mutability = Mutable> + Sized {
    /// Sets the fields that trade cost for accuracy to `quality`'s values.
    fn set_quality(&mut self, quality: CausticQuality);

    /// These settings with `quality`'s values in the fields it sets.
    fn with_quality(mut self, quality: CausticQuality) -> Self {
        self.set_quality(quality);
        self
    }
}

/// Applies [`CausticQuality`] to the settings `S` before the frame's systems read them.
#[cfg(any(feature = "warped-volumes", feature = "illumination-textures", feature = "hierarchical-maps"))]
pub(crate) fn build<S: QualityPreset>(app: &mut App) {
    app.add_systems(PreUpdate, apply::<S>.run_if(resource_exists_and_changed::<CausticQuality>));
}

#[cfg(any(feature = "warped-volumes", feature = "illumination-textures", feature = "hierarchical-maps"))]
fn apply<S: QualityPreset>(quality: Res<CausticQuality>, mut settings: ResMut<S>) {
    settings.set_quality(*quality);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Medium` is each technique's defaults.
    #[test]
    fn medium_is_the_defaults() {
        fn check<S: QualityPreset + Default + PartialEq + std::fmt::Debug>() {
            assert_eq!(S::default().with_quality(CausticQuality::Medium), S::default());
        }
        #[cfg(feature = "warped-volumes")]
        check::<crate::warped_volumes::WarpedVolumesSettings>();
        #[cfg(feature = "hierarchical-maps")]
        check::<crate::hierarchical_maps::HierarchicalMapsSettings>();
        #[cfg(feature = "illumination-textures")]
        {
            use crate::illumination_textures::IlluminationTexturesSettings;
            let (preset, default) = (IlluminationTexturesSettings::default().with_quality(CausticQuality::Medium), IlluminationTexturesSettings::default());
            assert_eq!((preset.planes, preset.texture_size, preset.table_directions), (default.planes, default.texture_size, default.table_directions));
        }
    }

    /// The preset is applied when inserted and when changed, and leaves the other
    /// fields as the game set them.
    #[cfg(feature = "warped-volumes")]
    #[test]
    fn a_preset_sets_its_fields_and_keeps_the_others() {
        use crate::warped_volumes::{VolumeIntensity, WarpedVolumesSettings};
        let mut app = App::new();
        app.insert_resource(WarpedVolumesSettings { intensity: VolumeIntensity::Constant, ..default() });
        build::<WarpedVolumesSettings>(&mut app);
        app.update();
        assert_eq!(app.world().resource::<WarpedVolumesSettings>().shaft_grid, 96, "no preset, no change");
        app.insert_resource(CausticQuality::High);
        app.update();
        let settings = *app.world().resource::<WarpedVolumesSettings>();
        assert_eq!((settings.shaft_grid, settings.shaft_downsample, settings.intensity), (128, 2, VolumeIntensity::Constant));
        // Set by hand, kept while the preset stands.
        app.world_mut().resource_mut::<WarpedVolumesSettings>().shaft_grid = 200;
        app.update();
        assert_eq!(app.world().resource::<WarpedVolumesSettings>().shaft_grid, 200);
        *app.world_mut().resource_mut::<CausticQuality>() = CausticQuality::Low;
        app.update();
        assert_eq!(app.world().resource::<WarpedVolumesSettings>().shaft_grid, 64);
    }
}

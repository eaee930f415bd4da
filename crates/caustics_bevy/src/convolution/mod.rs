//! Pool caustics by convolution (Trendall & Stewart 2000, §4): a rectangular pool whose
//! water ripples where pebbles fall (§4.3).
//!
//! [`PoolRipples`] on an entity makes its mesh the pool's water surface, animated from
//! `caustics_core::convolution::ripples`: every [`DropPebble`] that lands inside the
//! pool starts an impulse, mirrored across the four walls, and faded impulses are
//! removed. While the water moves its mesh changes every frame: with a render app, on
//! the GPU (`water.rs`: the heights from the impulses and the vertices written in
//! Bevy's vertex buffer, no CPU work), unless the pool is a
//! [`crate::CausticGenerator`] whose technique reads its triangles on the CPU (the
//! caustic maps); otherwise the mesh asset is rewritten in place. Either way a
//! generator beside it feeds the other techniques as a dynamic generator (the warped
//! caustic volumes rebuild from it), and still water costs nothing.

mod render;
mod ripples;
mod water;

pub use render::PoolGpu;
pub use ripples::{PoolImpulses, PoolKernels, PoolSurface};

use bevy::prelude::*;
use caustics_core::convolution::ConvolutionSettings;
use caustics_core::convolution::ripples::RippleSettings;
use caustics_core::view::PoolView;

/// A rectangular pool of rippling water, centred on its entity in its xz plane: the
/// surface's rest level is the entity's `y = 0`, and it spans `columns × rows` texels
/// `cell_size` metres wide, over a floor `depth` metres below. The entity's `Mesh3d`
/// becomes a grid with a vertex at each texel centre. The wave fields are
/// `caustics_core::convolution::ripples::RippleSettings`' and the light's
/// `caustics_core::convolution::ConvolutionSettings`' (see there). Invalid settings are
/// reported once and the pool stands still.
///
/// With a `CausticGenerator` that refracts and asks for `CausticTechnique::Convolution`,
/// the brightest visible `DirectionalLight` that shines down on the water makes caustics
/// on the pool floor: irradiance at `y = −depth` under the pool, shown by the
/// `CausticReceiver` lying there.
#[derive(Component, Reflect, Clone, Debug, PartialEq)]
#[reflect(Component)]
#[require(Transform, Visibility)]
#[allow(missing_docs)]
pub struct PoolRipples {
    pub columns: u32,
    pub rows: u32,
    pub cell_size: f32,
    pub wave_number: f32,
    pub angular_frequency: f32,
    pub time_damping: f32,
    pub front_damping: f32,
    pub expiry_height: f32,
    pub depth: f32,
    pub exponent: f32,
    pub extinction: f32,
    pub kernel_radius: u32,
}

impl Default for PoolRipples {
    /// A 4 m × 4 m pool 1 m deep at 128² texels with the core's default waves and light.
    fn default() -> Self {
        let waves = RippleSettings::default();
        let light = ConvolutionSettings::default();
        Self {
            columns: 128,
            rows: 128,
            cell_size: 4.0 / 128.0,
            wave_number: waves.wave_number,
            angular_frequency: waves.angular_frequency,
            time_damping: waves.time_damping,
            front_damping: waves.front_damping,
            expiry_height: waves.expiry_height,
            depth: light.depth,
            exponent: light.exponent,
            extinction: light.extinction,
            kernel_radius: light.kernel_radius as u32,
        }
    }
}

impl PoolRipples {
    /// The core crate's wave settings.
    pub fn waves(&self) -> RippleSettings {
        RippleSettings {
            wave_number: self.wave_number,
            angular_frequency: self.angular_frequency,
            time_damping: self.time_damping,
            front_damping: self.front_damping,
            expiry_height: self.expiry_height,
        }
    }

    /// The core crate's light settings, with the water's index of refraction and the
    /// sunlight (direction in pool space, irradiance).
    pub fn light(&self, ior: f32, sun_direction: Vec3, sun_irradiance: f32) -> ConvolutionSettings {
        ConvolutionSettings {
            ior,
            sun_direction: caustics_core::glam::Vec3::from_array(sun_direction.to_array()),
            sun_irradiance,
            depth: self.depth,
            exponent: self.exponent,
            extinction: self.extinction,
            kernel_radius: self.kernel_radius as usize,
            ..ConvolutionSettings::default()
        }
    }

    /// The pool as a saved frame keeps it, `generator` its water's index in the
    /// frame's scene: these settings, placed by `transform`, with `surface`'s live
    /// impulses as of `time` on the pool's clock.
    pub fn to_view(&self, generator: usize, transform: &GlobalTransform, surface: &PoolSurface, time: f32) -> PoolView {
        PoolView {
            generator,
            transform: crate::read_scene::to_core_affine(&transform.affine()),
            columns: self.columns,
            rows: self.rows,
            cell_size: self.cell_size,
            waves: self.waves(),
            depth: self.depth,
            exponent: self.exponent,
            extinction: self.extinction,
            kernel_radius: self.kernel_radius,
            impulses: surface.ripples().impulses().to_vec(),
            time,
        }
    }

    /// The settings of a saved frame's pool.
    pub fn from_view(view: &PoolView) -> Self {
        let w = &view.waves;
        Self {
            columns: view.columns,
            rows: view.rows,
            cell_size: view.cell_size,
            wave_number: w.wave_number,
            angular_frequency: w.angular_frequency,
            time_damping: w.time_damping,
            front_damping: w.front_damping,
            expiry_height: w.expiry_height,
            depth: view.depth,
            exponent: view.exponent,
            extinction: view.extinction,
            kernel_radius: view.kernel_radius,
        }
    }

    /// The pool's width (x) and length (z) in metres.
    pub fn size(&self) -> Vec2 {
        Vec2::new(self.columns as f32, self.rows as f32) * self.cell_size
    }

    /// These settings with a grid that fits one storage binding of `largest_binding`
    /// bytes and a budget of `budget` bytes: the texels' buffers (four terms in one
    /// binding; with the height, the irradiance and the water's mesh, [`BYTES_PER_TEXEL`])
    /// and the kernels' taps (64 bytes each, one binding). While they do not fit, texels
    /// twice as wide (half as many along each side, a side with an odd count gaining
    /// half a texel at its far edge) keep the lobe in metres with half the kernel
    /// radius; a kernel too wide alone gets a smaller radius.
    pub fn fitted(&self, largest_binding: u64, budget: u64) -> Self {
        let mut fitted = self.clone();
        let texels = |p: &Self| u64::from(p.columns) * u64::from(p.rows);
        let taps = |p: &Self| (2 * u64::from(p.kernel_radius) + 1).pow(2) * 64;
        while texels(&fitted) > 1 && (texels(&fitted) * 16 > largest_binding || texels(&fitted) * BYTES_PER_TEXEL + taps(&fitted) > budget) {
            fitted.columns = fitted.columns.div_ceil(2);
            fitted.rows = fitted.rows.div_ceil(2);
            fitted.cell_size *= 2.0;
            fitted.kernel_radius = fitted.kernel_radius.div_ceil(2);
        }
        while fitted.kernel_radius > 0 && taps(&fitted) > largest_binding.min(budget) {
            fitted.kernel_radius /= 2;
        }
        fitted
    }
}

/// The bytes a pool takes per texel: on the GPU its height, four convolution terms and
/// floor irradiance (24), and its water's grid mesh (position, normal, UV and six
/// indices: 56).
pub const BYTES_PER_TEXEL: u64 = 24 + 56;

/// Drops a pebble: a new ripple impulse (§4.3) in the pool whose water lies under
/// `position` (world space; its height does not matter), `strength` metres high at
/// its start (negative inverts the wave). A pebble outside every pool is ignored.
#[derive(Message, Clone, Copy, Debug, PartialEq)]
pub struct DropPebble {
    /// Where it falls, in world space: the pool whose water lies under it gets the ripple.
    pub position: Vec3,
    /// The wave's height at its start, in metres; negative starts with a trough.
    pub strength: f32,
}

/// Animates every [`PoolRipples`]. `CausticsPlugin` adds it with the passes; it also
/// works on its own.
pub struct PoolRipplesPlugin;

impl Plugin for PoolRipplesPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<PoolRipples>().add_message::<DropPebble>().init_resource::<crate::CausticGpuBudget>();
        ripples::build(app);
        if app.get_sub_app(bevy::render::RenderApp).is_some() {
            app.insert_resource(ripples::WaterOnGpu);
            crate::mesh_vertices::build(app);
            water::build(app);
        }
    }
}

pub(crate) fn build(app: &mut App) {
    app.add_plugins(PoolRipplesPlugin);
    render::build(app);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pool_too_large_for_the_gpu_or_the_budget_runs_on_wider_texels() {
        const MIB: u64 = 1 << 20;
        let pool = PoolRipples::default();
        assert_eq!(pool.fitted(128 * MIB, 1 << 30), pool, "the default pool fits as asked");

        // 8192² texels: 1 GiB of terms in one binding, 5 GiB in all.
        let huge = PoolRipples { columns: 8192, rows: 6000, cell_size: 4.0 / 8192.0, kernel_radius: 8, ..default() };
        let fitted = huge.fitted(128 * MIB, 1 << 30);
        let texels = u64::from(fitted.columns) * u64::from(fitted.rows);
        assert_eq!((fitted.columns, fitted.rows, fitted.kernel_radius), (2048, 1500, 2));
        assert!(texels * 16 <= 128 * MIB && texels * BYTES_PER_TEXEL <= 1 << 30);
        // The same pool, the same lobe in metres.
        assert!((fitted.size() - huge.size()).abs().max_element() < 1e-6);
        assert_eq!(fitted.cell_size * fitted.kernel_radius as f32, huge.cell_size * huge.kernel_radius as f32);

        // A kernel of radius 2048 alone takes 1 GiB of taps.
        let wide = PoolRipples { kernel_radius: 2048, ..default() }.fitted(128 * MIB, 1 << 30);
        assert!((2 * u64::from(wide.kernel_radius) + 1).pow(2) * 64 <= 128 * MIB, "radius {}", wide.kernel_radius);

        // An odd side gains half a texel at its far edge.
        let odd = PoolRipples { columns: 129, rows: 128, ..default() }.fitted(u64::MAX, 128 * 128 * BYTES_PER_TEXEL);
        assert_eq!((odd.columns, odd.rows), (65, 64));
    }
}

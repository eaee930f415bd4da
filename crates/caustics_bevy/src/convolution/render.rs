//! Render world: extraction, GPU buffers, the compute passes of the convolution and
//! the projection of the floor irradiance into each view's caustic irradiance buffer.

use super::{PoolRipples, PoolSurface};
use crate::CausticTechnique;
use crate::components::{CausticGenerator, GeneratorInteraction, InvalidCausticParams};
use crate::cpu_time::timed;
use crate::gpu_work::anchor_first_timestamp;
use crate::irradiance::kept_bind_group::{KeptBindGroup, KeptLayout, ViewBindGroups, write_changed};
use crate::irradiance::{ActiveCausticTechniques, ProjectionContext, ProjectionView};
use crate::report::PassRecorder;
use crate::technique::CausticTechniqueChoice;
use bevy::core_pipeline::schedule::{Core3d, camera_driver};
use bevy::core_pipeline::{Core3dSystems, FullscreenShader};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::{
    Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems,
    diagnostic::RecordDiagnostics,
    render_resource::{
        binding_types::{storage_buffer, storage_buffer_read_only, texture_depth_2d, texture_depth_2d_multisampled, uniform_buffer},
        *,
    },
    renderer::{RenderContext, RenderDevice, RenderGraph, RenderGraphSystems, RenderQueue, ViewQuery},
    sync_world::MainEntity,
    view::ViewUniform,
};
use std::sync::Arc;

/// `Pool` in `types.wgsl`.
#[derive(Clone, Copy, Default, PartialEq, ShaderType)]
pub(super) struct GpuPool {
    pub columns: u32,
    pub rows: u32,
    cell_size: f32,
    wave_number: f32,
    angular_frequency: f32,
    time_damping: f32,
    front_damping: f32,
    ior: f32,
    normaliser: f32,
    sun: Vec4,
    lobe_first: Vec4,
    lobe_second: Vec4,
    lobe_axis: Vec4,
    kernel_radius: i32,
    depth: f32,
    floor_tolerance: f32,
    pool_from_world: Mat4,
    color: Vec4,
    pub vertex: UVec4,
}

impl GpuPool {
    /// The pool's texels and its water's wave settings (§4.3), the rest zero: what
    /// `ripple_heights` reads beside the [`GpuWaves`].
    pub(super) fn waves(surface: &PoolSurface) -> Self {
        let (pool, waves) = (surface.settings(), surface.ripples().settings());
        Self {
            columns: pool.columns,
            rows: pool.rows,
            cell_size: pool.cell_size,
            wave_number: waves.wave_number,
            angular_frequency: waves.angular_frequency,
            time_damping: waves.time_damping,
            front_damping: waves.front_damping,
            ..default()
        }
    }
}

/// The water's waves at a time, as `ripple_heights` reads them (`Waves` in
/// `types.wgsl`): the one buffer of a pool written every frame its water moves, the
/// [`GpuPool`] only when the pool changes.
#[derive(ShaderType, Clone, Default, PartialEq)]
pub(super) struct GpuWaves {
    /// The pool's clock (s); zero for still water, whose heights do not depend on it.
    time: f32,
    /// Live impulses.
    impulse_count: u32,
    /// Every live impulse: x, z, strength, drop time; then zeros to a power of two (one
    /// at least, as a binding may not be empty). The shader adds each one's nine wall
    /// images (§4.3).
    #[shader(size(runtime))]
    impulses: Vec<Vec4>,
}

impl GpuWaves {
    /// Whether no impulse is live.
    pub(super) fn still(&self) -> bool {
        self.impulse_count == 0
    }
}

/// `surface`'s waves at `time` (s).
pub(super) fn ripple_waves(surface: &PoolSurface, time: f32) -> GpuWaves {
    let live = surface.ripples().impulses();
    // Room to the next power of two (one impulse at least, as a binding may not be
    // empty), so that a pool's buffer grows a few times as the live impulses add up,
    // not at every new one.
    let room = live.len().max(1).next_power_of_two();
    let mut impulses = Vec::with_capacity(room);
    impulses.extend(live.iter().map(|i| Vec4::new(i.position.x, i.position.y, i.strength, i.time)));
    let count = impulses.len() as u32;
    impulses.resize(room, Vec4::ZERO);
    GpuWaves { time: if count == 0 { 0.0 } else { time }, impulse_count: count, impulses }
}

/// Render world: one pool to draw this frame.
struct ExtractedPool {
    uniform: GpuPool,
    waves: GpuWaves,
    taps: Arc<Vec<Vec4>>,
}

/// Render world: the pools of this frame, by main-world entity.
#[derive(Resource, Default)]
struct ExtractedPools(HashMap<MainEntity, ExtractedPool>);

/// Render world: a pool's buffers on the GPU and the bind groups over them.
struct PoolBuffers {
    texels: u32,
    uniform: UniformBuffer<GpuPool>,
    waves: StorageBuffer<GpuWaves>,
    taps: StorageBuffer<Vec<Vec4>>,
    /// The kernels `taps` holds, so that unchanged ones are not written again.
    taps_written: Option<Arc<Vec<Vec4>>>,
    heights: Buffer,
    terms: Buffer,
    irradiance: Buffer,
    /// The compute passes' bind group, kept while it binds the same buffers.
    compute: KeptBindGroup,
    /// The projection's bind group for each view.
    projections: ViewBindGroups,
    /// Whether the compute passes run this frame: not while the water stays still and
    /// `still` already holds its floor.
    computes: bool,
    /// The still pool (its clock left out) whose floor `irradiance` holds, if any.
    still: Option<GpuPool>,
}

impl PoolBuffers {
    fn new(device: &RenderDevice, texels: u32) -> Self {
        Self {
            texels,
            uniform: UniformBuffer::default(),
            waves: StorageBuffer::default(),
            taps: StorageBuffer::default(),
            taps_written: None,
            heights: texel_buffer(device, "caustic_pool_heights", texels, 1),
            terms: texel_buffer(device, "caustic_pool_terms", texels, 4),
            irradiance: texel_buffer(device, "caustic_pool_floor_irradiance", texels, 1),
            compute: KeptBindGroup::default(),
            projections: ViewBindGroups::default(),
            computes: true,
            still: None,
        }
    }
}

/// Render world: every pool's buffers on the GPU.
#[derive(Resource, Default)]
pub struct PoolGpu(HashMap<MainEntity, PoolBuffers>);

impl PoolGpu {
    /// The heights the GPU computed for the pool on main-world entity `pool` in the last
    /// frame, one `f32` per texel, row-major (copyable: `COPY_SRC`).
    pub fn heights(&self, pool: Entity) -> Option<&Buffer> {
        self.0.get(&MainEntity::from(pool)).map(|buffers| &buffers.heights)
    }
}

/// The compute pipelines and the projection's layouts and shader.
#[derive(Resource)]
pub(super) struct ConvolutionPipelines {
    compute_layout: KeptLayout,
    /// `ripple_heights`, `convolution_terms`, `convolve`, `deficit_ratios`, `lift`.
    compute: [CachedComputePipelineId; 5],
    /// The empty `anchor` of [`anchor_first_timestamp`], under the same layout.
    anchor: CachedComputePipelineId,
    project_layouts: [KeptLayout; 2],
    project_shader: Handle<Shader>,
    fullscreen: FullscreenShader,
}

pub(super) fn build(app: &mut App) {
    bevy::asset::embedded_asset!(app, "convolution.wgsl");
    bevy::asset::embedded_asset!(app, "project.wgsl");
    bevy::shader::load_shader_library!(app, "types.wgsl");
    let cpu = crate::CausticCpuTime::of(app);
    app.add_systems(PostUpdate, (timed(&cpu.main, mark_active), timed(&cpu.main, aim_kernels).after(bevy::transform::TransformSystems::Propagate)));
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedPools>()
        .init_resource::<PoolGpu>()
        .init_resource::<SpecializedRenderPipelines<ConvolutionPipelines>>()
        .add_systems(RenderStartup, init_pipelines)
        .add_systems(ExtractSchedule, timed(&cpu.render, extract_pools))
        .add_systems(
            Render,
            (
                timed(&cpu.render, prepare_buffers)
                    .run_if(|extracted: Res<ExtractedPools>, gpu: Res<PoolGpu>| !extracted.0.is_empty() || !gpu.0.is_empty())
                    .in_set(RenderSystems::PrepareResources),
                timed(&cpu.render, crate::irradiance::prepare_projection_pipelines::<ConvolutionPipelines>).run_if(pools_on_gpu).in_set(RenderSystems::Prepare),
            ),
        )
        .add_systems(RenderGraph, timed(&cpu.render, compute_floor_irradiance).run_if(pools_on_gpu).in_set(RenderGraphSystems::Render).before(camera_driver))
        .add_systems(
            Core3d,
            timed(&cpu.render, project_floor_irradiance)
                .run_if(pools_on_gpu)
                .after(crate::irradiance::inject_irradiance)
                .after(Core3dSystems::Prepass)
                .before(Core3dSystems::MainPass),
        );
}

/// Whether any pool's floor is drawn on the GPU: else the convolution's passes are
/// left out of the frame.
fn pools_on_gpu(gpu: Res<PoolGpu>) -> bool {
    !gpu.0.is_empty()
}

/// A pool's generator and the technique it got.
type PoolGenerator = (&'static CausticGenerator, &'static CausticTechniqueChoice);

/// The pools whose water refracts sunlight by this technique.
type ConvolutionPools = Query<'static, 'static, (Entity, &'static PoolSurface, PoolGenerator, &'static GlobalTransform), Without<InvalidCausticParams>>;

/// The pools whose kernels [`aim_kernels`] aims.
type AimedPools<'w, 's> = Query<'w, 's, (Entity, &'static mut PoolSurface, PoolGenerator, &'static GlobalTransform), Without<InvalidCausticParams>>;

/// The directional lights a pool may refract.
type Suns = Query<'static, 'static, SunComponents>;
type SunComponents = (&'static DirectionalLight, &'static GlobalTransform, &'static InheritedVisibility);

fn uses_convolution((generator, choice): (&CausticGenerator, &CausticTechniqueChoice)) -> Option<f32> {
    match (choice.technique(), generator.interaction) {
        (CausticTechnique::Convolution, GeneratorInteraction::Refract { ior, .. }) => Some(ior),
        _ => None,
    }
}

/// The pool space (x, z from 0 to the pool's size, the rest surface at y = 0) of a pool
/// from world space.
fn pool_from_world(pool: &PoolRipples, transform: &GlobalTransform) -> Mat4 {
    let size = pool.size();
    Mat4::from_translation(Vec3::new(0.5 * size.x, 0.0, 0.5 * size.y)) * transform.to_matrix().inverse()
}

/// The sunlight a pool refracts: the brightest visible directional light that shines
/// down onto its water, and its direction of travel in pool space. A sun below the
/// horizon or hidden lights nothing, however bright.
fn pool_sun<'a>(
    pool_from_world: &Mat4,
    suns: impl Iterator<Item = (&'a DirectionalLight, &'a GlobalTransform, &'a InheritedVisibility)>,
) -> Option<(&'a DirectionalLight, Vec3)> {
    suns.filter(|(.., visible)| visible.get())
        .map(|(sun, t, _)| (sun, pool_from_world.transform_vector3(crate::read_scene::facing(t)).normalize_or_zero()))
        .filter(|(_, direction)| direction.y < 0.0)
        .max_by(|a, b| a.0.illuminance.total_cmp(&b.0.illuminance))
}

/// Main world: aims each pool's kernels at the sunlight it refracts (the lobe is
/// expanded about it); only a change of light, index or pool orientation redraws them.
fn aim_kernels(mut pools: AimedPools, suns: Query<SunComponents>) {
    for (entity, mut surface, generator, transform) in &mut pools {
        let Some(ior) = uses_convolution(generator) else { continue };
        let Some((_, direction)) = pool_sun(&pool_from_world(surface.settings(), transform), suns.iter()) else { continue };
        if let Err(e) = surface.bypass_change_detection().aim_kernels(ior, direction) {
            warn!("bevy_caustics: the pool {entity} keeps its kernels: {e}");
        }
    }
}

/// Main world: the views have convolution work while a pool refracts a sun.
fn mark_active(
    mut active: ResMut<ActiveCausticTechniques>,
    pools: Query<PoolGenerator, (With<PoolSurface>, Without<InvalidCausticParams>)>,
    suns: Query<(), With<DirectionalLight>>,
) {
    let any = !suns.is_empty() && pools.iter().any(|generator| uses_convolution(generator).is_some());
    active.set_if_neq(ActiveCausticTechniques { convolution: any, ..*active });
}

fn extract_pools(mut extracted: ResMut<ExtractedPools>, pools: Extract<ConvolutionPools>, suns: Extract<Suns>, time: Extract<Res<Time>>) {
    extracted.0.clear();
    for (entity, surface, generator, transform) in &pools {
        let Some(ior) = uses_convolution(generator) else { continue };
        let pool = surface.settings();
        let pool_from_world = pool_from_world(pool, transform);
        let Some((sun, direction)) = pool_sun(&pool_from_world, suns.iter()) else { continue };
        // Kernels aimed at other light (the frame before the light moved) wait a frame.
        if surface.kernels().aimed != (ior, direction) {
            continue;
        }
        let kernels = surface.kernels();
        let color = sun.color.to_linear();
        let uniform = GpuPool {
            ior,
            normaliser: kernels.normaliser as f32,
            sun: direction.extend(sun.illuminance),
            lobe_first: kernels.frame[0].extend(0.0),
            lobe_second: kernels.frame[1].extend(0.0),
            lobe_axis: kernels.frame[2].extend(0.0),
            kernel_radius: pool.kernel_radius as i32,
            depth: pool.depth,
            floor_tolerance: 0.05 * pool.depth,
            pool_from_world,
            color: Vec4::new(color.red, color.green, color.blue, 1.0),
            ..GpuPool::waves(surface)
        };
        let waves = ripple_waves(surface, time.elapsed_secs());
        extracted.0.insert(MainEntity::from(entity), ExtractedPool { uniform, waves, taps: kernels.taps.clone() });
    }
}

/// Writes a pool's uniform and its waves ([`ripple_waves`]) to the GPU where they
/// changed: a write costs a staging buffer, tens of µs of CPU.
pub(super) fn write_waves(
    (uniform, waves): (&mut UniformBuffer<GpuPool>, &mut StorageBuffer<GpuWaves>),
    (pool, now): (GpuPool, GpuWaves),
    (device, queue): (&RenderDevice, &RenderQueue),
) {
    uniform.set_label(Some("caustic_pool_settings"));
    write_changed(uniform, pool, device, queue);
    if waves.buffer().is_none() || *waves.get() != now {
        waves.set(now);
        waves.set_label(Some("caustic_pool_waves"));
        waves.write_buffer(device, queue);
    }
}

/// A storage buffer of `floats_per_texel` floats per texel, written by the compute
/// passes (and copyable, so that applications and tests can read it back).
pub(super) fn texel_buffer(device: &RenderDevice, label: &'static str, count: u32, floats_per_texel: u64) -> Buffer {
    device.create_buffer(&BufferDescriptor {
        label: Some(label),
        size: count.max(1) as u64 * floats_per_texel * 4,
        usage: BufferUsages::STORAGE | BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

fn prepare_buffers(
    mut extracted: ResMut<ExtractedPools>,
    mut gpu: ResMut<PoolGpu>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    pipelines: Res<ConvolutionPipelines>,
    cache: Res<PipelineCache>,
) {
    gpu.0.retain(|entity, _| extracted.0.contains_key(entity));
    for (entity, pool) in &mut extracted.0 {
        let texels = pool.uniform.columns * pool.uniform.rows;
        let buffers = gpu.0.entry(*entity).or_insert_with(|| PoolBuffers::new(&device, texels));
        if buffers.texels != texels {
            *buffers = PoolBuffers::new(&device, texels);
        }
        // Still water under the same light and kernels: the floor already computed.
        let still = pool.waves.still().then_some(pool.uniform);
        let same_taps = buffers.taps_written.as_ref().is_some_and(|written| Arc::ptr_eq(written, &pool.taps));
        buffers.computes = still.is_none() || buffers.still != still || !same_taps;
        buffers.still = None;
        write_waves((&mut buffers.uniform, &mut buffers.waves), (pool.uniform, std::mem::take(&mut pool.waves)), (&device, &queue));
        if !same_taps {
            buffers.taps.set(pool.taps.as_ref().clone());
            buffers.taps.set_label(Some("caustic_pool_kernel_taps"));
            buffers.taps.write_buffer(&device, &queue);
            buffers.taps_written = Some(pool.taps.clone());
        }
        let (Some(uniform), Some(images), Some(taps)) = (buffers.uniform.buffer(), buffers.waves.buffer(), buffers.taps.buffer()) else {
            continue;
        };
        let layout = pipelines.compute_layout.get(&cache);
        let (heights, terms, irradiance) = (&buffers.heights, &buffers.terms, &buffers.irradiance);
        buffers.compute.get(&[layout.into(), uniform.into(), images.into(), taps.into()], || {
            device.create_bind_group(
                "pool_convolution_bind_group",
                layout,
                &BindGroupEntries::sequential((
                    uniform.as_entire_binding(),
                    images.as_entire_binding(),
                    taps.as_entire_binding(),
                    heights.as_entire_binding(),
                    terms.as_entire_binding(),
                    irradiance.as_entire_binding(),
                )),
            )
        });
        // The compute node runs this frame's passes once every kernel is ready.
        if pipelines.compute.iter().all(|&id| cache.get_compute_pipeline(id).is_some()) {
            buffers.still = still;
        }
    }
}

fn init_pipelines(mut commands: Commands, asset_server: Res<AssetServer>, cache: Res<PipelineCache>, fullscreen: Res<FullscreenShader>) {
    let compute_layout = BindGroupLayoutDescriptor::new(
        "pool_convolution_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                uniform_buffer::<GpuPool>(false),
                storage_buffer_read_only::<GpuWaves>(false),
                storage_buffer_read_only::<Vec4>(false),
                storage_buffer::<f32>(false),
                storage_buffer::<Vec4>(false),
                storage_buffer::<f32>(false),
            ),
        ),
    );
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "convolution.wgsl");
    let kernels = ["ripple_heights", "convolution_terms", "convolve", "deficit_ratios", "lift"];
    let compute = crate::irradiance::compute_pipelines(&cache, "pool", &compute_layout, &shader, kernels);
    let [anchor] = crate::irradiance::compute_pipelines(&cache, "pool", &compute_layout, &shader, ["anchor"]);
    let project_layout = |multisampled: bool| {
        BindGroupLayoutDescriptor::new(
            if multisampled { "pool_project_layout_msaa" } else { "pool_project_layout" },
            &BindGroupLayoutEntries::sequential(
                ShaderStages::FRAGMENT,
                (
                    uniform_buffer::<ViewUniform>(true),
                    if multisampled { texture_depth_2d_multisampled() } else { texture_depth_2d() },
                    uniform_buffer::<GpuPool>(false),
                    storage_buffer_read_only::<f32>(false),
                ),
            ),
        )
    };
    commands.insert_resource(ConvolutionPipelines {
        compute_layout: KeptLayout::new(compute_layout),
        compute,
        anchor,
        project_layouts: [project_layout(false), project_layout(true)].map(KeptLayout::new),
        project_shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "project.wgsl"),
        fullscreen: fullscreen.clone(),
    });
}

impl SpecializedRenderPipeline for ConvolutionPipelines {
    /// Whether the depth prepass is multisampled.
    type Key = bool;

    fn specialize(&self, multisampled: bool) -> RenderPipelineDescriptor {
        crate::irradiance::projection_pipeline(
            "pool_project_pipeline",
            &self.project_layouts[multisampled as usize].descriptor,
            &self.project_shader,
            &self.fullscreen,
            multisampled,
        )
    }
}

/// Once per frame: every pool's heights, per-texel terms and floor irradiance, lifted
/// to non-negative (`lift_negative_irradiance`); none for water that stays still
/// (`PoolBuffers::computes`).
fn compute_floor_irradiance(
    mut ctx: RenderContext,
    gpu: Res<PoolGpu>,
    pipelines: Res<ConvolutionPipelines>,
    cache: Res<PipelineCache>,
    recorder: Res<PassRecorder>,
) {
    let Some(kernels) = pipelines.compute.map(|id| cache.get_compute_pipeline(id)).into_iter().collect::<Option<Vec<_>>>() else {
        return;
    };
    let pools: Vec<_> =
        gpu.0.values().filter(|buffers| buffers.computes).filter_map(|buffers| Some((buffers.compute.current()?, buffers.uniform.get()))).collect();
    // No pools: no pass (and no span in the GPU timings).
    if pools.is_empty() {
        return;
    }
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let mut pass = ctx.command_encoder().begin_compute_pass(&ComputePassDescriptor { label: Some("pool_convolution"), ..default() });
    let span = diagnostics.pass_span(&mut pass, "caustics/convolution");
    pass.set_bind_group(0, pools[0].0, &[]);
    anchor_first_timestamp(&mut pass, diagnostics.is_some(), cache.get_compute_pipeline(pipelines.anchor));
    for (bind_group, uniform) in pools {
        pass.set_bind_group(0, bind_group, &[]);
        for pipeline in &kernels {
            pass.set_pipeline(pipeline);
            pass.dispatch_workgroups(uniform.columns.div_ceil(8), uniform.rows.div_ceil(8), 1);
        }
        recorder.record("convolution");
    }
    span.end(&mut pass);
}

/// Adds each pool's floor irradiance where the view sees its floor.
fn project_floor_irradiance(
    view: ViewQuery<ProjectionView<ConvolutionPipelines>>,
    mut gpu: ResMut<PoolGpu>,
    pipelines: Res<ConvolutionPipelines>,
    projection: ProjectionContext<ConvolutionPipelines>,
    mut ctx: RenderContext,
) {
    let entity = view.entity();
    let (buffer, prepass, offset, pipeline) = view.into_inner();
    let Some(inputs) = projection.inputs(pipeline, prepass, &pipelines.project_layouts) else { return };
    let device = ctx.render_device().clone();
    let bind_groups: Vec<BindGroup> = gpu
        .0
        .values_mut()
        .filter_map(|buffers| {
            let (uniform, binding) = (buffers.uniform.buffer()?, buffers.uniform.binding()?);
            let source = [uniform.into(), (&buffers.irradiance).into()];
            Some(inputs.bind_group(&mut buffers.projections, (entity, |e| projection.exists(e)), &source, || {
                device.create_bind_group(
                    "pool_project_bind_group",
                    inputs.layout,
                    &BindGroupEntries::sequential((inputs.view.clone(), inputs.depth, binding, buffers.irradiance.as_entire_binding())),
                )
            }))
        })
        .collect();
    buffer.project(&mut ctx, inputs.pipeline, &bind_groups, offset.offset, ("pool_floor", "caustics/pool_floor", "pool floor"), &projection.recorder);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pool_refracts_the_brightest_sun_that_shines_down_on_it() {
        let sun = |illuminance: f32, direction: Vec3, visible: bool| {
            let transform = GlobalTransform::from(Transform::default().looking_to(direction, Vec3::Y));
            let visibility = if visible { InheritedVisibility::VISIBLE } else { InheritedVisibility::HIDDEN };
            (DirectionalLight { illuminance, ..default() }, transform, visibility)
        };
        let suns = [
            sun(100_000.0, Vec3::new(0.2, 1.0, 0.0), true),  // brightest, below the horizon
            sun(50_000.0, Vec3::new(0.0, -1.0, 0.3), false), // hidden
            sun(2_000.0, Vec3::new(0.3, -1.0, 0.0), true),
            sun(1_000.0, Vec3::NEG_Y, true),
        ];
        let lit = |pool_from_world: Mat4| pool_sun(&pool_from_world, suns.iter().map(|(l, t, v)| (l, t, v))).map(|(l, d)| (l.illuminance, d));
        let (illuminance, direction) = lit(Mat4::IDENTITY).unwrap();
        assert_eq!(illuminance, 2_000.0);
        assert!(direction.abs_diff_eq(Vec3::new(0.3, -1.0, 0.0).normalize(), 1e-5));
        // A pool turned upside down sees the first sun from above.
        assert_eq!(lit(Mat4::from_rotation_x(std::f32::consts::PI)).unwrap().0, 100_000.0);
        assert!(pool_sun(&Mat4::IDENTITY, std::iter::empty()).is_none());
    }
}

//! Render world: extraction of the plan, and the GPU buffers, pipelines and bind groups
//! the passes (`pass.rs`) draw with.

use super::plan::{CausticMapInstance, CausticMapPlan, PlannedLightView};
use crate::cpu_time::timed;
use crate::gpu_budget::{CausticGpuBudget, largest_binding, mib};
use crate::irradiance::kept_bind_group::{Bound, KeptBindGroup, KeptLayout, ViewBindGroups};
use crate::irradiance::mesh_bvhs::InstancedBvhBuffer;
use bevy::core_pipeline::schedule::{Core3d, camera_driver};
use bevy::core_pipeline::{Core3dSystems, FullscreenShader};
use bevy::material::specialize::SpecializedMeshPipelineError;
use bevy::mesh::{MeshVertexBufferLayoutRef, PrimitiveTopology};
use bevy::prelude::*;
use bevy::render::{
    Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems,
    mesh::RenderMesh,
    render_asset::RenderAssets,
    render_resource::{
        binding_types::{
            storage_buffer, storage_buffer_read_only, texture_2d, texture_2d_multisampled, texture_depth_2d, texture_depth_2d_multisampled, uniform_buffer,
        },
        *,
    },
    renderer::{RenderDevice, RenderGraph, RenderGraphSystems, RenderQueue},
    view::ViewUniform,
};
use caustics_core::hierarchical::hierarchy::start_level;
use caustics_core::hierarchical::{CausticMapSettings, Clustering, Gather, LevelOverflow, PhotonPaths, Projection, Splats};
use caustics_core::triangle_bvh::InstancedBvh;

/// `LightView` in `types.wgsl`.
#[derive(Clone, Copy, Default, ShaderType)]
pub(super) struct GpuLightView {
    clip_from_world: Mat4,
    origin: Vec4,
    right: Vec4,
    up: Vec4,
    forward: Vec4,
    spot: Vec4,
    color: Vec4,
    far: f32,
    spot_scale: f32,
    photon_resolution: u32,
    map_resolution: u32,
    photon_levels: u32,
    start_level: u32,
    clustering: u32,
    variable_splats: u32,
    fixed_diameter: f32,
    top_level: u32,
    discard_above_top: u32,
    exit_iterations: u32,
    pyramid_offsets: [UVec4; 3],
    level_offsets: [UVec4; 3],
    materials: [Vec4; 16],
    /// `DRAWN_HERE` and `ONE_SIDED` bits per generator, four to a vector.
    material_flags: [UVec4; 16],
    material_count: u32,
    /// 1/range² of a point or spot light, 0 without a range.
    inverse_range_squared: f32,
    traced_paths: u32,
    path_epsilon: f32,
    /// Where the BVH's instances start in its buffer (vec4s), 0 without a BVH.
    bvh_instances: u32,
    emission: f32,
}

/// `DRAWN_HERE` and `ONE_SIDED` in `types.wgsl`.
const DRAWN_HERE: u32 = 1;
const ONE_SIDED: u32 = 2;

/// The most generators the caustic maps draw (their indices of refraction live in the
/// light view's uniform).
pub const MAX_GENERATORS: usize = 64;

/// `Step` in `caustic_map.wgsl`.
#[derive(Clone, Copy, Default, ShaderType)]
struct GpuStep {
    level: u32,
    source: u32,
    destination: u32,
    args_slot: u32,
    fixed_count: u32,
    counter_base: u32,
    branch: u32,
}

/// `Instance` in `maps.wgsl`.
#[derive(Clone, Copy, Default, ShaderType)]
struct GpuInstance {
    world_from_local: Mat4,
    normal_from_local: Mat4,
    material: UVec4,
}

/// The lists a step reads (`Step::source`): the traversal's two, the gathered one, all nodes.
const LIST_GATHERED: u32 = 2;
const ALL_NODES: u32 = 3;
/// No list to clear (`Step::destination`).
const NO_TARGET: u32 = 9;
/// Counters per light view: three list lengths, clusters, nodes processed at 13 levels,
/// padding.
pub const COUNTERS_PER_VIEW: u32 = 20;
/// Index of the first "nodes processed" counter.
pub const PROCESSED_COUNTER: u32 = 4;

fn to_vec3(v: caustics_core::glam::Vec3) -> Vec3 {
    Vec3::from_array(v.to_array())
}

/// Word offsets of `count` levels of sizes `size(level)` from `first`, packed four to a `UVec4`.
fn packed_offsets(first: u32, count: u32, size: impl Fn(u32) -> u32) -> ([UVec4; 3], u32) {
    let mut offsets = [0u32; 12];
    let mut total = 0;
    for (i, level) in (first..first + count).enumerate() {
        offsets[i.min(11)] = total;
        total += size(level);
    }
    let packed = std::array::from_fn(|i| UVec4::from_slice(&offsets[4 * i..4 * i + 4]));
    (packed, total)
}

/// The map's top level for `settings` (0 for fixed splats).
fn top_level(settings: &CausticMapSettings) -> u32 {
    match settings.splats {
        Splats::Fixed { .. } => 0,
        Splats::Variable { max_level, .. } => max_level.min(settings.map_resolution.ilog2()),
    }
}

impl GpuLightView {
    fn new(planned: &PlannedLightView, settings: &CausticMapSettings, generators: &[CausticMapInstance], bvh: Option<&InstancedBvh>) -> (Self, u32, u32) {
        let v = &planned.view;
        let half = v.half_extent();
        let p = settings.photon_resolution;
        let m = settings.map_resolution;
        let levels = p.ilog2();
        let (pyramid_offsets, pyramid_nodes) = packed_offsets(1, levels, |k| (p >> k) * (p >> k));
        let top = top_level(settings);
        let (level_offsets, map_texels) = packed_offsets(0, top + 1, |l| (m >> l).max(1).pow(2));
        let (clustering, start) = match settings.gather {
            Gather::Flat => (0, 0),
            Gather::Hierarchical { clustering } => (
                match clustering {
                    Clustering::Off => 0,
                    Clustering::LastLevel => 1,
                    Clustering::AllLevels => 2,
                },
                start_level(p, caustics_core::hierarchical::START_RESOLUTION),
            ),
        };
        let (variable, fixed_diameter, discard) = match settings.splats {
            Splats::Fixed { diameter } => (0, diameter, 0),
            Splats::Variable { overflow, .. } => (1, 0.0, (overflow == LevelOverflow::Discard) as u32),
        };
        let (spot, spot_scale) = match planned.cone {
            Some((axis, cos_outer, scale)) => (axis.extend(cos_outer), scale),
            None => (Vec4::ZERO, 0.0),
        };
        let perspective = matches!(v.projection, Projection::Perspective { .. }) as u32 as f32;
        let gpu = Self {
            clip_from_world: Mat4::from_cols_array(&v.clip_from_world().to_cols_array()),
            origin: to_vec3(v.origin).extend(perspective),
            right: to_vec3(v.right).extend(half.x),
            up: to_vec3(v.up).extend(half.y),
            forward: to_vec3(v.forward).extend(v.near),
            spot,
            color: planned.color.extend(1.0),
            far: v.far,
            spot_scale,
            photon_resolution: p,
            map_resolution: m,
            photon_levels: levels,
            start_level: start,
            clustering,
            variable_splats: variable,
            fixed_diameter,
            top_level: top,
            discard_above_top: discard,
            exit_iterations: settings.exit_iterations,
            pyramid_offsets,
            level_offsets,
            materials: std::array::from_fn(|i| Vec4::from_array(std::array::from_fn(|c| generators.get(4 * i + c).map_or(0.0, |g| g.ior)))),
            material_flags: std::array::from_fn(|i| {
                UVec4::from_array(std::array::from_fn(|c| {
                    generators.get(4 * i + c).map_or(0, |g| DRAWN_HERE * g.drawn as u32 + ONE_SIDED * g.one_sided as u32)
                }))
            }),
            material_count: generators.len().min(MAX_GENERATORS) as u32,
            inverse_range_squared: planned.inverse_range_squared,
            traced_paths: bvh.is_some() as u32,
            path_epsilon: bvh.map_or(0.0, InstancedBvh::ray_offset),
            bvh_instances: bvh.map_or(0, InstancedBvh::gpu_instance_offset),
            emission: v.emission,
        };
        (gpu, pyramid_nodes, map_texels)
    }
}

/// Render world: the plan of this frame.
#[derive(Resource, Default)]
struct ExtractedPlan(CausticMapPlan);

/// Which light map a mesh is drawn into.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(super) enum LightMapPass {
    /// The nearest front faces.
    Front,
    /// The nearest faces of either side: an open double-sided generator's back
    /// reflects and refracts too (`Sides::Both`).
    FrontAndBack,
    /// The farthest back faces.
    Back,
    Receivers,
}

/// The light maps' mesh pipeline: Bevy's own meshes, positions (and normals) only.
#[derive(Resource)]
pub(super) struct LightMapPipeline {
    layout: KeptLayout,
    shader: Handle<Shader>,
}

impl SpecializedMeshPipeline for LightMapPipeline {
    type Key = (LightMapPass, PrimitiveTopology);

    fn specialize(&self, (pass, topology): Self::Key, layout: &MeshVertexBufferLayoutRef) -> Result<RenderPipelineDescriptor, SpecializedMeshPipelineError> {
        let receivers = pass == LightMapPass::Receivers;
        let mut attributes = vec![Mesh::ATTRIBUTE_POSITION.at_shader_location(0)];
        if !receivers {
            attributes.push(Mesh::ATTRIBUTE_NORMAL.at_shader_location(1));
        }
        let buffer = layout.0.get_layout(&attributes)?;
        let (cull_mode, depth_compare) = match pass {
            LightMapPass::Front => (Some(Face::Back), CompareFunction::Less),
            LightMapPass::FrontAndBack => (None, CompareFunction::Less),
            LightMapPass::Back => (Some(Face::Front), CompareFunction::Greater),
            LightMapPass::Receivers => (None, CompareFunction::Less),
        };
        let (vertex, fragment, format) = if receivers {
            ("receiver_vertex", "receiver_fragment", TextureFormat::R32Float)
        } else {
            ("generator_vertex", "surface_fragment", TextureFormat::Rgba32Float)
        };
        Ok(RenderPipelineDescriptor {
            label: Some(format!("caustic_light_map_{pass:?}").into()),
            layout: vec![self.layout.descriptor.clone()],
            vertex: VertexState { shader: self.shader.clone(), entry_point: Some(vertex.into()), buffers: vec![buffer], ..default() },
            fragment: Some(FragmentState {
                shader: self.shader.clone(),
                entry_point: Some(fragment.into()),
                targets: vec![Some(ColorTargetState { format, blend: None, write_mask: ColorWrites::ALL })],
                ..default()
            }),
            primitive: PrimitiveState { topology, cull_mode, front_face: FrontFace::Ccw, ..default() },
            depth_stencil: Some(DepthStencilState {
                format: TextureFormat::Depth32Float,
                depth_write_enabled: Some(true),
                depth_compare: Some(depth_compare),
                stencil: default(),
                bias: default(),
            }),
            ..default()
        })
    }
}

/// The compute pipelines, in `caustic_map.wgsl`'s order, and the projection's.
#[derive(Resource)]
pub(super) struct CausticMapPipelines {
    compute_layout: KeptLayout,
    /// The indirect arguments, bound for `write_args` alone.
    args_layout: KeptLayout,
    pub(super) compute: [CachedComputePipelineId; 6],
    /// The empty `anchor` of [`crate::gpu_work::anchor_first_timestamp`], under `compute_layout`.
    pub(super) anchor: CachedComputePipelineId,
    pub(super) project_layouts: [KeptLayout; 2],
    pub(super) project_shader: Handle<Shader>,
    pub(super) fullscreen: FullscreenShader,
}

/// The compute entry points, indices into [`CausticMapPipelines::compute`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kernel {
    TracePhotons,
    BuildPyramid,
    WriteArgs,
    Traverse,
    Splat,
    Resolve,
}

pub(super) const KERNELS: [(Kernel, &str); 6] = [
    (Kernel::TracePhotons, "trace_photons"),
    (Kernel::BuildPyramid, "build_pyramid"),
    (Kernel::WriteArgs, "write_args"),
    (Kernel::Traverse, "traverse"),
    (Kernel::Splat, "splat"),
    (Kernel::Resolve, "resolve"),
];

impl Kernel {
    /// The stage of the paper's Table 3 the kernel belongs to: the name its GPU time
    /// span is recorded under (Bevy's `RenderDiagnosticsPlugin`).
    pub(super) fn stage(self) -> &'static str {
        match self {
            Kernel::TracePhotons => "caustic_maps/photon_buffer",
            Kernel::BuildPyramid => "caustic_maps/pyramid",
            Kernel::WriteArgs | Kernel::Traverse => "caustic_maps/gather",
            Kernel::Splat => "caustic_maps/splat",
            Kernel::Resolve => "caustic_maps/resolve",
        }
    }
}

/// How many workgroups a dispatch runs.
#[derive(Clone, Copy, Debug)]
pub(super) enum Groups {
    Direct(u32, u32),
    /// Three words of the args buffer, written by the `write_args` before it.
    Indirect(u32),
}

/// One dispatch of a light view's compute passes.
#[derive(Clone, Copy, Debug)]
pub(super) struct Dispatch {
    pub(super) kernel: Kernel,
    pub(super) step: usize,
    pub(super) groups: Groups,
}

/// The dispatches of one light view and the steps they read, in order: for each photon
/// buffer (the transmitted light's, then each Fresnel branch's) the trace, the pyramid
/// levels, the gather (flat, or the traversal level by level) and the splats into the
/// one caustic map; then its resolve.
fn plan_dispatches(settings: &CausticMapSettings, counter_base: u32) -> (Vec<Dispatch>, Vec<GpuStep>) {
    let p = settings.photon_resolution;
    let m = settings.map_resolution;
    let (mut steps, mut dispatches) = (Vec::new(), Vec::new());
    let mut push = |kernel: Kernel, step: GpuStep, groups: Groups| {
        steps.push(GpuStep { counter_base, ..step });
        dispatches.push(Dispatch { kernel, step: steps.len() - 1, groups });
    };
    // The flat gather reads no pyramid.
    let (start, pyramid_levels) = match settings.gather {
        Gather::Flat => (0, 0),
        Gather::Hierarchical { .. } => (start_level(p, caustics_core::hierarchical::START_RESOLUTION), p.ilog2()),
    };
    let fixed_count = (p >> start) * (p >> start);
    let mut slot = 0;
    for branch in 0..settings.photon_buffers() {
        push(Kernel::TracePhotons, GpuStep { branch, ..default() }, Groups::Direct(p.div_ceil(8), p.div_ceil(8)));
        for level in 1..=pyramid_levels {
            let w = (p >> level).div_ceil(8);
            push(Kernel::BuildPyramid, GpuStep { level, ..default() }, Groups::Direct(w, w));
        }
        let mut source = ALL_NODES;
        for level in (0..=start).rev() {
            let destination = if level == 0 { NO_TARGET } else { (start - level) % 2 };
            let step = GpuStep { level, source, destination, args_slot: slot, fixed_count, ..default() };
            push(Kernel::WriteArgs, step, Groups::Direct(1, 1));
            push(Kernel::Traverse, step, Groups::Indirect(slot));
            (slot, source) = (slot + 1, destination);
        }
        let step = GpuStep { source: LIST_GATHERED, destination: NO_TARGET, args_slot: slot, ..default() };
        push(Kernel::WriteArgs, step, Groups::Direct(1, 1));
        push(Kernel::Splat, step, Groups::Indirect(slot));
        slot += 1;
    }
    push(Kernel::Resolve, GpuStep::default(), Groups::Direct(m.div_ceil(8), m.div_ceil(8)));
    (dispatches, steps)
}

/// What the scratch buffers are sized for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct ScratchSize {
    pub(super) photon_resolution: u32,
    pub(super) map_resolution: u32,
    pub(super) pyramid_nodes: u32,
    pub(super) map_texels: u32,
    pub(super) views: usize,
    pub(super) slots: usize,
}

/// The buffers and textures every light view uses in turn, sized for the settings.
pub(super) struct Scratch {
    pub(super) size: ScratchSize,
    pub(super) front: (Texture, TextureView),
    pub(super) back: (Texture, TextureView),
    pub(super) photon_depth: TextureView,
    pub(super) map_depth: TextureView,
    pub(super) photon_uv: Buffer,
    pub(super) photon_flux: Buffer,
    pub(super) pyramid: Buffer,
    pub(super) lists: [Buffer; 3],
    pub(super) counters: Buffer,
    pub(super) args: Buffer,
    pub(super) levels: Buffer,
    pub(super) args_bind_group: Option<BindGroup>,
    pub(super) bytes: u64,
}

/// One light view's own GPU data: its uniform, receiver map, resolved caustic map and
/// bind groups, and the passes that make them.
pub(super) struct ViewMaps {
    pub(super) uniform: UniformBuffer<GpuLightView>,
    pub(super) receivers: (Texture, TextureView),
    pub(super) resolved: Buffer,
    pub(super) generator_bind_group: BindGroup,
    pub(super) occluder_bind_group: BindGroup,
    pub(super) compute_bind_group: BindGroup,
    pub(super) dispatches: Vec<Dispatch>,
    pub(super) step_offsets: Vec<u32>,
    /// The three bind groups, kept while they bind the same buffers and views.
    kept: [KeptBindGroup; 3],
    /// The projection's bind group for each view.
    pub(super) projections: ViewBindGroups,
}

/// A mesh instance to draw into the light maps, with its pipelines.
pub(super) struct MeshDraw {
    pub(super) instance: u32,
    pub(super) mesh: AssetId<Mesh>,
    /// Front and back (generators) or receivers (occluders).
    pub(super) pipelines: [CachedRenderPipelineId; 2],
}

/// Render world: the caustic maps on the GPU.
#[derive(Resource, Default)]
pub struct CausticMapsGpu {
    /// The plan generation the maps were made for.
    pub(super) generation: Option<u64>,
    /// The maps must be (re)made this frame.
    pub(super) dirty: bool,
    pub(super) scratch: Option<Scratch>,
    pub(super) views: Vec<ViewMaps>,
    generators: StorageBuffer<Vec<GpuInstance>>,
    occluders: StorageBuffer<Vec<GpuInstance>>,
    /// `triangle_bvh` in `caustic_map.wgsl`: the generators' `InstancedBvh` (one zero
    /// vector without one).
    bvh: InstancedBvhBuffer,
    steps: DynamicUniformBuffer<GpuStep>,
    pub(super) generator_draws: Vec<MeshDraw>,
    pub(super) occluder_draws: Vec<MeshDraw>,
    /// The photon and map resolutions last asked for that did not fit (warned once).
    lowered: Option<(u32, u32)>,
}

impl CausticMapsGpu {
    /// The photon buffer of the last light view made, in two halves: where each photon
    /// lands (`vec2<f32>` map coordinates) and its flux and solid angle (`vec2<f32>`);
    /// copyable.
    pub fn photons(&self) -> Option<(&Buffer, &Buffer)> {
        self.scratch.as_ref().map(|s| (&s.photon_uv, &s.photon_flux))
    }

    /// The gathered list of the last light view made (`u32` entries, level in the top
    /// eight bits; its length is counter 2), copyable.
    pub fn gathered(&self) -> Option<&Buffer> {
        self.scratch.as_ref().map(|s| &s.lists[2])
    }

    /// The photon and map resolutions the maps were made at (the settings', or less
    /// where this GPU's buffers do not hold them).
    pub fn resolutions(&self) -> Option<(u32, u32)> {
        self.scratch.as_ref().map(|s| (s.size.photon_resolution, s.size.map_resolution))
    }

    /// Every light view's counters ([`COUNTERS_PER_VIEW`] `u32` each: list lengths, the
    /// gathered count at 2, clusters at 3, nodes processed per level from
    /// [`PROCESSED_COUNTER`]), copyable.
    pub fn counters(&self) -> Option<&Buffer> {
        self.scratch.as_ref().map(|s| &s.counters)
    }

    /// Light view `index`'s resolved caustic map (`f32` a texel, photon units), copyable.
    pub fn resolved(&self, index: usize) -> Option<&Buffer> {
        self.views.get(index).map(|v| &v.resolved)
    }

    /// Bytes of GPU memory the caustic maps hold.
    pub fn bytes(&self) -> u64 {
        self.scratch.as_ref().map_or(0, |s| s.bytes)
            + self.bvh.size()
            + self.views.iter().map(|v| v.resolved.size() + 8 * v.receivers.0.width() as u64 * v.receivers.0.height() as u64).sum::<u64>()
    }

    /// How many light views have maps.
    pub fn view_count(&self) -> usize {
        self.views.len()
    }
}

pub(super) fn build(app: &mut App) {
    let cpu = crate::CausticCpuTime::of(app).render;
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedPlan>()
        .init_resource::<CausticMapsGpu>()
        .init_resource::<SpecializedMeshPipelines<LightMapPipeline>>()
        .init_resource::<SpecializedRenderPipelines<CausticMapPipelines>>()
        .add_systems(RenderStartup, init_pipelines)
        .add_systems(ExtractSchedule, timed(&cpu, extract_plan))
        .add_systems(
            Render,
            (
                timed(&cpu, prepare_maps)
                    .run_if(|extracted: Res<ExtractedPlan>, gpu: Res<CausticMapsGpu>| !extracted.0.views.is_empty() || gpu.generation.is_some())
                    .in_set(RenderSystems::PrepareResources),
                timed(&cpu, crate::irradiance::prepare_projection_pipelines::<CausticMapPipelines>).run_if(maps_in_view).in_set(RenderSystems::Prepare),
            ),
        )
        .add_systems(RenderGraph, timed(&cpu, super::pass::make_caustic_maps).run_if(maps_in_view).in_set(RenderGraphSystems::Render).before(camera_driver))
        .add_systems(
            Core3d,
            timed(&cpu, super::pass::project_caustic_maps)
                .run_if(maps_in_view)
                .after(crate::irradiance::inject_irradiance)
                .after(Core3dSystems::Prepass)
                .before(Core3dSystems::MainPass),
        );
}

/// Whether any view shows caustic maps: else their passes are left out of the frame.
fn maps_in_view(gpu: Res<CausticMapsGpu>) -> bool {
    !gpu.views.is_empty()
}

fn extract_plan(mut extracted: ResMut<ExtractedPlan>, plan: Extract<Res<CausticMapPlan>>) {
    if extracted.0.generation != plan.generation || extracted.0.views.len() != plan.views.len() {
        extracted.0 = plan.clone();
    }
}

fn init_pipelines(mut commands: Commands, asset_server: Res<AssetServer>, cache: Res<PipelineCache>, fullscreen: Res<FullscreenShader>) {
    let map_layout = BindGroupLayoutDescriptor::new(
        "caustic_light_map_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::VERTEX_FRAGMENT,
            (uniform_buffer::<GpuLightView>(false), storage_buffer_read_only::<GpuInstance>(false)),
        ),
    );
    commands.insert_resource(LightMapPipeline {
        layout: KeptLayout::new(map_layout),
        shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "maps.wgsl"),
    });
    let float = TextureSampleType::Float { filterable: false };
    let compute_layout = BindGroupLayoutDescriptor::new(
        "caustic_map_compute_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                uniform_buffer::<GpuLightView>(false),
                uniform_buffer::<GpuStep>(true),
                texture_2d(float),
                texture_2d(float),
                texture_2d(float),
                storage_buffer::<Vec2>(false),
                storage_buffer::<Vec2>(false),
                storage_buffer::<UVec4>(false),
                storage_buffer::<u32>(false),
                storage_buffer::<u32>(false),
                storage_buffer::<u32>(false),
                storage_buffer::<u32>(false),
                storage_buffer::<u32>(false),
                storage_buffer::<f32>(false),
                storage_buffer_read_only::<Vec4>(false),
            ),
        ),
    );
    let args_layout =
        BindGroupLayoutDescriptor::new("caustic_map_args_layout", &BindGroupLayoutEntries::single(ShaderStages::COMPUTE, storage_buffer::<u32>(false)));
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "caustic_map.wgsl");
    let compute = KERNELS.map(|(kernel, entry)| {
        let mut layout = vec![compute_layout.clone()];
        if kernel == Kernel::WriteArgs {
            layout.push(args_layout.clone());
        }
        cache.queue_compute_pipeline(ComputePipelineDescriptor {
            label: Some(format!("caustic_map_{entry}").into()),
            layout,
            shader: shader.clone(),
            entry_point: Some(entry.into()),
            ..default()
        })
    });
    let [anchor] = crate::irradiance::compute_pipelines(&cache, "caustic_map", &compute_layout, &shader, ["anchor"]);
    let project_layout = |multisampled: bool| {
        BindGroupLayoutDescriptor::new(
            if multisampled { "caustic_map_project_layout_msaa" } else { "caustic_map_project_layout" },
            &BindGroupLayoutEntries::sequential(
                ShaderStages::FRAGMENT,
                (
                    uniform_buffer::<ViewUniform>(true),
                    if multisampled { texture_depth_2d_multisampled() } else { texture_depth_2d() },
                    if multisampled { texture_2d_multisampled(float) } else { texture_2d(float) },
                    uniform_buffer::<GpuLightView>(false),
                    texture_2d(float),
                    storage_buffer_read_only::<f32>(false),
                ),
            ),
        )
    };
    commands.insert_resource(CausticMapPipelines {
        compute_layout: KeptLayout::new(compute_layout),
        args_layout: KeptLayout::new(args_layout),
        compute,
        anchor,
        project_layouts: [project_layout(false), project_layout(true)].map(KeptLayout::new),
        project_shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "project.wgsl"),
        fullscreen: fullscreen.clone(),
    });
}

impl SpecializedRenderPipeline for CausticMapPipelines {
    /// Whether the prepass is multisampled.
    type Key = bool;

    fn specialize(&self, multisampled: bool) -> RenderPipelineDescriptor {
        crate::irradiance::projection_pipeline(
            "caustic_map_project_pipeline",
            &self.project_layouts[multisampled as usize].descriptor,
            &self.project_shader,
            &self.fullscreen,
            multisampled,
        )
    }
}

fn target_texture(device: &RenderDevice, label: &'static str, size: u32, format: TextureFormat) -> (Texture, TextureView) {
    let texture = device.create_texture(&TextureDescriptor {
        label: Some(label),
        size: Extent3d { width: size, height: size, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: TextureDimension::D2,
        format,
        usage: TextureUsages::RENDER_ATTACHMENT | TextureUsages::TEXTURE_BINDING | TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let view = texture.create_view(&TextureViewDescriptor::default());
    (texture, view)
}

fn storage(device: &RenderDevice, label: &'static str, bytes: u64, extra: BufferUsages) -> Buffer {
    device.create_buffer(&BufferDescriptor {
        label: Some(label),
        size: bytes.max(16),
        usage: BufferUsages::STORAGE | BufferUsages::COPY_SRC | BufferUsages::COPY_DST | extra,
        mapped_at_creation: false,
    })
}

impl Scratch {
    fn new(device: &RenderDevice, size: ScratchSize) -> Self {
        let (p, m) = (size.photon_resolution, size.map_resolution);
        let photons = p as u64 * p as u64;
        let depth = |label, side| target_texture(device, label, side, TextureFormat::Depth32Float).1;
        let sizes = [
            photons * 8,
            size.pyramid_nodes as u64 * 16,
            photons * 4,
            size.views as u64 * COUNTERS_PER_VIEW as u64 * 4,
            size.slots as u64 * 12,
            size.map_texels as u64 * 8,
        ];
        // The buffers, the front and back maps with their depth, and the receiver depth.
        let bytes = 2 * sizes[0] + sizes[1] + 3 * sizes[2] + sizes[3] + sizes[4] + sizes[5] + photons * (16 + 16 + 4) + m as u64 * m as u64 * 4;
        Self {
            size,
            front: target_texture(device, "caustic_front_map", p, TextureFormat::Rgba32Float),
            back: target_texture(device, "caustic_back_map", p, TextureFormat::Rgba32Float),
            photon_depth: depth("caustic_photon_depth", p),
            map_depth: depth("caustic_receiver_depth", m),
            photon_uv: storage(device, "caustic_photon_uv", sizes[0], BufferUsages::empty()),
            photon_flux: storage(device, "caustic_photon_flux", sizes[0], BufferUsages::empty()),
            pyramid: storage(device, "caustic_photon_pyramid", sizes[1], BufferUsages::empty()),
            lists: ["caustic_traversal_list_0", "caustic_traversal_list_1", "caustic_gathered"]
                .map(|label| storage(device, label, sizes[2], BufferUsages::empty())),
            counters: storage(device, "caustic_gather_counters", sizes[3], BufferUsages::empty()),
            args: storage(device, "caustic_gather_args", sizes[4], BufferUsages::INDIRECT),
            levels: storage(device, "caustic_map_levels", sizes[5], BufferUsages::empty()),
            args_bind_group: None,
            bytes,
        }
    }
}

/// `settings` with the photon and map resolutions that the device's limits and the
/// budget allow, at most the asked ones: the photon buffer's halves (8 bytes a photon)
/// and the map levels (8 bytes a texel) are the largest bindings, and the scratch and
/// `views` light views' maps ([`Scratch::new`], [`ViewMaps`]) must fit `budget` bytes.
/// Halves the finer of the two until they fit (or reach 16).
fn fitting(device: &RenderDevice, settings: &CausticMapSettings, budget: u64, views: usize) -> CausticMapSettings {
    let (largest, widest) = (largest_binding(device), device.limits().max_texture_dimension_2d);
    let side = |r: u32| (r as u64).pow(2);
    let levels = |s: &CausticMapSettings| (0..=top_level(s)).map(|l| side((s.map_resolution >> l).max(1)) * 8).sum::<u64>();
    let pyramid = |p: u32| (0..=p.ilog2()).map(|l| side(p >> l)).sum::<u64>() * 16;
    let bytes = |s: &CausticMapSettings| {
        let (p, m) = (s.photon_resolution, s.map_resolution);
        side(p) * (2 * 8 + 3 * 4 + 16 + 16 + 4) + pyramid(p) + levels(s) + side(m) * (4 + 8 * views as u64)
    };
    let mut fitted = *settings;
    loop {
        let photons_too_many = side(fitted.photon_resolution) * 8 > largest || fitted.photon_resolution > widest;
        let map_too_fine = levels(&fitted) > largest || fitted.map_resolution > widest;
        let finer_photons = fitted.photon_resolution >= fitted.map_resolution;
        let halve_photons = photons_too_many || (!map_too_fine && bytes(&fitted) > budget && finer_photons);
        let halve_map = map_too_fine || (bytes(&fitted) > budget && !finer_photons);
        if halve_photons && fitted.photon_resolution > 16 {
            fitted.photon_resolution /= 2;
        } else if (halve_map || halve_photons) && fitted.map_resolution > 16 {
            fitted.map_resolution /= 2;
        } else if halve_map && fitted.photon_resolution > 16 {
            fitted.photon_resolution /= 2;
        } else {
            return fitted;
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn prepare_maps(
    extracted: Res<ExtractedPlan>,
    mut gpu: ResMut<CausticMapsGpu>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    pipelines: Res<CausticMapPipelines>,
    map_pipeline: Res<LightMapPipeline>,
    mut specialized: ResMut<SpecializedMeshPipelines<LightMapPipeline>>,
    cache: Res<PipelineCache>,
    meshes: Res<RenderAssets<RenderMesh>>,
    budget: Res<CausticGpuBudget>,
) {
    let plan = &extracted.0;
    let Some(mut settings) = plan.settings.filter(|_| !plan.views.is_empty()) else {
        if gpu.generation.is_some() {
            *gpu = CausticMapsGpu::default();
        }
        return;
    };
    if gpu.generation == Some(plan.generation) && !gpu.dirty {
        return;
    }
    let gpu = gpu.as_mut();
    gpu.generation = Some(plan.generation);
    gpu.dirty = true;
    let fitted = fitting(&device, &settings, budget.bytes, plan.views.len());
    if fitted != settings {
        let asked = (settings.photon_resolution, settings.map_resolution);
        if gpu.lowered != Some(asked) {
            warn!(
                "bevy_caustics: {}² photons into a {}² caustic map do not fit this GPU's buffers or CausticGpuBudget ({}); the caustic maps use {}² into {}²",
                settings.photon_resolution,
                settings.map_resolution,
                mib(budget.bytes),
                fitted.photon_resolution,
                fitted.map_resolution
            );
            gpu.lowered = Some(asked);
        }
        settings = fitted;
    }

    // Instances and their pipelines: a mesh not on the GPU yet makes the maps wait a frame.
    let instance = |i: &CausticMapInstance, material: u32| {
        let normal = Mat3::from_mat4(i.world_from_local).inverse().transpose();
        GpuInstance { world_from_local: i.world_from_local, normal_from_local: Mat4::from_mat3(normal), material: UVec4::new(material, 0, 0, 0) }
    };
    let mut draws = |list: &[CausticMapInstance], passes: &dyn Fn(&CausticMapInstance) -> [LightMapPass; 2], ready: &mut bool| -> Vec<MeshDraw> {
        let mut out = Vec::new();
        for (index, i) in list.iter().enumerate() {
            let Some(mesh) = meshes.get(i.mesh) else {
                *ready = false;
                continue;
            };
            let topology = mesh.primitive_topology();
            if !matches!(topology, PrimitiveTopology::TriangleList | PrimitiveTopology::TriangleStrip) {
                continue;
            }
            let ids = passes(i).map(|pass| specialized.specialize(&cache, &map_pipeline, (pass, topology), &mesh.layout));
            if let [Ok(a), Ok(b)] = ids {
                out.push(MeshDraw { instance: index as u32, mesh: i.mesh, pipelines: [a, b] });
            }
        }
        out
    };
    let mut ready = true;
    let front = |i: &CausticMapInstance| if i.both_sides { LightMapPass::FrontAndBack } else { LightMapPass::Front };
    gpu.generator_draws = draws(&plan.generators, &|i| [front(i), LightMapPass::Back], &mut ready);
    gpu.occluder_draws = draws(&plan.occluders, &|_| [LightMapPass::Receivers; 2], &mut ready);
    if !ready {
        gpu.generation = None;
    }
    let mut generators: Vec<GpuInstance> = plan.generators.iter().enumerate().map(|(k, i)| instance(i, k as u32)).collect();
    let mut occluders: Vec<GpuInstance> = plan.occluders.iter().map(|i| instance(i, 0)).collect();
    let bvh = plan.bvh.as_deref().filter(|_| settings.paths == PhotonPaths::Traced);
    let bvh_buffer = gpu.bvh.write(bvh.unwrap_or(&InstancedBvh::default()), "caustic_map_generator_bvh", &device, &queue);
    // A binding may not be empty.
    for list in [&mut generators, &mut occluders] {
        if list.is_empty() {
            list.push(GpuInstance::default());
        }
    }
    gpu.generators.set(generators);
    gpu.generators.set_label(Some("caustic_map_generators"));
    gpu.generators.write_buffer(&device, &queue);
    gpu.occluders.set(occluders);
    gpu.occluders.set_label(Some("caustic_map_occluders"));
    gpu.occluders.write_buffer(&device, &queue);

    // Per light view: its uniform and dispatches; scratch sized for all.
    let mut uniforms = Vec::new();
    gpu.steps.clear();
    let mut plans = Vec::new();
    let (mut pyramid_nodes, mut map_texels) = (0, 0);
    for (k, planned) in plan.views.iter().enumerate() {
        let (uniform, nodes, texels) = GpuLightView::new(planned, &settings, &plan.generators, bvh);
        (pyramid_nodes, map_texels) = (nodes, texels);
        uniforms.push(uniform);
        let (dispatches, steps) = plan_dispatches(&settings, k as u32 * COUNTERS_PER_VIEW);
        let offsets: Vec<u32> = steps.into_iter().map(|s| gpu.steps.push(&s)).collect();
        plans.push((dispatches, offsets));
    }
    gpu.steps.set_label(Some("caustic_map_steps"));
    gpu.steps.write_buffer(&device, &queue);
    let slots = plans.iter().map(|(d, _)| d.iter().filter(|d| matches!(d.groups, Groups::Indirect(_))).count()).max().unwrap_or(0);
    let size = ScratchSize {
        photon_resolution: settings.photon_resolution,
        map_resolution: settings.map_resolution,
        pyramid_nodes,
        map_texels,
        views: plan.views.len(),
        slots,
    };
    if gpu.scratch.as_ref().is_none_or(|s| s.size != size) {
        let scratch = Scratch::new(&device, size);
        info!("bevy_caustics: caustic maps hold {:.1} MB of GPU memory", scratch.bytes as f64 / 1e6);
        let mut scratch = scratch;
        scratch.args_bind_group = Some(device.create_bind_group(
            "caustic_map_args_bind_group",
            pipelines.args_layout.get(&cache),
            &BindGroupEntries::single(scratch.args.as_entire_binding()),
        ));
        gpu.scratch = Some(scratch);
        gpu.views.clear();
    }
    let (Some(generators), Some(occluders), Some(steps)) = (gpu.generators.binding(), gpu.occluders.binding(), gpu.steps.binding()) else {
        return;
    };
    let (Some(generator_buffer), Some(occluder_buffer), Some(steps_buffer)) = (gpu.generators.buffer(), gpu.occluders.buffer(), gpu.steps.buffer()) else {
        return;
    };
    let Some(scratch) = gpu.scratch.as_ref() else { return };
    let map_layout = map_pipeline.layout.get(&cache);
    let compute_layout = pipelines.compute_layout.get(&cache);
    let m = settings.map_resolution;
    let mut views = std::mem::take(&mut gpu.views);
    views.truncate(plan.views.len());
    for (k, (uniform_value, (dispatches, step_offsets))) in uniforms.into_iter().zip(plans).enumerate() {
        let (mut uniform, receivers, resolved, (mut kept, projections)) = match views.get_mut(k) {
            Some(existing) => (
                std::mem::take(&mut existing.uniform),
                (existing.receivers.0.clone(), existing.receivers.1.clone()),
                existing.resolved.clone(),
                (std::mem::take(&mut existing.kept), std::mem::take(&mut existing.projections)),
            ),
            None => (
                UniformBuffer::default(),
                target_texture(&device, "caustic_receiver_map", m, TextureFormat::R32Float),
                storage(&device, "caustic_map_resolved", m as u64 * m as u64 * 4, BufferUsages::empty()),
                default(),
            ),
        };
        uniform.set(uniform_value);
        uniform.set_label(Some("caustic_map_light_view"));
        uniform.write_buffer(&device, &queue);
        let (Some(view_binding), Some(view_buffer)) = (uniform.binding(), uniform.buffer()) else { continue };
        let [kept_generators, kept_occluders, kept_compute] = &mut kept;
        let map_group = |kept: &mut KeptBindGroup, instances: &Buffer, binding: &BindingResource| {
            kept.get(&[map_layout.into(), view_buffer.into(), instances.into()], || {
                device.create_bind_group("caustic_light_map_bind_group", map_layout, &BindGroupEntries::sequential((view_binding.clone(), binding.clone())))
            })
        };
        let generator_bind_group = map_group(kept_generators, generator_buffer, &generators);
        let occluder_bind_group = map_group(kept_occluders, occluder_buffer, &occluders);
        let scratch_buffers = [
            &scratch.photon_uv,
            &scratch.photon_flux,
            &scratch.pyramid,
            &scratch.lists[0],
            &scratch.lists[1],
            &scratch.lists[2],
            &scratch.counters,
            &scratch.levels,
        ];
        let bound: Vec<Bound> =
            [compute_layout.into(), view_buffer.into(), steps_buffer.into(), (&scratch.front.1).into(), (&scratch.back.1).into(), (&receivers.1).into()]
                .into_iter()
                .chain(scratch_buffers.map(Bound::from))
                .chain([(&resolved).into(), (&bvh_buffer).into()])
                .collect();
        let compute_bind_group = kept_compute.get(&bound, || {
            device.create_bind_group(
                "caustic_map_compute_bind_group",
                compute_layout,
                &BindGroupEntries::sequential((
                    view_binding.clone(),
                    steps.clone(),
                    &scratch.front.1,
                    &scratch.back.1,
                    &receivers.1,
                    scratch.photon_uv.as_entire_binding(),
                    scratch.photon_flux.as_entire_binding(),
                    scratch.pyramid.as_entire_binding(),
                    scratch.lists[0].as_entire_binding(),
                    scratch.lists[1].as_entire_binding(),
                    scratch.lists[2].as_entire_binding(),
                    scratch.counters.as_entire_binding(),
                    scratch.levels.as_entire_binding(),
                    resolved.as_entire_binding(),
                    bvh_buffer.as_entire_binding(),
                )),
            )
        });
        let view_maps = ViewMaps {
            generator_bind_group,
            occluder_bind_group,
            uniform,
            receivers,
            resolved,
            compute_bind_group,
            dispatches,
            step_offsets,
            kept,
            projections,
        };
        if k < views.len() {
            views[k] = view_maps;
        } else {
            views.push(view_maps);
        }
    }
    gpu.views = views;
}

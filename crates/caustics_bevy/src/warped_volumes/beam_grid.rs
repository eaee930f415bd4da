//! Render world: light shafts at a fixed cost per eye ray (`beam_grid.wgsl`, the twin
//! of `caustics_core::volumes::BeamGrid`). After each build of the volumes, and when
//! the media change, a compute pass adds every volume's beam to a grid over each
//! medium's box (in fixed point, then turned into floats); the volumetric pass then
//! marches each eye ray through the grid, one
//! step a cell (at most [`super::WarpedVolumesSettings::shaft_steps`]), whatever the
//! number of volumes.

use super::ShaftIntegral;
use super::compute::VolumeBuild;
use super::render::{ExtractedVolumeSettings, ViewSeesMedium, VolumeBuffers};
use crate::gpu_budget::{largest_binding, mib};
use crate::gpu_work::anchor_first_timestamp;
use crate::irradiance::kept_bind_group::{KeptBindGroup, KeptLayout, write_changed};
use crate::irradiance::{ExtractedMedia, GpuMedium, MAX_MEDIA};
use crate::report::PassRecorder;
use bevy::core_pipeline::FullscreenShader;
use bevy::prelude::*;
use bevy::render::{
    diagnostic::RecordDiagnostics,
    render_resource::{
        binding_types::{
            sampler, storage_buffer_read_only_sized, storage_buffer_sized, texture_2d, texture_3d, texture_depth_2d, texture_depth_2d_multisampled,
            texture_storage_3d, uniform_buffer,
        },
        *,
    },
    renderer::{RenderContext, RenderDevice, RenderQueue},
    view::ViewUniform,
};
use bevy::shader::ShaderDefVal;
use caustics_core::glam;
use caustics_core::params::MediumCoefficients;
use caustics_core::volumes::{MediumBox, cell_of, direction_blocks, grid_size};

/// `Grid` in `beam_grid.wgsl`: one medium's cells (xyz) and the first one's index (w);
/// a cell's smallest world edge (x) and world volume (y), and the grid's first layer in
/// the march's textures (z); its blocks of deposited directions
/// ([`direction_blocks`], xyz) and the first one's index (w), the blocks of every grid
/// following the cells of every grid.
#[derive(Clone, Copy, Default, PartialEq, ShaderType)]
pub(super) struct GpuGrid {
    size: UVec4,
    cell: Vec4,
    blocks: UVec4,
}

/// `Grids` in `beam_grid.wgsl`.
#[derive(Clone, Copy, Default, PartialEq, ShaderType)]
pub(super) struct GpuBeamGrids {
    grids: [GpuGrid; MAX_MEDIA],
    /// xyz: the hue every volume shares ([`VolumeBuild::hue`]) in every grey medium,
    /// w: 1 when they do.
    hue: Vec4,
    max_steps: u32,
}

/// The march's textures: source and summed direction (where every volume shares a hue,
/// the first only: the direction and the source's sum), in half floats that the
/// sampler filters trilinearly.
const GRID_TEXTURE_FORMAT: TextureFormat = TextureFormat::Rgba16Float;

/// Three words a cell or a block of cells as the deposit adds to it, in 32-bit fixed
/// point: a cell's source, a block's directions.
const FIXED_CELL_BYTES: u64 = 12;

/// Nineteen words a bundle of beams (`BUNDLE_WORDS` in `beam_grid.wgsl`), and one in the
/// list of the slots taken.
const BUNDLE_BYTES: u64 = 80;

/// The bundles' hash table: a slot for each volume or cell, whichever is fewer, as a
/// power of two from 2¹⁰ to 2¹⁶ (a surface's beams enter about one layer of cells:
/// 96² on the default grid). Beams that find no slot go one by one.
fn bundle_slots(volumes: u64, cells: u64) -> u64 {
    volumes.min(cells).next_power_of_two().clamp(1 << 10, 1 << 16)
}

/// The bytes of a table of `slots` bundles: theirs, and the count of those taken.
fn bundle_bytes(slots: u64) -> u64 {
    slots * BUNDLE_BYTES + 4
}

/// Render world: the grids of this frame's media and whether they need a deposit.
#[derive(Resource, Default)]
pub(super) struct BeamGridBuffers {
    /// The march's two textures, every grid stacked along z from its first layer.
    pub textures: Option<[TextureView; 2]>,
    /// What the deposit adds to, and `resolve` turns into `textures`.
    fixed: Option<Buffer>,
    /// The bundles of thin beams ([`caustics_core::volumes::BeamGrid::deposit_all`])
    /// and, per volume and medium, the slot of the bundle its beam went to.
    bundles: Option<Buffer>,
    bundle_of: Option<Buffer>,
    /// The grids' cells together, and the textures' size.
    cells: u32,
    extent: Extent3d,
    /// The cells along a box's longest side when fewer than asked for fit (warned once).
    clamped: Option<u32>,
    pub grids: UniformBuffer<GpuBeamGrids>,
    /// The media and their cells the grid was laid out for.
    layout: Vec<(GpuMedium, UVec4)>,
    deposit: bool,
    /// The deposit's and the resolve's bind groups, kept while they bind the same.
    kept: [KeptBindGroup; 2],
}

/// The deposit's and the resolve's compute pipelines and the march's render pipelines.
#[derive(Resource)]
pub(super) struct BeamGridPipelines {
    deposit_layout: KeptLayout,
    /// The deposit's kernels in the order they run: the bundles gathered, the beams
    /// of those that do not merge deposited, the bundles deposited.
    deposit: [CachedComputePipelineId; 3],
    resolve_layout: KeptLayout,
    resolve: CachedComputePipelineId,
    /// `anchor`, an empty kernel ([`anchor_first_timestamp`]), under the deposit's and
    /// the resolve's layouts.
    anchors: [CachedComputePipelineId; 2],
    pub march_layouts: [KeptLayout; 2],
    /// The march's trilinear filter, clamped at the edges.
    pub sampler: Sampler,
    shader: Handle<Shader>,
    fullscreen: FullscreenShader,
}

pub(super) fn init_pipelines(
    mut commands: Commands,
    asset_server: Res<AssetServer>,
    fullscreen: Res<FullscreenShader>,
    cache: Res<PipelineCache>,
    device: Res<RenderDevice>,
) {
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "beam_grid.wgsl");
    let deposit_layout = BindGroupLayoutDescriptor::new(
        "caustic_shaft_deposit_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                texture_2d(TextureSampleType::Float { filterable: false }),
                storage_buffer_read_only_sized(false, None),
                uniform_buffer::<super::render::GpuVolumeSettings>(false),
                uniform_buffer::<GpuBeamGrids>(false),
                storage_buffer_sized(false, None),
                storage_buffer_sized(false, None),
                storage_buffer_sized(false, None),
            ),
        ),
    );
    let resolve_layout = BindGroupLayoutDescriptor::new(
        "caustic_shaft_resolve_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                uniform_buffer::<GpuBeamGrids>(false),
                storage_buffer_read_only_sized(false, None),
                texture_storage_3d(GRID_TEXTURE_FORMAT, StorageTextureAccess::WriteOnly),
                texture_storage_3d(GRID_TEXTURE_FORMAT, StorageTextureAccess::WriteOnly),
            ),
        ),
    );
    // `beam_grid.wgsl`'s entry point `entry`, under the shader def `def`.
    let kernel = |entry: &'static str, def: &'static str, layout: &BindGroupLayoutDescriptor| {
        cache.queue_compute_pipeline(ComputePipelineDescriptor {
            label: Some(format!("caustic_shaft_{entry}").into()),
            layout: vec![layout.clone()],
            shader: shader.clone(),
            shader_defs: vec![def.into()],
            entry_point: Some(entry.into()),
            ..default()
        })
    };
    let deposit = ["gather_bundles", "deposit", "deposit_bundles"].map(|entry| kernel(entry, "DEPOSIT", &deposit_layout));
    let resolve = kernel("resolve", "RESOLVE", &resolve_layout);
    let anchors = [kernel("anchor", "DEPOSIT", &deposit_layout), kernel("anchor", "RESOLVE", &resolve_layout)];
    let march_layouts = [false, true].map(|multisampled| {
        BindGroupLayoutDescriptor::new(
            "caustic_shaft_march_layout",
            &BindGroupLayoutEntries::sequential(
                ShaderStages::FRAGMENT,
                (
                    uniform_buffer::<ViewUniform>(true),
                    uniform_buffer::<super::render::GpuVolumeSettings>(false),
                    uniform_buffer::<GpuBeamGrids>(false),
                    storage_buffer_read_only_sized(false, None),
                    texture_3d(TextureSampleType::Float { filterable: true }),
                    texture_3d(TextureSampleType::Float { filterable: true }),
                    sampler(SamplerBindingType::Filtering),
                    if multisampled { texture_depth_2d_multisampled() } else { texture_depth_2d() },
                ),
            ),
        )
    });
    commands.insert_resource(BeamGridPipelines {
        deposit_layout: KeptLayout::new(deposit_layout),
        deposit,
        resolve_layout: KeptLayout::new(resolve_layout),
        resolve,
        anchors,
        march_layouts: march_layouts.map(KeptLayout::new),
        sampler: device.create_sampler(&SamplerDescriptor {
            label: Some("caustic_shaft_grid_sampler"),
            mag_filter: FilterMode::Linear,
            min_filter: FilterMode::Linear,
            ..default()
        }),
        shader,
        fullscreen: fullscreen.clone(),
    });
}

#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub(super) struct MarchKey {
    pub multisampled: bool,
    pub shaft_scale: u32,
    pub target_format: TextureFormat,
}

impl SpecializedRenderPipeline for BeamGridPipelines {
    type Key = MarchKey;

    fn specialize(&self, key: Self::Key) -> RenderPipelineDescriptor {
        let mut shader_defs: Vec<ShaderDefVal> = vec!["MARCH".into()];
        if key.multisampled {
            shader_defs.push("MULTISAMPLED".into());
        }
        if key.shaft_scale > 1 {
            shader_defs.push(ShaderDefVal::UInt("SHAFT_SCALE".into(), key.shaft_scale));
        }
        // As the per-volume pass: scaled by the view's intensity when straight into
        // its image, by the upsampling otherwise.
        let src_factor = if key.shaft_scale == 1 { BlendFactor::Constant } else { BlendFactor::One };
        let additive = BlendComponent { src_factor, dst_factor: BlendFactor::One, operation: BlendOperation::Add };
        RenderPipelineDescriptor {
            label: Some("caustic_shaft_march_pipeline".into()),
            layout: vec![self.march_layouts[key.multisampled as usize].descriptor.clone()],
            vertex: self.fullscreen.to_vertex_state(),
            fragment: Some(FragmentState {
                shader: self.shader.clone(),
                shader_defs,
                entry_point: Some("march".into()),
                targets: vec![Some(ColorTargetState {
                    format: key.target_format,
                    blend: Some(BlendState { color: additive, alpha: additive }),
                    write_mask: ColorWrites::ALL,
                })],
            }),
            ..default()
        }
    }
}

/// The resolve's workgroups: one a tile of 8 × 8 cells across x and y and 16 layers
/// along z, of every grid (`resolve_tile` in `beam_grid.wgsl`).
fn resolve_tiles(layout: &[(GpuMedium, UVec4)]) -> u64 {
    layout.iter().map(|(_, size)| u64::from(size.x.div_ceil(8) * size.y.div_ceil(8) * size.z.div_ceil(16))).sum()
}

/// The grids over `media`, `longest` cells along each box's longest side, their
/// layout (to tell when it changes), their cells and blocks together and the textures'
/// size (the grids stacked along z).
fn lay_out(media: &ExtractedMedia, longest: u32, max_steps: u32) -> (GpuBeamGrids, Vec<(GpuMedium, UVec4)>, u32, UVec3) {
    let mut gpu = GpuBeamGrids { max_steps, ..default() };
    let mut layout = Vec::new();
    let mut first = 0u32;
    let mut extent = UVec3::ZERO;
    for (grid, medium) in gpu.grids.iter_mut().zip(&media.0) {
        let world_from_local = glam::Affine3A::from_mat4(glam::Mat4::from_cols_array(&medium.local_from_world.inverse().to_cols_array()));
        let coefficients = MediumCoefficients { scattering: 0.0, absorption: glam::Vec3::ZERO, asymmetry: 0.0 };
        let core = MediumBox { world_from_local, coefficients };
        let size = grid_size(&core, longest);
        let (edge, volume) = cell_of(&core, size);
        let blocks = direction_blocks(size).extend(0);
        *grid = GpuGrid { size: UVec4::new(size.x, size.y, size.z, first), cell: Vec4::new(edge, volume, extent.z as f32, 0.0), blocks };
        layout.push((*medium, grid.size));
        first += size.x * size.y * size.z;
        extent = UVec3::new(extent.x.max(size.x), extent.y.max(size.y), extent.z + size.z);
    }
    for grid in gpu.grids.iter_mut().take(media.0.len()) {
        grid.blocks.w = first;
        first += grid.blocks.truncate().element_product();
    }
    (gpu, layout, first, extent)
}

/// Lays the grids out over this frame's media (cells along each box's longest side:
/// [`super::WarpedVolumesSettings::shaft_grid`], fewer where the deposit's fixed-point
/// cells would pass what the adapter binds or the stacked grids its largest 3D
/// texture, with a warning) and marks a deposit when
/// the volumes are built this frame or the layout changed; none while no view shows
/// shafts.
#[expect(clippy::too_many_arguments)]
pub(super) fn prepare_grids(
    views: Query<(), With<ViewSeesMedium>>,
    extracted: Res<ExtractedVolumeSettings>,
    media: Res<ExtractedMedia>,
    build: Res<VolumeBuild>,
    volumes: Res<VolumeBuffers>,
    mut grids: ResMut<BeamGridBuffers>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let settings = extracted.0;
    if settings.shaft_integral != ShaftIntegral::Grid || views.is_empty() || media.0.is_empty() || volumes.volumes.is_none() {
        *grids = BeamGridBuffers { clamped: grids.clamped, ..default() };
        return;
    }
    let bindable = largest_binding(&device);
    let largest_texture = device.limits().max_texture_dimension_3d;
    let mut longest = settings.shaft_grid.max(2);
    let (mut gpu, layout, first, extent) = loop {
        let laid = lay_out(&media, longest, settings.shaft_steps.max(1));
        if (u64::from(laid.2) * FIXED_CELL_BYTES <= bindable && laid.3.max_element() <= largest_texture) || longest <= 2 {
            break laid;
        }
        longest -= longest / 8 + 1;
    };
    let clamped = (longest < settings.shaft_grid).then_some(longest);
    if clamped.is_some() && grids.clamped != clamped {
        warn!(
            "bevy_caustics: the light shafts' grids of {} media at WarpedVolumesSettings::shaft_grid = {} cells need more than this adapter binds ({}) \
             or its 3D textures hold ({largest_texture} texels a side): they are laid out at {longest} cells along each box's longest side",
            media.0.len(),
            settings.shaft_grid,
            mib(bindable)
        );
    }
    grids.clamped = clamped;
    // A coloured medium dims each channel of a beam by its own σₜ: no hue is shared.
    let hue = build.hue.filter(|_| media.0.iter().all(GpuMedium::is_grey));
    gpu.hue = hue.map_or(Vec4::ZERO, |h| Vec4::new(h.x, h.y, h.z, 1.0));
    grids.deposit |= build.builds_this_frame() || grids.layout != layout;
    let buffer = |label, size| {
        Some(device.create_buffer(&BufferDescriptor {
            label: Some(label),
            size,
            usage: BufferUsages::STORAGE | BufferUsages::COPY_DST,
            mapped_at_creation: false,
        }))
    };
    let size = Extent3d { width: extent.x.max(1), height: extent.y.max(1), depth_or_array_layers: extent.z.max(1) };
    if grids.extent != size || grids.cells != first {
        let texture = |label| {
            device
                .create_texture(&TextureDescriptor {
                    label: Some(label),
                    size,
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: TextureDimension::D3,
                    format: GRID_TEXTURE_FORMAT,
                    usage: TextureUsages::STORAGE_BINDING | TextureUsages::TEXTURE_BINDING,
                    view_formats: &[],
                })
                .create_view(&TextureViewDescriptor::default())
        };
        grids.textures = Some([texture("caustic_shaft_grid_light"), texture("caustic_shaft_grid_directions")]);
        grids.fixed = buffer("caustic_shaft_grid_fixed", u64::from(first.max(1)) * FIXED_CELL_BYTES);
        grids.cells = first;
        grids.extent = size;
        grids.deposit = true;
    }
    let capacity = volumes.capacity();
    let cells = layout.iter().map(|(_, size)| u64::from(size.x * size.y * size.z)).sum();
    let table = bundle_bytes(bundle_slots(capacity, cells));
    if grids.bundles.as_ref().is_none_or(|b| b.size() != table) {
        grids.bundles = buffer("caustic_shaft_bundles", table);
        grids.deposit = true;
    }
    let bundle_of = 4 * MAX_MEDIA as u64 * capacity.max(1);
    if grids.bundle_of.as_ref().is_none_or(|b| b.size() != bundle_of) {
        grids.bundle_of = buffer("caustic_shaft_bundle_of", bundle_of);
        grids.deposit = true;
    }
    grids.layout = layout;
    grids.grids.set_label(Some("caustic_shaft_grids"));
    write_changed(&mut grids.grids, gpu, &device, &queue);
}

/// Adds every volume's beam to the fixed-point grids, then turns them into the march's
/// half-float textures, one invocation a column of cells, and clears them for the
/// next deposit (a new buffer starts cleared), when [`prepare_grids`] asked for it
/// (after the build: the same frame's volumes). The narrow beams that enter the grid
/// through one cell go as one bundle (gathered one invocation a volume, deposited one
/// invocation a bundle), the others one invocation a volume, or a workgroup a wide one.
pub(super) fn deposit_beams(
    mut ctx: RenderContext,
    mut grids: ResMut<BeamGridBuffers>,
    volumes: Res<VolumeBuffers>,
    pipelines: Res<BeamGridPipelines>,
    cache: Res<PipelineCache>,
    recorder: Res<PassRecorder>,
) {
    let grids = &mut *grids;
    let (
        true,
        Some(deposit),
        Some(resolve),
        Some([light, directions]),
        Some(fixed),
        Some(bundles),
        Some(bundle_of),
        Some(volume_texels),
        Some(counters),
        Some(settings),
        Some(uniform),
    ) = (
        grids.deposit,
        pipelines.deposit.iter().map(|id| cache.get_compute_pipeline(*id)).collect::<Option<Vec<_>>>(),
        cache.get_compute_pipeline(pipelines.resolve),
        grids.textures.as_ref(),
        grids.fixed.as_ref(),
        grids.bundles.as_ref(),
        grids.bundle_of.as_ref(),
        volumes.volumes.as_ref().map(|v| &v.view),
        volumes.counters.as_ref(),
        volumes.settings.buffer(),
        grids.grids.buffer(),
    )
    else {
        return;
    };
    let device = ctx.render_device();
    let layout = pipelines.deposit_layout.get(&cache);
    let bound = [layout.into(), volume_texels.into(), counters.into(), settings.into(), uniform.into(), fixed.into(), bundles.into(), bundle_of.into()];
    let deposit_group = grids.kept[0].get(&bound, || {
        device.create_bind_group(
            "caustic_shaft_deposit_bind_group",
            layout,
            &BindGroupEntries::sequential((
                volume_texels,
                counters.as_entire_binding(),
                settings.as_entire_binding(),
                uniform.as_entire_binding(),
                fixed.as_entire_binding(),
                bundles.as_entire_binding(),
                bundle_of.as_entire_binding(),
            )),
        )
    });
    let layout = pipelines.resolve_layout.get(&cache);
    let bound = [layout.into(), uniform.into(), fixed.into(), light.into(), directions.into()];
    let resolve_group = grids.kept[1].get(&bound, || {
        device.create_bind_group(
            "caustic_shaft_resolve_bind_group",
            layout,
            &BindGroupEntries::sequential((uniform.as_entire_binding(), fixed.as_entire_binding(), light, directions)),
        )
    });
    // At most one workgroup for 64 volumes, bundles or cells the buffers hold; each
    // strides over the rest.
    let groups = |items: u64| items.clamp(1, 65535) as u32;
    let volume_groups = groups(volumes.capacity().div_ceil(64));
    let deposit_groups = [volume_groups, volume_groups, groups((bundles.size() / BUNDLE_BYTES).div_ceil(64))];
    let resolve_groups = groups(resolve_tiles(&grids.layout));
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let encoder = ctx.command_encoder();
    let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor { label: Some("caustic_shaft_deposit"), ..default() });
    let span = diagnostics.pass_span(&mut pass, "caustics/shaft_deposit");
    pass.set_bind_group(0, &deposit_group, &[]);
    anchor_first_timestamp(&mut pass, diagnostics.is_some(), cache.get_compute_pipeline(pipelines.anchors[0]));
    for (kernel, groups) in deposit.iter().zip(deposit_groups) {
        pass.set_pipeline(kernel);
        pass.dispatch_workgroups(groups, 1, 1);
    }
    span.end(&mut pass);
    drop(pass);
    let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor { label: Some("caustic_shaft_resolve"), ..default() });
    let span = diagnostics.pass_span(&mut pass, "caustics/shaft_resolve");
    pass.set_bind_group(0, &resolve_group, &[]);
    anchor_first_timestamp(&mut pass, diagnostics.is_some(), cache.get_compute_pipeline(pipelines.anchors[1]));
    pass.set_pipeline(resolve);
    pass.dispatch_workgroups(resolve_groups, 1, 1);
    span.end(&mut pass);
    drop(pass);
    encoder.clear_buffer(fixed, 0, None);
    encoder.clear_buffer(bundles, 0, None);
    grids.deposit = false;
    recorder.record("shaft deposit");
}

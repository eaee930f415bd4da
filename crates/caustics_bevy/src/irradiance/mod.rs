//! The per-view caustic irradiance buffer and the one composite step that shows it.
//!
//! Every technique accumulates caustic irradiance `E` (the light's units per m², lux
//! for Bevy's lights) into an HDR buffer the size of the view, at the surface each
//! pixel sees. It is stored as `E · exposure` (the view's exposure, as `bevy_pbr`
//! applies it to lights), each pass's share capped at [`MAX_EXPOSED_IRRADIANCE`], so
//! that a 100 000 lux sun focused a thousandfold under Bevy's default exposure stays
//! finite in half floats. The composite then draws the [`CausticReceiver`] meshes once more, after the
//! opaque pass and depth-tested against it, adding the Lambertian radiance
//! `albedo/π · E · exposure` — what `bevy_pbr` adds for the same irradiance from a
//! light — so caustics land on receivers only, with their unmodified
//! `StandardMaterial` colour and texture, and only where they are visible. It runs
//! before Bevy's transmissive pass copies the opaque image, so glass and water drawn
//! with `specular_transmission` show the caustics behind them.
//!
//! An application can supply the buffer itself with [`InjectedIrradiance`] (the demo
//! injects the CPU reference tracer's irradiance this way). A camera opts in with
//! [`Caustics`], which brings Bevy's `Hdr` (the composite adds linear light
//! before tonemapping) and the prepasses the techniques read receiver points from.

#[cfg(feature = "warped-volumes")]
pub(crate) mod bvh_refit;
mod composite;
pub mod kept_bind_group;
pub mod mesh_bvhs;
pub mod reference_view;

use crate::components::{CausticReceiver, Caustics, InvalidCausticParams, ParticipatingMedium};
use crate::cpu_time::timed;
use crate::report::PassRecorder;
use bevy::camera::{Hdr, Viewport};
use bevy::core_pipeline::{Core3dSystems, FullscreenShader, prepass::ViewPrepassTextures, schedule::Core3d};
use bevy::ecs::component::ComponentId;
use bevy::ecs::system::SystemParam;
use bevy::pbr::{ExtendedMaterial, Material, MaterialExtension, MeshMaterial3d, MeshPipeline, MeshPipelineKey, RenderMeshQueueData, StandardMaterial};
use bevy::platform::collections::{HashMap, HashSet};
use bevy::prelude::*;
use bevy::render::mesh::RenderMesh;
use bevy::render::{
    Extract, ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems,
    camera::ExtractedCamera,
    diagnostic::RecordDiagnostics,
    extract_component::{ExtractComponent, ExtractComponentPlugin},
    render_asset::RenderAssets,
    render_resource::{
        binding_types::{texture_2d, uniform_buffer},
        *,
    },
    renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery},
    sync_world::{MainEntity, RenderEntity},
    texture::{CachedTexture, GpuImage, TextureCache},
    view::{Msaa, ViewUniform, ViewUniformOffset, ViewUniforms},
};
use kept_bind_group::{Bound, KeptLayout, ViewBindGroups};
use std::marker::PhantomData;

pub use composite::CausticCompositePipeline;
pub(crate) use composite::draw_composite;

/// Format of the caustic irradiance buffer: HDR float, blendable so that passes can
/// accumulate with additive blending.
pub const CAUSTIC_IRRADIANCE_FORMAT: TextureFormat = TextureFormat::Rgba16Float;

/// The most a pass adds to, and the composite reads from, a texel of the buffer, as
/// `E · exposure`: 2048 times what shows a white surface at mid grey, far past what
/// tone mapping tells apart (only bloom sees the clipped part), while 32 such shares
/// still sum within half-float range (65 504). Under Bevy's default exposure (EV100
/// 9.7) it is 2·10⁶ lux, twenty direct suns. Below it the buffer holds `E · exposure`
/// exactly (to half-float precision); a `Rgba32Float` buffer would hold more at twice
/// the bandwidth of every caustics pass and the composite, for light nobody can see.
pub const MAX_EXPOSED_IRRADIANCE: f32 = 2048.0;

/// Caustic irradiance supplied by the application for a camera's view: a float image
/// (`Rgba32Float` or `Rgba16Float`), linear, in the light's units per m² (lux for Bevy
/// lights), one value per pixel for the surface that pixel sees (an image of another
/// size is resampled to the view). It starts the view's buffer each frame, before the
/// techniques add theirs. [`crate::pixels::irradiance_image`] builds one.
#[derive(Component, Clone, Debug, ExtractComponent, Reflect)]
#[reflect(Component)]
pub struct InjectedIrradiance(pub Handle<Image>);

/// Main world: which techniques have something to draw this frame (set by the
/// techniques' own systems). A view has caustics work when any has, or when the
/// application injects irradiance into it.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ActiveCausticTechniques {
    /// The warped volumes have volumes to draw.
    pub warped_volumes: bool,
    /// A pool is lit by convolution.
    pub convolution: bool,
    /// The caustic maps have a light view to draw.
    pub hierarchical_maps: bool,
    /// The illumination textures have a frame to draw.
    pub illumination_textures: bool,
}

impl ActiveCausticTechniques {
    /// Whether any technique has work.
    pub fn any(&self) -> bool {
        self.warped_volumes || self.convolution || self.hierarchical_maps || self.illumination_textures
    }
}

/// Render world: this view has caustics work this frame, with its camera's settings.
#[derive(Component, Clone, Copy)]
pub struct ViewCausticWork(pub Caustics);

/// The most media the passes read (the first visible ones).
pub const MAX_MEDIA: usize = 4;

/// A [`ParticipatingMedium`] as the shaders read it (`Medium` in `receiver.wgsl`): the
/// unit cube `[-½, ½]³` of its entity's transform, σₜ per channel, and (σₛ, g).
#[derive(Clone, Copy, Default, PartialEq, ShaderType)]
pub struct GpuMedium {
    pub(crate) local_from_world: Mat4,
    pub(crate) extinction: Vec4,
    pub(crate) coefficients: Vec4,
}

impl GpuMedium {
    /// Whether it dims every channel alike.
    pub fn is_grey(&self) -> bool {
        self.extinction.x == self.extinction.y && self.extinction.y == self.extinction.z
    }
}

/// Render world: the visible valid media of this frame, at most [`MAX_MEDIA`].
#[derive(Resource, Default)]
pub struct ExtractedMedia(pub Vec<GpuMedium>);

impl ExtractedMedia {
    /// The media padded to the shaders' fixed array, and how many there are.
    pub fn padded(&self) -> ([GpuMedium; MAX_MEDIA], u32) {
        let mut media = [GpuMedium::default(); MAX_MEDIA];
        media[..self.0.len()].copy_from_slice(&self.0);
        (media, self.0.len() as u32)
    }
}

/// What the composite reads of a view besides its buffer (`ViewCaustics` in
/// `composite.wgsl`).
#[derive(Clone, Copy, PartialEq, ShaderType)]
struct GpuViewCaustics {
    intensity: f32,
    medium_count: u32,
    media: [GpuMedium; MAX_MEDIA],
}

/// Render world: a view's caustic irradiance buffer and its bind group for the composite.
///
/// The buffer is the size of the camera's render target, as Bevy's prepass textures
/// and main texture are, and every pass draws into the camera's viewport of it: one
/// pixel coordinate addresses the buffer, the prepasses and the view's image alike,
/// for a split-screen half or a minimap as for a full-target camera.
#[derive(Component)]
pub struct ViewCausticIrradiance {
    /// The buffer (`CAUSTIC_IRRADIANCE_FORMAT`), the size of the view's target.
    pub texture: CachedTexture,
    /// What the composite binds of it: the buffer and the view's settings.
    pub bind_group: BindGroup,
    /// The camera's viewport, `None` for the whole target.
    pub viewport: Option<Viewport>,
    /// What the composite reads besides the buffer, kept across frames with
    /// `bind_group` while the buffer's texture stays the same.
    settings: UniformBuffer<GpuViewCaustics>,
}

impl ViewCausticIrradiance {
    /// A render pass that adds to the buffer (with a pipeline from
    /// [`projection_pipeline`]), keeping what the techniques before it wrote, within
    /// the camera's viewport.
    pub fn accumulate<'a>(&self, encoder: &'a mut CommandEncoder, label: &'static str) -> wgpu::RenderPass<'a> {
        let mut pass = encoder.begin_render_pass(&RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[Some(RenderPassColorAttachment {
                view: &self.texture.default_view,
                depth_slice: None,
                resolve_target: None,
                ops: Operations { load: LoadOp::Load, store: StoreOp::Store },
            })],
            ..default()
        });
        self.set_viewport(&mut pass);
        pass
    }

    /// Restricts `pass` (on the buffer or on the view's target-sized textures) to the
    /// camera's viewport, as Bevy's main passes do.
    pub fn set_viewport(&self, pass: &mut wgpu::RenderPass) {
        self.set_scaled_viewport(pass, 1);
    }

    /// The camera's viewport in the buffer, in pixels: its corner and size.
    pub fn region(&self) -> (UVec2, UVec2) {
        let size = self.texture.texture.size();
        self.viewport.as_ref().map_or((UVec2::ZERO, UVec2::new(size.width, size.height)), |v| (v.physical_position, v.physical_size))
    }

    /// [`Self::set_viewport`] on a texture `scale` times smaller than the target.
    pub fn set_scaled_viewport(&self, pass: &mut wgpu::RenderPass, scale: u32) {
        if let Some(v) = &self.viewport {
            let (position, size) = (v.physical_position.as_vec2() / scale as f32, v.physical_size.as_vec2() / scale as f32);
            pass.set_viewport(position.x, position.y, size.x, size.y, v.depth.start, v.depth.end);
        }
    }
}

/// A technique's compute kernels: one pipeline per entry point of `shader`, each with
/// `layout`, labelled `{prefix}_{entry}`.
pub fn compute_pipelines<const N: usize>(
    cache: &PipelineCache,
    prefix: &str,
    layout: &BindGroupLayoutDescriptor,
    shader: &Handle<Shader>,
    entries: [&'static str; N],
) -> [CachedComputePipelineId; N] {
    entries.map(|entry| {
        cache.queue_compute_pipeline(ComputePipelineDescriptor {
            label: Some(format!("{prefix}_{entry}").into()),
            layout: vec![layout.clone()],
            shader: shader.clone(),
            entry_point: Some(entry.into()),
            ..default()
        })
    })
}

/// The key bits of a mesh instance that the plugin's passes draw with Bevy's mesh bind
/// group ([`mesh_layout`]): its topology, and [`MeshPipelineKey::LIGHTMAPPED`] where it
/// has a lightmap; `None` for a skinned or morphed mesh, whose bind group binds joints
/// or morph targets that those passes' vertex stages do not read.
pub fn mesh_key(instance: &RenderMeshQueueData, mesh: &RenderMesh) -> Option<MeshPipelineKey> {
    if mesh.layout.0.contains(Mesh::ATTRIBUTE_JOINT_INDEX) || mesh.has_morph_targets() {
        return None;
    }
    let lightmapped = if instance.lightmap_slab_index().is_some() { MeshPipelineKey::LIGHTMAPPED } else { MeshPipelineKey::NONE };
    Some(MeshPipelineKey::from_primitive_topology_and_strip_index(mesh.primitive_topology(), mesh.index_format()) | lightmapped)
}

/// The layout of the mesh bind group that Bevy's `SetMeshBindGroup` binds for a mesh
/// of `key` that is neither skinned nor morphed: the model alone, or with a lightmap.
pub fn mesh_layout(mesh_pipeline: &MeshPipeline, key: MeshPipelineKey) -> BindGroupLayoutDescriptor {
    let layouts = &mesh_pipeline.mesh_layouts;
    if key.contains(MeshPipelineKey::LIGHTMAPPED) { layouts.lightmapped.clone() } else { layouts.model_only.clone() }
}

/// A single-sampled 2D texture of `size` from Bevy's texture cache, which hands a view
/// the same texture frame after frame while its descriptor stays the same.
pub fn cached_texture(
    cache: &mut TextureCache,
    device: &RenderDevice,
    label: &'static str,
    size: UVec2,
    format: TextureFormat,
    usage: TextureUsages,
) -> CachedTexture {
    let size = Extent3d { width: size.x, height: size.y, depth_or_array_layers: 1 };
    let descriptor =
        TextureDescriptor { label: Some(label), size, mip_level_count: 1, sample_count: 1, dimension: TextureDimension::D2, format, usage, view_formats: &[] };
    cache.get(device, descriptor)
}

/// A technique's fullscreen pass that adds the irradiance it computes at each pixel's
/// receiver point to the view's buffer: `layout`, the fragment entry point `project`
/// of `shader` (with `MULTISAMPLED` defined for a multisampled prepass), additive
/// blending.
pub fn projection_pipeline(
    label: &'static str,
    layout: &BindGroupLayoutDescriptor,
    shader: &Handle<Shader>,
    fullscreen: &FullscreenShader,
    multisampled: bool,
) -> RenderPipelineDescriptor {
    let shader_defs = if multisampled { vec!["MULTISAMPLED".into()] } else { vec![] };
    let additive = BlendComponent { src_factor: BlendFactor::One, dst_factor: BlendFactor::One, operation: BlendOperation::Add };
    RenderPipelineDescriptor {
        label: Some(label.into()),
        layout: vec![layout.clone()],
        vertex: fullscreen.to_vertex_state(),
        fragment: Some(FragmentState {
            shader: shader.clone(),
            shader_defs,
            entry_point: Some("project".into()),
            targets: vec![Some(ColorTargetState {
                format: CAUSTIC_IRRADIANCE_FORMAT,
                blend: Some(BlendState { color: additive, alpha: additive }),
                write_mask: ColorWrites::ALL,
            })],
        }),
        ..default()
    }
}

/// Render world: a view's pipeline for technique `P`'s fullscreen projection
/// ([`projection_pipeline`], for a single-sampled or multisampled prepass).
#[derive(Component)]
pub struct ViewProjectionPipeline<P: 'static> {
    /// The pipeline, specialised for the view.
    pub pipeline: CachedRenderPipelineId,
    /// Whether the view's prepass is multisampled.
    pub multisampled: bool,
    technique: PhantomData<fn() -> P>,
}

/// What a projection binds of its view: the pipeline, the prepass's depth (and normal,
/// where the prepass has one), the view uniform and the bind group layout that fits the
/// prepass's sampling.
pub struct ProjectionInputs<'a> {
    /// The projection's pipeline.
    pub pipeline: &'a RenderPipeline,
    /// The prepass's depth.
    pub depth: &'a TextureView,
    /// The prepass's normals, where it has them.
    pub normal: Option<&'a TextureView>,
    /// The view uniform.
    pub view: BindingResource<'a>,
    /// The buffer the view uniform lies in.
    pub view_buffer: &'a Buffer,
    /// The layout that fits the prepass's sampling.
    pub layout: &'a BindGroupLayout,
}

impl<P: 'static> ViewProjectionPipeline<P> {
    /// The inputs to bind, `layouts` the technique's `[single-sampled, multisampled]`
    /// ones; `None` until the pipeline, the depth prepass and the view uniform exist.
    pub fn inputs<'a>(
        &self,
        cache: &'a PipelineCache,
        prepass: &'a ViewPrepassTextures,
        view_uniforms: &'a ViewUniforms,
        layouts: &'a [KeptLayout; 2],
    ) -> Option<ProjectionInputs<'a>> {
        Some(ProjectionInputs {
            pipeline: cache.get_render_pipeline(self.pipeline)?,
            depth: prepass.depth_view()?,
            normal: prepass.normal_view(),
            view: view_uniforms.uniforms.binding()?,
            view_buffer: view_uniforms.uniforms.buffer()?,
            layout: layouts[self.multisampled as usize].get(cache),
        })
    }
}

impl ProjectionInputs<'_> {
    /// A source's bind group for `view`: these inputs and `source` (the source's own
    /// buffers and views), kept in the source's `kept` while it binds the same.
    /// `exists` says which views still exist.
    pub fn bind_group(
        &self,
        kept: &mut ViewBindGroups,
        (view, exists): (Entity, impl Fn(Entity) -> bool),
        source: &[Bound],
        make: impl FnOnce() -> BindGroup,
    ) -> BindGroup {
        let inputs = [self.layout.into(), self.view_buffer.into(), self.depth.into()].into_iter().chain(self.normal.map(Bound::from));
        let bound: Vec<Bound> = inputs.chain(source.iter().copied()).collect();
        kept.get(view, exists, &bound, make)
    }
}

/// What a technique's projection system reads of a view: its caustics buffer, prepass,
/// view uniform offset and `P`'s pipeline.
pub type ProjectionView<P> = (&'static ViewCausticIrradiance, &'static ViewPrepassTextures, &'static ViewUniformOffset, &'static ViewProjectionPipeline<P>);

/// What every technique's projection system reads besides its view and its own
/// resources: which views still have `P`'s pipeline, the pipeline cache, the view
/// uniforms and the pass recorder.
#[derive(SystemParam)]
pub struct ProjectionContext<'w, 's, P: 'static> {
    views: Query<'w, 's, (), With<ViewProjectionPipeline<P>>>,
    cache: Res<'w, PipelineCache>,
    view_uniforms: Res<'w, ViewUniforms>,
    /// Where the projection records that it ran.
    pub recorder: Res<'w, PassRecorder>,
}

impl<P: 'static> ProjectionContext<'_, '_, P> {
    /// The view's inputs ([`ViewProjectionPipeline::inputs`]).
    pub fn inputs<'a>(
        &'a self,
        pipeline: &ViewProjectionPipeline<P>,
        prepass: &'a ViewPrepassTextures,
        layouts: &'a [KeptLayout; 2],
    ) -> Option<ProjectionInputs<'a>> {
        pipeline.inputs(&self.cache, prepass, &self.view_uniforms, layouts)
    }

    /// Whether `view` still has `P`'s pipeline (its kept bind groups stay).
    pub fn exists(&self, view: Entity) -> bool {
        self.views.contains(view)
    }
}

/// Views with caustics work, and the projection pipeline of `P` each had last frame.
type ProjectionViews<'w, 's, P> = Query<'w, 's, (Entity, &'static Msaa, Option<&'static mut ViewProjectionPipeline<P>>), With<ViewCausticWork>>;

/// Specializes `P`'s projection pipeline for every view with caustics work; scheduled
/// by each technique with a run condition for when it has something to project.
pub fn prepare_projection_pipelines<P: SpecializedRenderPipeline<Key = bool> + Resource>(
    mut commands: Commands,
    mut views: ProjectionViews<P>,
    pipelines: Res<P>,
    mut specialized: ResMut<SpecializedRenderPipelines<P>>,
    cache: Res<PipelineCache>,
) {
    for (entity, msaa, kept) in &mut views {
        let multisampled = msaa.samples() > 1;
        let pipeline = specialized.specialize(&cache, &pipelines, multisampled);
        match kept {
            Some(mut kept) => (kept.pipeline, kept.multisampled) = (pipeline, multisampled),
            None => {
                commands.entity(entity).insert(ViewProjectionPipeline::<P> { pipeline, multisampled, technique: PhantomData });
            }
        }
    }
}

impl ViewCausticIrradiance {
    /// A technique's projection into the buffer: one fullscreen triangle per bind group
    /// (a light view, a pool, a light's planes) with `pipeline`, `view_offset` the
    /// view uniform's, in a render pass named `label`, timed as the span `span` and
    /// recorded in the report as `pass`. Nothing without bind groups.
    pub fn project(
        &self,
        ctx: &mut RenderContext,
        pipeline: &RenderPipeline,
        bind_groups: &[BindGroup],
        view_offset: u32,
        (label, span, pass): (&'static str, &'static str, &'static str),
        recorder: &PassRecorder,
    ) {
        if bind_groups.is_empty() {
            return;
        }
        let diagnostics = ctx.diagnostic_recorder();
        let diagnostics = diagnostics.as_deref();
        let mut render_pass = self.accumulate(ctx.command_encoder(), label);
        let timed = diagnostics.pass_span(&mut render_pass, span);
        render_pass.set_pipeline(pipeline);
        for bind_group in bind_groups {
            render_pass.set_bind_group(0, bind_group, &[view_offset]);
            render_pass.draw(0..3, 0..1);
        }
        timed.end(&mut render_pass);
        recorder.record(pass);
    }
}

/// Render world: a receiver's albedo as its `StandardMaterial` defines it.
#[derive(Clone, Copy, Debug)]
struct ReceiverAlbedo {
    base_color: LinearRgba,
    texture: Option<AssetId<Image>>,
    uv_transform: Mat3,
    /// `StandardMaterial::fog_enabled`: the view's `DistanceFog` dims the caustics too.
    fog_enabled: bool,
}

/// Render world: the receivers of this frame, by main-world entity.
#[derive(Resource, Default)]
struct ExtractedReceivers(HashMap<MainEntity, ReceiverAlbedo>);

pub(crate) fn build(app: &mut App) {
    bevy::asset::embedded_asset!(app, "composite.wgsl");
    bevy::asset::embedded_asset!(app, "inject.wgsl");
    bevy::shader::load_shader_library!(app, "receiver.wgsl");
    bevy::shader::load_shader_library!(app, "receiver_view.wgsl");
    bevy::shader::load_shader_library!(app, "optics.wgsl");
    bevy::shader::load_shader_library!(app, "triangle_bvh.wgsl");
    #[cfg(feature = "warped-volumes")]
    bevy::asset::embedded_asset!(app, "bvh_refit.wgsl");
    let cpu = crate::CausticCpuTime::of(app);
    app.register_type::<InjectedIrradiance>()
        .init_resource::<ActiveCausticTechniques>()
        .init_resource::<mesh_bvhs::MeshBvhs>()
        .add_systems(
            PostUpdate,
            (
                timed(&cpu.main, warn_receivers_with_unread_material),
                timed(&cpu.main, mesh_bvhs::forget_changed_meshes).before(crate::CausticSystems::ReadScene),
            ),
        )
        .add_plugins(CausticReceiverMaterialPlugin::<StandardMaterial>::default())
        .add_plugins(ExtractComponentPlugin::<InjectedIrradiance>::default());
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<ExtractedReceivers>()
        .init_resource::<ExtractedMedia>()
        .add_systems(RenderStartup, (composite::init_pipeline.after(bevy::pbr::MeshPipelineSystems), init_inject_pipeline))
        .add_systems(ExtractSchedule, (timed(&cpu.render, start_receivers), timed(&cpu.render, extract_media), timed(&cpu.render, mark_views_with_work)))
        .add_systems(
            Render,
            (
                timed(&cpu.render, composite::queue).in_set(RenderSystems::Queue),
                timed(&cpu.render, prepare_irradiance_buffers).in_set(RenderSystems::PrepareResources),
                timed(&cpu.render, composite::prepare_receiver_bind_groups).in_set(RenderSystems::PrepareBindGroups),
            ),
        )
        .add_systems(Core3d, timed(&cpu.render, inject_irradiance).after(Core3dSystems::Prepass).before(Core3dSystems::MainPass));
    composite::build(app);
    reference_view::build(app);
}

/// A material whose receivers' albedo the composite reads: its `StandardMaterial`
/// part's base colour, texture and UV transform.
pub trait ReceiverMaterial: Material {
    /// Its `StandardMaterial` part.
    fn standard(&self) -> &StandardMaterial;
}

impl ReceiverMaterial for StandardMaterial {
    fn standard(&self) -> &StandardMaterial {
        self
    }
}

impl<E: MaterialExtension> ReceiverMaterial for ExtendedMaterial<StandardMaterial, E> {
    fn standard(&self) -> &StandardMaterial {
        &self.base
    }
}

/// Lets the composite read the albedo of receivers drawn with `M`; without it a
/// receiver with that material shows its caustics on white and says so once. The
/// [`crate::CausticsPlugin`] adds it for `StandardMaterial`; a game whose receivers use
/// `ExtendedMaterial<StandardMaterial, MyExtension>` adds
/// `CausticReceiverMaterialPlugin::<ExtendedMaterial<StandardMaterial, MyExtension>>::default()`.
pub struct CausticReceiverMaterialPlugin<M: ReceiverMaterial>(PhantomData<M>);

impl<M: ReceiverMaterial> Default for CausticReceiverMaterialPlugin<M> {
    fn default() -> Self {
        Self(PhantomData)
    }
}

impl<M: ReceiverMaterial> Plugin for CausticReceiverMaterialPlugin<M> {
    fn build(&self, app: &mut App) {
        let component = app.world_mut().register_component::<MeshMaterial3d<M>>();
        app.init_resource::<ReadableReceiverMaterials>().world_mut().resource_mut::<ReadableReceiverMaterials>().0.push(component);
        let cpu = crate::CausticCpuTime::of(app).render;
        if let Some(render_app) = app.get_sub_app_mut(RenderApp) {
            render_app.add_systems(ExtractSchedule, timed(&cpu, extract_receiver_albedo::<M>).after(start_receivers));
        }
    }
}

/// The `MeshMaterial3d<M>` components whose albedo the composite reads.
#[derive(Resource, Default)]
pub struct ReadableReceiverMaterials(Vec<ComponentId>);

/// Warns once per receiver mesh whose material the composite cannot read (none, or a
/// material without a [`CausticReceiverMaterialPlugin`]): it shows its caustics on white.
pub fn warn_receivers_with_unread_material(
    receivers: Query<(Entity, EntityRef), (With<CausticReceiver>, With<Mesh3d>)>,
    readable: Option<Res<ReadableReceiverMaterials>>,
    mut warned: Local<HashSet<Entity>>,
) {
    let readable = readable.as_deref().map_or(&[][..], |r| &r.0[..]);
    for (entity, components) in &receivers {
        if !readable.iter().any(|&id| components.contains_id(id)) && warned.insert(entity) {
            warn!(
                "bevy_caustics: CausticReceiver {entity} has a material the composite cannot read: its caustics are shown with albedo 1 (add CausticReceiverMaterialPlugin for its material)"
            );
        }
    }
}

/// Valid receivers.
type ValidReceivers = (With<CausticReceiver>, Without<InvalidCausticParams>);

/// Starts the frame's receivers: every valid one, on white until its material is read.
fn start_receivers(mut extracted: ResMut<ExtractedReceivers>, receivers: Extract<Query<Entity, ValidReceivers>>) {
    extracted.0.clear();
    let white = ReceiverAlbedo { base_color: LinearRgba::WHITE, texture: None, uv_transform: Mat3::IDENTITY, fog_enabled: true };
    extracted.0.extend(receivers.iter().map(|entity| (MainEntity::from(entity), white)));
}

/// Receivers drawn with `M`.
type ReceiversOf<M> = Query<'static, 'static, (Entity, &'static MeshMaterial3d<M>), With<CausticReceiver>>;

/// Reads the albedo of the receivers drawn with `M`.
fn extract_receiver_albedo<M: ReceiverMaterial>(
    mut extracted: ResMut<ExtractedReceivers>,
    receivers: Extract<ReceiversOf<M>>,
    materials: Extract<Res<Assets<M>>>,
) {
    for (entity, material) in &receivers {
        let (Some(albedo), Some(m)) = (extracted.0.get_mut(&MainEntity::from(entity)), materials.get(&material.0)) else {
            continue;
        };
        let m = m.standard();
        *albedo = ReceiverAlbedo {
            base_color: m.base_color.to_linear(),
            texture: m.base_color_texture.as_ref().map(Handle::id),
            uv_transform: Mat3::from(m.uv_transform),
            fog_enabled: m.fog_enabled,
        };
    }
}

/// Valid media and whether they are visible.
pub type MediumQuery =
    Query<'static, 'static, (&'static ParticipatingMedium, &'static GlobalTransform, &'static InheritedVisibility), Without<InvalidCausticParams>>;

fn extract_media(mut extracted: ResMut<ExtractedMedia>, media: Extract<MediumQuery>) {
    extracted.0 = media
        .iter()
        .filter(|(.., visible)| visible.get())
        .take(MAX_MEDIA)
        .map(|(m, t, _)| GpuMedium {
            local_from_world: t.to_matrix().inverse(),
            extinction: m.coefficients().extinction().extend(0.0),
            coefficients: Vec4::new(m.scattering, m.asymmetry, 0.0, 0.0),
        })
        .collect();
}

/// 3D cameras: their caustics settings, whether they have injected irradiance and
/// whether they render HDR.
type CameraQuery = Query<'static, 'static, (Entity, RenderEntity, Option<&'static Caustics>, Has<InjectedIrradiance>, Has<Hdr>), With<Camera3d>>;

/// A view has caustics work when its camera opted in with [`Caustics`] and the
/// application injects irradiance into it or a technique has something to draw.
/// Caustics are added to the linear HDR image before tonemapping, so the camera needs
/// [`Hdr`] (which `Caustics` requires; a camera that removed it is reported
/// once and skipped). Injected irradiance on a camera that did not opt in is reported
/// once too.
fn mark_views_with_work(
    mut commands: Commands,
    views: Extract<CameraQuery>,
    active: Extract<Res<ActiveCausticTechniques>>,
    mut warned: Local<HashSet<Entity>>,
) {
    for (main_entity, render_entity, settings, injected, hdr) in &views {
        let mut entity = commands.entity(render_entity);
        let has_work = injected || active.any();
        match settings {
            Some(settings) if has_work && hdr => {
                entity.insert(ViewCausticWork(*settings));
            }
            _ => {
                entity.remove::<(ViewCausticWork, ViewCausticIrradiance)>();
            }
        }
        let problem = match (settings.is_some(), hdr) {
            (true, false) if has_work => Some("has Caustics but no `Hdr` component; add `Hdr` to see caustics"),
            (false, _) if injected => Some("has InjectedIrradiance but no Caustics; add Caustics to see it"),
            _ => None,
        };
        if let Some(problem) = problem
            && warned.insert(main_entity)
        {
            warn!("bevy_caustics: camera {main_entity} {problem}");
        }
    }
}

/// The views' caustics buffers, and whether Bevy's volumetric fog draws the media there.
type IrradianceViews =
    (Entity, &'static ExtractedCamera, &'static ViewCausticWork, Option<&'static mut ViewCausticIrradiance>, Has<bevy::light::VolumetricFog>);

#[expect(clippy::too_many_arguments)]
fn prepare_irradiance_buffers(
    mut commands: Commands,
    mut views: Query<IrradianceViews>,
    media: Res<ExtractedMedia>,
    mut texture_cache: ResMut<TextureCache>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    pipeline: Res<CausticCompositePipeline>,
    pipeline_cache: Res<PipelineCache>,
) {
    let (padded_media, medium_count) = media.padded();
    for (entity, camera, work, kept, bevy_fog) in &mut views {
        let Some(size) = camera.physical_target_size.filter(|s| s.x > 0 && s.y > 0) else {
            continue;
        };
        // COPY_SRC: tools read it back (`HeadlessRenderer::caustic_irradiance`).
        let usage = TextureUsages::TEXTURE_BINDING | TextureUsages::RENDER_ATTACHMENT | TextureUsages::COPY_SRC;
        let texture = cached_texture(&mut texture_cache, &device, "caustic_irradiance", size, CAUSTIC_IRRADIANCE_FORMAT, usage);
        // Where Bevy's volumetric fog draws the media (`medium_fog.rs`), it dims the
        // caustics with the rest of the pixel.
        let medium_count = if bevy_fog { 0 } else { medium_count };
        let value = GpuViewCaustics { intensity: work.0.applied_intensity(), medium_count, media: padded_media };
        let viewport = camera.viewport.clone();
        // The same texture as last frame: the bind group stands, the settings are
        // uploaded only when they changed.
        if let Some(mut kept) = kept.filter(|kept| kept.texture.default_view.id() == texture.default_view.id()) {
            kept_bind_group::write_changed(&mut kept.settings, value, &device, &queue);
            kept.viewport = viewport;
            continue;
        }
        let mut settings = UniformBuffer::from(value);
        settings.set_label(Some("caustic_view_settings"));
        settings.write_buffer(&device, &queue);
        let Some(binding) = settings.binding() else { continue };
        let bind_group = device.create_bind_group(
            "caustic_irradiance_bind_group",
            pipeline.view_layout.get(&pipeline_cache),
            &BindGroupEntries::sequential((&texture.default_view, binding)),
        );
        commands.entity(entity).insert(ViewCausticIrradiance { texture, bind_group, viewport, settings });
    }
}

/// The pipeline that starts a view's buffer from [`InjectedIrradiance`].
#[derive(Resource)]
pub(crate) struct InjectPipeline {
    layout: KeptLayout,
    pipeline: CachedRenderPipelineId,
}

fn init_inject_pipeline(mut commands: Commands, asset_server: Res<AssetServer>, fullscreen: Res<FullscreenShader>, pipeline_cache: Res<PipelineCache>) {
    let layout = BindGroupLayoutDescriptor::new(
        "caustic_inject_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::FRAGMENT,
            (texture_2d(TextureSampleType::Float { filterable: false }), uniform_buffer::<ViewUniform>(true)),
        ),
    );
    let pipeline = pipeline_cache.queue_render_pipeline(RenderPipelineDescriptor {
        label: Some("caustic_inject_pipeline".into()),
        layout: vec![layout.clone()],
        vertex: fullscreen.to_vertex_state(),
        fragment: Some(FragmentState {
            shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "inject.wgsl"),
            targets: vec![Some(ColorTargetState { format: CAUSTIC_IRRADIANCE_FORMAT, blend: None, write_mask: ColorWrites::ALL })],
            ..default()
        }),
        ..default()
    });
    commands.insert_resource(InjectPipeline { layout: KeptLayout::new(layout), pipeline });
}

impl InjectPipeline {
    /// Draws `image` (irradiance, resampled to the view) over what `pass` covers of the
    /// view's buffer, replacing it; false when the pipeline or the image is not ready.
    pub(crate) fn draw(
        &self,
        pass: &mut wgpu::RenderPass,
        image: Option<&GpuImage>,
        view_offset: &ViewUniformOffset,
        (device, cache, view_uniforms): (&RenderDevice, &PipelineCache, &ViewUniforms),
    ) -> bool {
        let (Some(pipeline), Some(image), Some(view_binding)) = (cache.get_render_pipeline(self.pipeline), image, view_uniforms.uniforms.binding()) else {
            return false;
        };
        let bind_group =
            device.create_bind_group("caustic_inject_bind_group", self.layout.get(cache), &BindGroupEntries::sequential((&image.texture_view, view_binding)));
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &bind_group, &[view_offset.offset]);
        pass.draw(0..3, 0..1);
        true
    }
}

/// Starts the view's buffer for this frame: the injected irradiance times exposure, or zero.
pub(crate) fn inject_irradiance(
    view: ViewQuery<(&ViewCausticIrradiance, &ViewUniformOffset, Option<&InjectedIrradiance>)>,
    images: Res<RenderAssets<GpuImage>>,
    inject: Res<InjectPipeline>,
    pipeline_cache: Res<PipelineCache>,
    view_uniforms: Res<ViewUniforms>,
    recorder: Res<PassRecorder>,
    mut ctx: RenderContext,
) {
    let (buffer, view_offset, injected) = view.into_inner();
    let source = injected.and_then(|i| images.get(&i.0));
    let device = ctx.render_device().clone();
    let mut pass = ctx.command_encoder().begin_render_pass(&RenderPassDescriptor {
        label: Some("caustic_irradiance_inject"),
        color_attachments: &[Some(RenderPassColorAttachment {
            view: &buffer.texture.default_view,
            depth_slice: None,
            resolve_target: None,
            ops: Operations { load: LoadOp::Clear(Default::default()), store: StoreOp::Store },
        })],
        ..default()
    });
    buffer.set_viewport(&mut pass);
    if inject.draw(&mut pass, source, view_offset, (&device, &pipeline_cache, &view_uniforms)) {
        recorder.record("inject");
    }
}

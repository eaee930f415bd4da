//! Warped caustic volumes (Ernst, Akenine-Möller & Jensen 2005).
//!
//! Every generator triangle lit by a light bounds a *caustic volume*: the three rays
//! `vⁱ + t rⁱ` reflected or refracted at its vertices with the vertex normals (§3).
//! Its side surfaces are bilinear patches, not planes (§3.2, Fig. 2), so adjacent
//! volumes share their sides exactly and leave no gaps. In the volume's local frame
//! (y along the triangle normal, vertex y = 0, ray y = 1; Fig. 3) a point `p′` lies in
//! the plane `y = α` of the caustic triangle `cⁱ = vⁱ + α rⁱ`; it is inside when its
//! three unnormalised barycentric coordinates βᵢ share a sign (§3.3), and the
//! irradiance there is the flux through the generator triangle over the area of the
//! caustic triangle, `A(α) = a + bα + cα²` (§3.4). The interpolated variant replaces
//! that constant per-triangle ratio by one per vertex, from the flattened triangle fan
//! around the vertex (Fig. 5), blended with the βᵢ.
//!
//! Beyond the paper:
//! - flux is weighted per vertex by the light's irradiance, the cosine on the triangle
//!   and the Fresnel reflectance or transmittance (the paper's `I` is the ratio of areas
//!   alone);
//! - the magnification `a/A(α)` is clamped at [`VolumeSettings::max_magnification`] so
//!   that focal points, where `A(α) → 0`, give finite irradiance; `|A|` is used past a
//!   focus, where the caustic triangle turns over;
//! - volumes whose rays are lost to total internal reflection or leave at grazing angles
//!   are dropped and their flux counted in [`BuildStats`], never kept as garbage;
//! - the bounding prism of §4.3 falls back to a box in the volume's frame when no tight
//!   plane exists or the box is smaller ([`BoundingShape`]);
//! - in a medium, the eye ray's path through the warped volume is found exactly (the
//!   roots of three quadratics) rather than by the paper's straight-edged scan-plane
//!   triangle (§3.5), and extinction along the beam uses σₜ, not σₛ;
//! - occluders: a vertex hidden from the light carries no flux, and each vertex ray
//!   ends on the first surface it meets ([`CausticVolume::hit_planes`]), so a box
//!   standing in the caustic casts its caustic shadow (§3.1 lights every receiver
//!   point inside a volume).
//!
//! [`VolumeSet::irradiance_at`] is the CPU twin of the GPU pass in `caustics_bevy`.

mod beam_grid;
mod build;
mod medium;
mod prism;

pub use beam_grid::{
    BeamGrid, MAX_DEPOSIT_LAYERS, MAX_DEPOSIT_SPLIT, ThinBeam, cell_of, deposit_barycentric, deposit_split, direction_blocks, grid_size, march_steps,
};
pub use build::{BuildStats, VertexFans, build_drawn_volumes, build_generator_volumes, build_scene_volumes, channels, occluders_of};
pub use medium::{MAX_RAY_PIECES, MediumBox, in_scattered_radiance, mean_attenuation, ray_pieces};
pub use prism::{BoundingShape, HEXAHEDRON_TRIANGLES};

use crate::scene::range_window;
use glam::{Vec3, Vec4};

/// Half-width, in barycentric units, of the band along a shared side that only the
/// side's owner counts: wider than the rounding of two volumes' different frames and
/// of a point rebuilt from a depth buffer, far narrower than a pixel.
pub const EDGE_EPSILON: f32 = 1.0e-4;

/// How far behind the surface a vertex ray meets a point must lie to be in its
/// shadow, as a fraction of the hit's depth α: receiver points rebuilt from a depth
/// buffer, and curved receivers between the tangent planes at three hits, lie within
/// it; occluders nearer a receiver than this (1 cm per metre) cast no caustic shadow.
pub const OCCLUSION_SLACK: f32 = 1.0e-2;

/// The hit plane of a vertex ray that meets no surface: nothing lies behind it.
pub const NO_HIT_PLANE: Vec4 = Vec4::W;

/// How irradiance varies inside one caustic triangle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum IntensityMode {
    /// The paper's interpolation (§3.4): `I = Σβᵢwᵢāᵢ / ΣβᵢĀᵢ(α)`, the per-vertex fan
    /// area functions blended with the βᵢ. Smooth, but near focal lines, where a fan's
    /// signed area passes through zero, it overshoots the flux the triangle carries.
    Interpolated,
    /// The per-vertex fan intensities `Iᵢ = wᵢāᵢ/Āᵢ(α)` blended linearly and scaled so
    /// that their mean over the caustic triangle is the constant intensity: as smooth
    /// as [`Self::Interpolated`] where the fans are well behaved, and energy-conserving
    /// per volume everywhere (a linear function's mean over a triangle is the mean of
    /// its corner values).
    #[default]
    Conserving,
    /// One area ratio `a / A(α)` per triangle, as in earlier work: blocky caustics.
    Constant,
}

/// Settings shared by the CPU twin and the GPU pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VolumeSettings {
    /// How irradiance varies inside one caustic triangle.
    pub intensity: IntensityMode,
    /// Upper bound of the magnification `a / A(α)`. Irradiance at an exact focus is
    /// infinite, and a point sample that lands in a caustic triangle a thousandth of
    /// its generator's size carries a thousand times its irradiance: a heavy tail that
    /// makes single pixels (or bench cells) flash. Slices beyond the cap (caustic
    /// triangles smaller than 1/cap of their generator) are left out. The default,
    /// 1000, keeps the flux on a large floor within half a percent on the pool and the
    /// ring scenes (100 lost 3.6 % of the pool's, whose floor lies at the waves' focus).
    pub max_magnification: f32,
    /// Smallest cosine between a vertex ray and the triangle normal; volumes with a
    /// flatter ray (grazing light) are dropped, since their scaled rays (`r_y = 1`)
    /// would be unbounded.
    pub min_ray_cosine: f32,
    /// Whether a pixel given its [`Footprint`] shows the mean irradiance over it
    /// ([`CausticVolume::irradiance_over`]) rather than the point sample at its centre
    /// (the default, `true`). Irradiance at a focal line is unbounded in ever thinner
    /// regions (§3.4), so a point sample aliases there: one pixel catches a caustic
    /// triangle a hundredth of its size at a hundred times the light, its neighbour
    /// none, and the image sparkles as the generator moves. The mean over the footprint
    /// is what the pixel can show, and keeps the flux.
    pub footprint_filter: bool,
}

impl Default for VolumeSettings {
    fn default() -> Self {
        Self { intensity: IntensityMode::default(), max_magnification: 1000.0, min_ray_cosine: 1.0e-3, footprint_filter: true }
    }
}

/// How far a pixel's footprint may stretch along a receiver seen at a slant, as a
/// multiple of its size across the eye ray: past about 83° from the normal the
/// footprint stops growing, so that a grazing view does not average a pixel over
/// metres.
pub const MAX_FOOTPRINT_STRETCH: f32 = 8.0;

/// A pixel's footprint on its receiver: the parallelogram `p + u·du + v·dv`,
/// `u, v ∈ [−½, ½]`, around the receiver point `p` seen at the pixel's centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    /// The step of one pixel to the right, on the receiver.
    pub du: Vec3,
    /// The step of one pixel down, on the receiver.
    pub dv: Vec3,
}

impl Footprint {
    /// The footprint on the receiver's tangent plane (unit normal `n`) of a pixel whose
    /// eye ray runs along `eye` (unit) to `p`, from the steps `across_u` and `across_v`
    /// of one pixel between neighbouring eye rays at `p`'s depth: each step carried
    /// along the eye ray onto the plane, at most [`MAX_FOOTPRINT_STRETCH`] times its
    /// length.
    pub fn seen(n: Vec3, eye: Vec3, across_u: Vec3, across_v: Vec3) -> Self {
        let onto_plane = |step: Vec3| {
            let cosine = eye.dot(n);
            let limit = MAX_FOOTPRINT_STRETCH * step.length();
            let along = if cosine != 0.0 { -step.dot(n) / cosine } else { 0.0 };
            step + eye * along.clamp(-limit, limit)
        };
        Self { du: onto_plane(across_u), dv: onto_plane(across_v) }
    }
}

/// The part of the unit square `u, v ∈ [−½, ½]` where the three affine functions
/// `λᵢ(u, v) = λ₀ᵢ + u·∂uᵢ + v·∂vᵢ` are all non-negative (a pixel's footprint inside a
/// caustic triangle, in the footprint's coordinates): its area (a fraction of the
/// square's) and its centroid. The part is convex, cut by seven half-planes `a + b·q ≥
/// 0` (the square's four sides and the three λᵢ ≥ 0); each one's boundary line adds
/// the stretch of it inside the other six, run counter-clockwise, to the area and
/// moment sums of the shoelace formula, which need no order of the edges. A fixed
/// amount of straight arithmetic, with no list of corners to index.
pub fn footprint_coverage(lambda: Vec3, du: Vec3, dv: Vec3) -> (f32, glam::Vec2) {
    use glam::Vec2;
    // Each λᵢ's least and greatest over the square: wholly outside, or wholly inside.
    let reach = 0.5 * (du.abs() + dv.abs());
    if (lambda + reach).cmplt(Vec3::ZERO).any() {
        return (0.0, Vec2::ZERO);
    }
    if (lambda - reach).cmpge(Vec3::ZERO).all() {
        return (1.0, Vec2::ZERO);
    }
    let planes = [
        (0.5, Vec2::X),
        (0.5, Vec2::NEG_X),
        (0.5, Vec2::Y),
        (0.5, Vec2::NEG_Y),
        (lambda.x, Vec2::new(du.x, dv.x)),
        (lambda.y, Vec2::new(du.y, dv.y)),
        (lambda.z, Vec2::new(du.z, dv.z)),
    ];
    let (mut twice_area, mut moment) = (0.0, Vec2::ZERO);
    for (k, &(a, b)) in planes.iter().enumerate() {
        let length_squared = b.length_squared();
        if length_squared == 0.0 {
            continue;
        }
        // The line a + b·q = 0, run with the inside (b) on its left.
        let origin = -a * b / length_squared;
        let along = Vec2::new(b.y, -b.x);
        let (mut enter, mut leave) = (f32::NEG_INFINITY, f32::INFINITY);
        for (j, &(aj, bj)) in planes.iter().enumerate() {
            let (at, rate) = (aj + bj.dot(origin), bj.dot(along));
            if j == k {
                continue;
            } else if rate > 0.0 {
                enter = enter.max(-at / rate);
            } else if rate < 0.0 {
                leave = leave.min(-at / rate);
            } else if at < 0.0 || (at == 0.0 && j < k) {
                // Outside a parallel side, or on the same line as an earlier one.
                leave = f32::NEG_INFINITY;
            }
        }
        if enter < leave {
            let (p, q) = (origin + enter * along, origin + leave * along);
            let cross = p.perp_dot(q);
            twice_area += cross;
            moment += (p + q) * cross;
        }
    }
    if !(twice_area > f32::EPSILON) {
        return (0.0, Vec2::ZERO);
    }
    (0.5 * twice_area, moment / (3.0 * twice_area))
}

/// One caustic volume, in the layout the GPU reads (§4.1's "vertical" vectors: the
/// three vertices' x components together, and so on).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CausticVolume {
    /// World position of the local origin (the generator triangle's vertex lowest
    /// along the slicing axis).
    pub origin: Vec3,
    /// World directions of the local x, y and z axes; y is the slicing axis (the
    /// generator's mean ray, or the triangle's normal on the side the rays leave to).
    pub axes: [Vec3; 3],
    /// Local x of the three vertices (their y is 0).
    pub vertex_x: Vec3,
    /// Local z of the three vertices.
    pub vertex_z: Vec3,
    /// Local x of the three vertex rays, scaled to `r_y = 1`.
    pub ray_x: Vec3,
    /// Local z of the three vertex rays, scaled to `r_y = 1`.
    pub ray_z: Vec3,
    /// Per-vertex area coefficients ā of the flattened fans (§3.4, Fig. 5).
    pub fan_a: Vec3,
    /// Per-vertex area coefficients b̄ of the flattened fans.
    pub fan_b: Vec3,
    /// Per-vertex area coefficients c̄ of the flattened fans.
    pub fan_c: Vec3,
    /// The triangle's own area coefficients (a, b, c) for the constant mode.
    pub triangle_abc: Vec3,
    /// The generator triangle's normal on the side the rays leave to: the volume
    /// starts at the triangle, `(p − origin)·n ≥ 0`, when the slices are not parallel
    /// to it.
    pub surface_normal: Vec3,
    /// Which sides (opposite vertex 0, 1, 2) this volume owns: a point on a side
    /// shared with a neighbour (within [`EDGE_EPSILON`]) counts for one of the two only,
    /// as a rasteriser's fill rule does for pixels on shared edges.
    pub owned_edges: [bool; 3],
    /// Per-vertex flux weight: the irradiance crossing the triangle's plane at the
    /// vertex (light irradiance × cosine × Fresnel term).
    pub flux: Vec3,
    /// Linear RGB scale of the flux (the light's colour, or one channel of it).
    pub color: Vec3,
    /// Per vertex, the light's path length to the vertex moved into the plane y = 0
    /// (0 for a directional light); with `inverse_range_squared` (0: no range) a point
    /// or spot light's range fades the caustic by its whole path, light to generator
    /// to receiver ([`crate::scene::Light::range_attenuation`]).
    pub light_distance: Vec3,
    /// `1 / range²` of a point or spot light; 0: no range.
    pub inverse_range_squared: f32,
    /// Local depth α at which the volume ends: where its rays have met the surfaces
    /// they hit (every point past is occluded), else the far side of the receivers.
    pub depth: f32,
    /// Where the rays that meet a surface land on one (the others meeting nothing),
    /// the thin slab around it: the surface pass draws the bounding shape cut to it and
    /// lights only the points inside ([`CausticVolume::irradiance`]); the in-scattering
    /// of a medium integrates the whole beam. `None` elsewhere.
    pub slab: Option<SurfaceSlab>,
    /// Per vertex, the plane tangent to the first surface its ray meets, in the local
    /// frame and facing the ray: `n·p + w < 0` behind that surface (`w` holds a slack
    /// of [`OCCLUSION_SLACK`] of the hit's depth). [`NO_HIT_PLANE`] for a ray that meets
    /// nothing.
    pub hit_planes: [Vec4; 3],
    /// The convex bounding shape rasterised on the GPU for the medium's in-scattering.
    pub bounds: BoundingShape,
    /// The convex shape the surface pass rasterises: the slice of the beam crossing
    /// the slab where there is one ([`Self::slab`]), nothing for a volume that lights
    /// no surface ([`BoundingShape::EMPTY`]), else `bounds`.
    pub surface_bounds: BoundingShape,
}

/// The slab `near ≤ normal·p ≤ far` (world space) around the one surface a caustic
/// volume's rays land on (those that meet any): the tangent planes at their hits,
/// widened by a margin for receiver points rebuilt from a depth buffer. A view at a slant crosses a beam
/// in a long sliver of pixels, and the slab in a few; the surfaces the volume lights
/// are those its rays land on, so the surface pass draws the slab alone. A receiver
/// between the generator and that surface that none of the three rays meets (smaller
/// than the caustic triangle there) gets no light from the volume, as it casts no
/// shadow in it. Likewise a volume whose rays all meet nothing lights no surface
/// ([`SurfaceSlab::EMPTY`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSlab {
    /// Unit normal, pointing the way the rays travel.
    pub normal: Vec3,
    /// Least `normal·p` in the slab.
    pub near: f32,
    /// Greatest `normal·p` in the slab.
    pub far: f32,
}

impl SurfaceSlab {
    /// The slab of a volume whose three rays meet no surface at all: it lights none.
    pub const EMPTY: Self = Self { normal: Vec3::Y, near: 1.0, far: 0.0 };

    /// Whether `p` lies in the slab.
    #[inline]
    pub fn contains(&self, p: Vec3) -> bool {
        let d = self.normal.dot(p);
        d >= self.near && d <= self.far
    }
}

/// What one volume contributes at a point: the caustic irradiance on a surface with
/// normal `n`, or nothing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VolumeSample {
    /// Irradiance on the plane parallel to the generator triangle (`E_plane`).
    pub plane_irradiance: f32,
    /// The interpolated ray in world space, scaled so that its component along the
    /// triangle normal is one (`|r|` turns plane irradiance into beam irradiance).
    pub ray: Vec3,
    /// Local depth α of the point.
    pub depth: f32,
}

impl CausticVolume {
    /// The point in the volume's local frame.
    #[inline]
    pub fn to_local(&self, p: Vec3) -> Vec3 {
        let d = p - self.origin;
        Vec3::new(d.dot(self.axes[0]), d.dot(self.axes[1]), d.dot(self.axes[2]))
    }

    /// Unnormalised barycentric coordinates βᵢ of a local point in its caustic
    /// triangle (§3.3): `β₀ = (p − c¹) × (p − c²)` and so on, in the vertical layout of
    /// §4.1. Expanded as the paper writes it, the terms are products of coordinates
    /// metres from the origin that cancel to a tiny area; from the edge vectors
    /// `p − cⁱ` they do not, which keeps the βᵢ of small caustic triangles exact
    /// enough for the fill rule on shared sides.
    #[inline]
    pub fn beta(&self, local: Vec3) -> Vec3 {
        let alpha = local.y;
        let ex = local.x - (self.vertex_x + alpha * self.ray_x);
        let ez = local.z - (self.vertex_z + alpha * self.ray_z);
        let yzx = |v: Vec3| Vec3::new(v.y, v.z, v.x);
        let zxy = |v: Vec3| Vec3::new(v.z, v.x, v.y);
        yzx(ez) * zxy(ex) - yzx(ex) * zxy(ez)
    }

    /// Normalised barycentric coordinates when the point is inside the volume
    /// (all βᵢ of one sign, `0 ≤ α ≤ depth`), `None` otherwise.
    #[inline]
    pub fn barycentric(&self, local: Vec3) -> Option<Vec3> {
        if !(local.y >= 0.0 && local.y <= self.depth) {
            return None;
        }
        if self.height(local) < 0.0 {
            return None;
        }
        let beta = self.beta(local);
        let sum = beta.x + beta.y + beta.z;
        if sum == 0.0 || !sum.is_finite() {
            return None;
        }
        let lambda = beta / sum;
        let inside = (0..3).all(|i| if self.owned_edges[i] { lambda[i] >= -EDGE_EPSILON } else { lambda[i] > EDGE_EPSILON });
        inside.then_some(lambda)
    }

    /// A local point's height above the generator triangle's plane, on the side the
    /// rays leave to: the volume starts there.
    #[inline]
    fn height(&self, local: Vec3) -> f32 {
        let n = self.surface_normal;
        local.x * self.axes[0].dot(n) + local.y * self.axes[1].dot(n) + local.z * self.axes[2].dot(n)
    }

    /// Whether a local point inside the volume, with barycentric coordinates λ, lies
    /// in the shadow of the surfaces its vertex rays meet first: behind the hit planes
    /// of vertices whose weights λᵢ sum past one half. Exact when the three rays meet
    /// one plane; a volume split by an occluder's edge splits where the weights of its
    /// two sides are equal, a first-order estimate of the edge within the volume.
    #[inline]
    pub fn occluded(&self, local: Vec3, lambda: Vec3) -> bool {
        let behind = |i: usize| self.hit_planes[i].truncate().dot(local) + self.hit_planes[i].w < 0.0;
        (0..3).filter(|&i| behind(i)).map(|i| lambda[i]).sum::<f32>() > 0.5
    }

    /// Irradiance on the slicing plane at a point inside, and the interpolated ray
    /// there (§3.4). A point sample: near a fold `E = Φ/A` grows without bound in
    /// ever smaller regions, so averages of point samples there converge slowly (but
    /// to the right flux); capping `E` per pixel would lose that flux instead.
    pub fn sample(&self, p: Vec3, settings: &VolumeSettings) -> Option<VolumeSample> {
        let local = self.to_local(p);
        let lambda = self.barycentric(local)?;
        self.sample_inside(local, lambda, settings)
    }

    /// [`Self::sample`] at the point with barycentric coordinates λ (each above the
    /// fill rule's margin) in the caustic triangle at depth α, which lies inside
    /// wherever `0 ≤ α ≤ depth` and it is above the generator triangle: the deposit's
    /// thin beams know both, so they skip the point-in-volume test.
    #[inline]
    pub fn sample_on_ray(&self, lambda: Vec3, alpha: f32, settings: &VolumeSettings) -> Option<VolumeSample> {
        let local = Vec3::new(lambda.dot(self.vertex_x + alpha * self.ray_x), alpha, lambda.dot(self.vertex_z + alpha * self.ray_z));
        if !(alpha >= 0.0 && alpha <= self.depth && self.height(local) >= 0.0) {
            return None;
        }
        self.sample_inside(local, lambda, settings)
    }

    /// [`Self::sample`] at a local point already found inside, with barycentric
    /// coordinates λ.
    fn sample_inside(&self, local: Vec3, lambda: Vec3, settings: &VolumeSettings) -> Option<VolumeSample> {
        if self.occluded(local, lambda) {
            return None;
        }
        let alpha = local.y;
        let max_mag = settings.max_magnification.max(1.0);
        let [a, b, c] = self.triangle_abc.to_array();
        let triangle_area = (a + alpha * b + alpha * alpha * c).abs();
        // Near a focus the caustic triangle shrinks to rounding noise and the βᵢ lose
        // their meaning: such slices are left out (their flux is what the clamp drops).
        if triangle_area < a / max_mag {
            return None;
        }
        let constant = (self.flux.x + self.flux.y + self.flux.z) / 3.0 * a / triangle_area;
        let plane_irradiance = match settings.intensity {
            IntensityMode::Constant => constant,
            IntensityMode::Interpolated => {
                let area = self.fan_a + alpha * self.fan_b + alpha * alpha * self.fan_c;
                let a = lambda.dot(self.fan_a);
                lambda.dot(self.flux * self.fan_a) / lambda.dot(area).abs().max(a / max_mag)
            }
            IntensityMode::Conserving => {
                // Per-vertex intensities Iᵢ = wᵢ āᵢ / Āᵢ(α) of the fans (§3.4).
                let area = (self.fan_a + alpha * self.fan_b + alpha * alpha * self.fan_c).abs();
                let vertex = self.flux * self.fan_a / area.max(self.fan_a / max_mag);
                let mean = (vertex.x + vertex.y + vertex.z) / 3.0;
                if mean > 0.0 { constant * lambda.dot(vertex) / mean } else { constant }
            }
        };
        let ray_x = lambda.dot(self.ray_x);
        let ray_z = lambda.dot(self.ray_z);
        let ray = self.axes[0] * ray_x + self.axes[1] + self.axes[2] * ray_z;
        let path = lambda.dot(self.light_distance) + alpha * ray.length();
        let plane_irradiance = plane_irradiance * range_window(path * path, self.inverse_range_squared);
        Some(VolumeSample { plane_irradiance, ray, depth: alpha })
    }

    /// Caustic irradiance on a surface at `p` with unit normal `n` facing the light:
    /// `E = E_plane · max(0, −r·n)` with `r` scaled to unit height — the flux density
    /// on the triangle-parallel plane carried onto the receiver's own plane.
    /// Points outside the volume's [`SurfaceSlab`] get none.
    pub fn irradiance(&self, p: Vec3, n: Vec3, settings: &VolumeSettings) -> Vec3 {
        if self.slab.is_some_and(|slab| !slab.contains(p)) {
            return Vec3::ZERO;
        }
        match self.sample(p, settings) {
            Some(s) => self.color * (s.plane_irradiance * (-s.ray.dot(n)).max(0.0)),
            None => Vec3::ZERO,
        }
    }

    /// The mean over a pixel's [`Footprint`] of what [`Self::irradiance`] gives, to
    /// first order: the footprint's part inside the caustic triangle (the βᵢ carried to
    /// the footprint's corners are affine across it; [`footprint_coverage`]) times the
    /// irradiance at that part's centroid (exact for an intensity linear across it).
    /// The slab is tested at `p`, every other test at the centroid. A footprint that
    /// straddles two volumes' shared side splits between them by area, so no fill rule
    /// is needed, and the light of a caustic triangle smaller than the pixel is spread
    /// over the pixel, not caught whole or missed by its centre.
    pub fn irradiance_over(&self, p: Vec3, n: Vec3, footprint: &Footprint, settings: &VolumeSettings) -> Vec3 {
        if self.slab.is_some_and(|slab| !slab.contains(p)) {
            return Vec3::ZERO;
        }
        let local = self.to_local(p);
        let rotate = |d: Vec3| Vec3::new(d.dot(self.axes[0]), d.dot(self.axes[1]), d.dot(self.axes[2]));
        let (du, dv) = (rotate(footprint.du), rotate(footprint.dv));
        let lambda = |q: Vec3| {
            let beta = self.beta(q);
            beta / (beta.x + beta.y + beta.z)
        };
        let centre = lambda(local);
        let along_u = lambda(local + 0.5 * du) - lambda(local - 0.5 * du);
        let along_v = lambda(local + 0.5 * dv) - lambda(local - 0.5 * dv);
        if !(centre.is_finite() && along_u.is_finite() && along_v.is_finite()) {
            return Vec3::ZERO;
        }
        let (area, centroid) = footprint_coverage(centre, along_u, along_v);
        if area <= 0.0 {
            return Vec3::ZERO;
        }
        let at = local + centroid.x * du + centroid.y * dv;
        if !(at.y >= 0.0 && at.y <= self.depth) || self.height(at) < 0.0 {
            return Vec3::ZERO;
        }
        let inside = lambda(at).max(Vec3::ZERO);
        let inside = inside / (inside.x + inside.y + inside.z);
        if !inside.is_finite() {
            return Vec3::ZERO;
        }
        match self.sample_inside(at, inside, settings) {
            Some(s) => self.color * (area * s.plane_irradiance * (-s.ray.dot(n)).max(0.0)),
            None => Vec3::ZERO,
        }
    }

    /// The flux this volume carries (the light crossing its generator triangle, after
    /// the Fresnel term): `flux × area`, with the per-vertex weights averaged.
    pub fn flux(&self) -> Vec3 {
        self.color * ((self.flux.x + self.flux.y + self.flux.z) / 3.0 * 0.5 * self.triangle_abc.x)
    }
}

/// All caustic volumes of a scene, binned by their world bounds on a uniform grid so
/// that a point meets only the volumes near it (the GPU gets the same effect from
/// rasterising each volume's prism).
#[derive(Clone, Debug, Default)]
pub struct VolumeSet {
    /// Every volume built.
    pub volumes: Vec<CausticVolume>,
    /// What the build kept and dropped.
    pub stats: BuildStats,
    boxes: Vec<(Vec3, Vec3)>,
    grid: VolumeGrid,
}

/// Volume indices per cell of a uniform grid over the volumes' bounds (rows packed).
#[derive(Clone, Debug, Default)]
struct VolumeGrid {
    lo: Vec3,
    cell: Vec3,
    dims: [usize; 3],
    start: Vec<u32>,
    items: Vec<u32>,
}

impl VolumeGrid {
    fn new(boxes: &[(Vec3, Vec3)]) -> Self {
        let finite = boxes.iter().filter(|(a, b)| a.is_finite() && b.is_finite());
        let (lo, hi) = finite.fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(l, h), (a, b)| (l.min(*a), h.max(*b)));
        if boxes.is_empty() || !(lo.cmple(hi).all()) {
            return Self::default();
        }
        // Cells about as large as a typical volume's bounds along each axis (so that a
        // volume lands in a few cells), at most 8 cells per volume in all.
        let extent = (hi - lo).max(Vec3::splat(1e-6));
        let mut sizes: [Vec<f32>; 3] = std::array::from_fn(|i| boxes.iter().map(|(a, b)| b[i] - a[i]).filter(|e| e.is_finite()).collect());
        let median = Vec3::from_array(std::array::from_fn(|i| {
            let v = &mut sizes[i];
            let mid = v.len() / 2;
            if v.is_empty() { extent[i] } else { *v.select_nth_unstable_by(mid, f32::total_cmp).1 }
        }));
        let mut cell = median.max(extent / 512.0);
        let budget = 8.0 * boxes.len() as f32;
        let cells_of = |cell: Vec3| (extent / cell).ceil().max(Vec3::ONE);
        let total = cells_of(cell).element_product();
        if total > budget {
            cell *= (total / budget).cbrt();
        }
        let d = cells_of(cell).min(Vec3::splat(512.0));
        let dims = [d.x as usize, d.y as usize, d.z as usize];
        let cell = extent / d;
        let grid = Self { lo, cell, dims, start: Vec::new(), items: Vec::new() };
        let ranges: Vec<Option<([usize; 3], [usize; 3])>> = boxes.iter().map(|&(a, b)| grid.range(a, b)).collect();
        let cells = dims[0] * dims[1] * dims[2];
        let mut count = vec![0u32; cells + 1];
        let each = |r: &([usize; 3], [usize; 3]), f: &mut dyn FnMut(usize)| {
            for z in r.0[2]..=r.1[2] {
                for y in r.0[1]..=r.1[1] {
                    for x in r.0[0]..=r.1[0] {
                        f((z * dims[1] + y) * dims[0] + x);
                    }
                }
            }
        };
        for r in ranges.iter().flatten() {
            each(r, &mut |c| count[c + 1] += 1);
        }
        for i in 0..cells {
            count[i + 1] += count[i];
        }
        let mut next = count.clone();
        let mut items = vec![0u32; count[cells] as usize];
        for (v, r) in ranges.iter().enumerate() {
            if let Some(r) = r {
                each(r, &mut |c| {
                    items[next[c] as usize] = v as u32;
                    next[c] += 1;
                });
            }
        }
        Self { start: count, items, ..grid }
    }

    fn coordinate(&self, p: Vec3) -> [usize; 3] {
        let c = ((p - self.lo) / self.cell).floor();
        std::array::from_fn(|i| (c[i].max(0.0) as usize).min(self.dims[i] - 1))
    }

    fn range(&self, a: Vec3, b: Vec3) -> Option<([usize; 3], [usize; 3])> {
        (a.is_finite() && b.is_finite()).then(|| (self.coordinate(a), self.coordinate(b)))
    }

    /// The volumes whose bounds may contain `p`.
    fn near(&self, p: Vec3) -> &[u32] {
        if self.start.is_empty() || !p.is_finite() {
            return &[];
        }
        let [x, y, z] = self.coordinate(p);
        let c = (z * self.dims[1] + y) * self.dims[0] + x;
        &self.items[self.start[c] as usize..self.start[c + 1] as usize]
    }

    /// The volumes whose bounds may meet the box `lo..hi`, each once.
    fn near_box(&self, lo: Vec3, hi: Vec3) -> Vec<u32> {
        let Some((a, b)) = self.range(lo, hi).filter(|_| !self.start.is_empty()) else {
            return Vec::new();
        };
        let mut found = Vec::new();
        for z in a[2]..=b[2] {
            for y in a[1]..=b[1] {
                for x in a[0]..=b[0] {
                    let c = (z * self.dims[1] + y) * self.dims[0] + x;
                    found.extend_from_slice(&self.items[self.start[c] as usize..self.start[c + 1] as usize]);
                }
            }
        }
        found.sort_unstable();
        found.dedup();
        found
    }
}

impl VolumeSet {
    /// Wraps built volumes.
    pub fn new(volumes: Vec<CausticVolume>, stats: BuildStats) -> Self {
        let boxes: Vec<_> = volumes.iter().map(|v| v.bounds.aabb()).collect();
        let grid = VolumeGrid::new(&boxes);
        Self { volumes, stats, boxes, grid }
    }

    /// Caustic irradiance at receiver points with their normals: the CPU twin of the
    /// GPU pass — every volume whose bounding shape contains a point runs the exact
    /// test and adds its irradiance (§3, the accumulation loop).
    pub fn irradiance_at(&self, points: &[Vec3], normals: &[Vec3], settings: &VolumeSettings) -> Vec<Vec3> {
        use rayon::prelude::*;
        points.par_iter().zip(normals.par_iter()).map(|(&p, &n)| self.irradiance(p, n, settings)).collect()
    }

    /// Caustic irradiance at one point.
    pub fn irradiance(&self, p: Vec3, n: Vec3, settings: &VolumeSettings) -> Vec3 {
        let mut e = Vec3::ZERO;
        for &i in self.grid.near(p) {
            let (lo, hi) = self.boxes[i as usize];
            if p.cmpge(lo).all() && p.cmple(hi).all() {
                e += self.volumes[i as usize].irradiance(p, n, settings);
            }
        }
        e
    }

    /// What a pixel with this [`Footprint`] on the receiver at `p` shows: with
    /// [`VolumeSettings::footprint_filter`], the mean caustic irradiance over the
    /// footprint from every volume whose bounds meet it
    /// ([`CausticVolume::irradiance_over`]); else the point sample at `p`.
    pub fn irradiance_over(&self, p: Vec3, n: Vec3, footprint: &Footprint, settings: &VolumeSettings) -> Vec3 {
        if !settings.footprint_filter {
            return self.irradiance(p, n, settings);
        }
        let reach = 0.5 * (footprint.du.abs() + footprint.dv.abs());
        let (lo, hi) = (p - reach, p + reach);
        let mut e = Vec3::ZERO;
        for i in self.grid.near_box(lo, hi) {
            let (a, b) = self.boxes[i as usize];
            if a.cmple(hi).all() && b.cmpge(lo).all() {
                e += self.volumes[i as usize].irradiance_over(p, n, footprint, settings);
            }
        }
        e
    }

    /// [`Self::irradiance_over`] at receiver points with their normals and footprints.
    pub fn irradiance_over_at(&self, points: &[(Vec3, Vec3, Footprint)], settings: &VolumeSettings) -> Vec<Vec3> {
        use rayon::prelude::*;
        points.par_iter().map(|(p, n, footprint)| self.irradiance_over(*p, *n, footprint, settings)).collect()
    }

    /// Total flux carried by all volumes.
    pub fn flux(&self) -> Vec3 {
        self.volumes.iter().map(CausticVolume::flux).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    #[test]
    fn footprint_coverage_is_the_part_of_the_square_inside() {
        // Wholly inside: the whole square, centred.
        let (area, centroid) = footprint_coverage(Vec3::splat(1.0 / 3.0), Vec3::ZERO, Vec3::ZERO);
        assert!((area - 1.0).abs() < 1e-6 && centroid.length() < 1e-6);
        // A side through the centre along v: the half u > 0, centred at u = ¼.
        let (area, centroid) = footprint_coverage(Vec3::new(0.0, 0.5, 0.5), Vec3::new(1.0, -0.5, -0.5), Vec3::ZERO);
        assert!((area - 0.5).abs() < 1e-6 && (centroid - Vec2::new(0.25, 0.0)).length() < 1e-6, "{area} {centroid}");
        // A triangle of area ⅛ inside the square: λ = (½ + 2u, ½ + 2v, −2u − 2v).
        let (area, _) = footprint_coverage(Vec3::new(0.5, 0.5, 0.0), Vec3::new(2.0, 0.0, -2.0), Vec3::new(0.0, 2.0, -2.0));
        assert!((area - 0.125).abs() < 1e-6, "{area}");
        // Wholly outside: nothing.
        assert_eq!(footprint_coverage(Vec3::new(-1.0, 1.0, 1.0), Vec3::new(0.1, 0.0, -0.1), Vec3::ZERO).0, 0.0);
        // Any triangle against the square counted on a 400² grid.
        let mut rng = crate::rng::Pcg32::for_photon(7, 0, 0);
        let mut next = || rng.next_f32() * 4.0 - 2.0;
        for _ in 0..200 {
            let lambda = Vec3::new(next(), next(), 0.0);
            let lambda = Vec3::new(lambda.x, lambda.y, 1.0 - lambda.x - lambda.y) * 0.5;
            let du = Vec3::new(next(), next(), 0.0);
            let dv = Vec3::new(next(), next(), 0.0);
            let (du, dv) = (Vec3::new(du.x, du.y, -du.x - du.y), Vec3::new(dv.x, dv.y, -dv.x - dv.y));
            let (area, centroid) = footprint_coverage(lambda, du, dv);
            let n = 400;
            let (mut count, mut sum) = (0usize, Vec2::ZERO);
            for i in 0..n * n {
                let q = Vec2::new((i % n) as f32 + 0.5, (i / n) as f32 + 0.5) / n as f32 - 0.5;
                if (lambda + q.x * du + q.y * dv).cmpge(Vec3::ZERO).all() {
                    count += 1;
                    sum += q;
                }
            }
            let counted = count as f32 / (n * n) as f32;
            assert!((area - counted).abs() < 0.01, "{lambda} {du} {dv}: {area} vs {counted}");
            if counted > 0.05 {
                assert!((centroid - sum / count as f32).length() < 0.01, "{centroid} vs {}", sum / count as f32);
            }
        }
    }

    #[test]
    fn a_footprint_seen_at_a_slant_stretches_along_the_receiver() {
        let step = Vec3::X * 0.01;
        // Straight down onto a floor: the step as it is.
        assert_eq!(Footprint::seen(Vec3::Y, Vec3::NEG_Y, step, Vec3::Z * 0.01).du, step);
        // At 60° from the normal, a step across the eye ray in its plane grows by 1/cos.
        let eye = Vec3::new(60f32.to_radians().sin(), -60f32.to_radians().cos(), 0.0);
        let across = Vec3::new(eye.y, -eye.x, 0.0) * 0.01;
        let du = Footprint::seen(Vec3::Y, eye, across, Vec3::Z * 0.01).du;
        assert!(du.y.abs() < 1e-7 && (du.length() - 0.02).abs() < 1e-6, "{du}");
        // Grazing: at most `MAX_FOOTPRINT_STRETCH` times longer, and finite.
        let grazing = Footprint::seen(Vec3::Y, Vec3::X, Vec3::Y * 0.01, Vec3::Z * 0.01).du;
        assert!(grazing.is_finite() && grazing.length() <= 0.01 * (1.0 + MAX_FOOTPRINT_STRETCH) + 1e-6, "{grazing}");
    }
}

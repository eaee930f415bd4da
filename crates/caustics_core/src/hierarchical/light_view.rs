//! A light's view of the scene, as a shadow map sees it: the frame, the projection to
//! map coordinates and back, the measure of a texel and the Jacobian that turns flux per
//! unit of map area into irradiance on a receiver.
//!
//! Map coordinates `uv ∈ [0, 1]²` run along `right` and down `up` (row 0 at the top,
//! as a render target's), and the view depth `z` is the distance along `forward`:
//! linear for both projections, so a ray's depth is linear in its length.

use crate::scene::{Light, LightKind};
use crate::tracer::orthonormal_basis;
use glam::{Mat4, Vec2, Vec3, Vec4};

/// How a light view projects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Parallel light: a box `2·half_extent` wide across the beam.
    Orthographic {
        /// Half the box's width (along `right`) and height (along `up`), in metres.
        half_extent: Vec2,
    },
    /// A point light's frustum with a square image plane at `z = 1`, `2·tan_half_fov` wide.
    Perspective {
        /// Tangent of the half-angle from the axis to the image plane's edges.
        tan_half_fov: f32,
    },
}

/// One light view: a shadow-map-like frame from which photons are emitted and in which
/// the caustic map is stored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightView {
    /// How the view projects.
    pub projection: Projection,
    /// A point on the view's axis (orthographic) or the light's position (perspective).
    pub origin: Vec3,
    /// Unit axis along which `u` grows.
    pub right: Vec3,
    /// Unit axis along which `v` shrinks (rows run down).
    pub up: Vec3,
    /// Unit direction of view depth, away from the light.
    pub forward: Vec3,
    /// View depth in front of everything the view draws.
    pub near: f32,
    /// View depth behind everything the view draws.
    pub far: f32,
    /// The central fraction of the image, across and down, that the photon buffer (and
    /// the front and back maps) covers; the receiver and caustic maps cover all of it.
    /// 1 but for a point light's cube faces that the scene extends past, whose maps
    /// reach further ([`CUBE_FACE_REACH`]) so that light one face emits lands on its
    /// own map.
    pub emission: f32,
}

/// Tangent of the half-angle a point light's cube face's receiver and caustic maps
/// reach when the scene extends past the face (63°), where its photons leave within
/// 45°: light bent across a face's edge lands on the map of the face it left from, and
/// each photon is on one map. Measured on `mirror_bunny` (a light 1.6 m over the
/// floor's edge, 2048² photons landed exactly): with tan 1 the faces' maps carry 0.898
/// of the tracer's caustic flux, with tan 2 0.937 (0.925 and 0.983 with one Fresnel
/// branch). A power of two: the photon buffer then
/// covers half the map, and photons of a `2ᵏ` buffer land on a lattice of a `2ʲ` map's
/// texels, where tent splats sum to a constant.
pub const CUBE_FACE_REACH: f32 = 2.0;

/// Widest spot cone drawn as one perspective view; wider spots and point lights take
/// the faces of a cube.
pub const MAX_SPOT_HALF_ANGLE: f32 = std::f32::consts::FRAC_PI_3;

impl LightView {
    /// `p` in view coordinates `(x along right, y along up, z along forward)`.
    #[inline]
    pub fn to_view(&self, p: Vec3) -> Vec3 {
        let d = p - self.origin;
        Vec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.forward))
    }

    /// View depth of `p`.
    #[inline]
    pub fn depth(&self, p: Vec3) -> f32 {
        (p - self.origin).dot(self.forward)
    }

    /// Map coordinates of the image-plane point `(x, y)` (at depth 1 in perspective).
    #[inline]
    fn uv_of_plane(&self, x: f32, y: f32) -> Vec2 {
        let half = self.half_extent();
        Vec2::new(0.5 + 0.5 * x / half.x, 0.5 - 0.5 * y / half.y)
    }

    /// Half the image plane's width and height.
    #[inline]
    pub fn half_extent(&self) -> Vec2 {
        match self.projection {
            Projection::Orthographic { half_extent } => half_extent,
            Projection::Perspective { tan_half_fov } => Vec2::splat(tan_half_fov),
        }
    }

    /// Map coordinates of `p`; `None` behind a perspective light. Outside `[0, 1]²`
    /// where `p` lies outside the view.
    #[inline]
    pub fn uv(&self, p: Vec3) -> Option<Vec2> {
        let v = self.to_view(p);
        match self.projection {
            Projection::Orthographic { .. } => Some(self.uv_of_plane(v.x, v.y)),
            Projection::Perspective { .. } => (v.z > 0.0).then(|| self.uv_of_plane(v.x / v.z, v.y / v.z)),
        }
    }

    /// The image-plane point (at depth 1 in perspective) of map coordinates `uv`.
    #[inline]
    fn plane_of_uv(&self, uv: Vec2) -> Vec2 {
        let half = self.half_extent();
        Vec2::new((2.0 * uv.x - 1.0) * half.x, (1.0 - 2.0 * uv.y) * half.y)
    }

    /// The ray of the light through map point `uv`: origin on the near plane
    /// (orthographic) or at the light, and the unit direction light travels.
    #[inline]
    pub fn ray(&self, uv: Vec2) -> (Vec3, Vec3) {
        let q = self.plane_of_uv(uv);
        match self.projection {
            Projection::Orthographic { .. } => (self.origin + self.right * q.x + self.up * q.y + self.forward * self.near, self.forward),
            Projection::Perspective { .. } => (self.origin, (self.forward + self.right * q.x + self.up * q.y).normalize()),
        }
    }

    /// The centre of texel `(x, y)` of a `resolution²` map, in map coordinates.
    #[inline]
    pub fn texel_center(x: u32, y: u32, resolution: u32) -> Vec2 {
        (Vec2::new(x as f32, y as f32) + 0.5) / resolution as f32
    }

    /// Map coordinates of the centre of photon texel `(x, y)` of a `resolution²` photon
    /// buffer, which covers the central [`Self::emission`] of the map.
    #[inline]
    pub fn photon_uv(&self, x: u32, y: u32, resolution: u32) -> Vec2 {
        Vec2::splat(0.5) + (Self::texel_center(x, y, resolution) - 0.5) * self.emission
    }

    /// The photon texel of a `resolution²` photon buffer at map coordinates `uv`.
    #[inline]
    pub fn photon_texel(&self, uv: Vec2, resolution: u32) -> Option<(u32, u32)> {
        super::photons::texel_of(Vec2::splat(0.5) + (uv - 0.5) / self.emission, resolution)
    }

    /// The image-plane area of one photon of a `resolution²` photon buffer.
    pub fn photon_measure(&self, resolution: u32) -> f32 {
        self.texel_measure(resolution) * self.emission * self.emission
    }

    /// Map texels per photon texel, across: `M·emission / P`.
    pub fn map_texels_per_photon(&self, photon_resolution: u32, map_resolution: u32) -> f32 {
        map_resolution as f32 * self.emission / photon_resolution as f32
    }

    /// The image-plane area of one texel of a `resolution²` map: m² across the beam
    /// (orthographic) or on the plane at depth 1 (perspective).
    pub fn texel_measure(&self, resolution: u32) -> f32 {
        let half = self.half_extent();
        4.0 * half.x * half.y / (resolution as f32 * resolution as f32)
    }

    /// The beam measure of a texel at `uv` relative to the view's centre: 1 for parallel
    /// light, `cos³α` in perspective (the solid angle of an image-plane element at the
    /// angle α off the axis is `dA cos³α`).
    #[inline]
    pub fn relative_beam(&self, uv: Vec2) -> f32 {
        match self.projection {
            Projection::Orthographic { .. } => 1.0,
            Projection::Perspective { .. } => {
                let q = self.plane_of_uv(uv);
                let cos2 = 1.0 / (1.0 + q.length_squared());
                cos2 * cos2.sqrt()
            }
        }
    }

    /// Image-plane area per unit of receiver area at `p` with unit normal `n`,
    /// `dA_map / dA`: `|n·forward|` for parallel light, `|n·d| / z³` in perspective
    /// (`d` from the light to `p`, `z` its depth): the solid angle `dA cos θ / |d|²`
    /// spread over the image plane, `dω / cos³α`.
    #[inline]
    pub fn receiver_jacobian(&self, p: Vec3, n: Vec3) -> f32 {
        match self.projection {
            Projection::Orthographic { .. } => n.dot(self.forward).abs(),
            Projection::Perspective { .. } => {
                let d = p - self.origin;
                let z = d.dot(self.forward);
                if z <= 0.0 { 0.0 } else { n.dot(d).abs() / (z * z * z) }
            }
        }
    }

    /// World size of a map texel at depth `z` (the larger side).
    pub fn texel_size(&self, z: f32, resolution: u32) -> f32 {
        let half = self.half_extent();
        let scale = match self.projection {
            Projection::Orthographic { .. } => 1.0,
            Projection::Perspective { .. } => z.max(0.0),
        };
        2.0 * half.x.max(half.y) * scale / resolution as f32
    }

    /// Clip space from world space for rasterising this view on a GPU: x right, y up,
    /// depth `[0, 1]` from `near` to `far` (not reversed), so that texel centres are
    /// the points [`Self::ray`] casts through.
    pub fn clip_from_world(&self) -> Mat4 {
        let view = Mat4::from_cols(
            Vec4::new(self.right.x, self.up.x, self.forward.x, 0.0),
            Vec4::new(self.right.y, self.up.y, self.forward.y, 0.0),
            Vec4::new(self.right.z, self.up.z, self.forward.z, 0.0),
            Vec4::new(-self.right.dot(self.origin), -self.up.dot(self.origin), -self.forward.dot(self.origin), 1.0),
        );
        let half = self.half_extent();
        let (n, f) = (self.near, self.far);
        let projection = match self.projection {
            Projection::Orthographic { .. } => Mat4::from_cols(
                Vec4::new(1.0 / half.x, 0.0, 0.0, 0.0),
                Vec4::new(0.0, 1.0 / half.y, 0.0, 0.0),
                Vec4::new(0.0, 0.0, 1.0 / (f - n), 0.0),
                Vec4::new(0.0, 0.0, -n / (f - n), 1.0),
            ),
            // z_ndc = f(z − n) / (z(f − n)), w = z.
            Projection::Perspective { .. } => Mat4::from_cols(
                Vec4::new(1.0 / half.x, 0.0, 0.0, 0.0),
                Vec4::new(0.0, 1.0 / half.y, 0.0, 0.0),
                Vec4::new(0.0, 0.0, f / (f - n), 1.0),
                Vec4::new(0.0, 0.0, -f * n / (f - n), 0.0),
            ),
        };
        projection * view
    }

    /// The views of `light` that can see generators within `generators` and receivers
    /// within `scene` (both `(min, max)` world bounds): one orthographic view of a
    /// directional light across the generators' shadow grown by half its size on each
    /// side (where the light they bend can land; a large floor does not dilute the
    /// map), within the scene, as deep as the scene; one perspective view of a
    /// spot up to [`MAX_SPOT_HALF_ANGLE`] along its cone; otherwise the faces of a cube
    /// around the light, only those whose frustum meets the generators (all six when
    /// the light is inside their bounds). Photons that hit no generator make no
    /// caustic, so a view that sees none is left out. Where the scene extends past a
    /// face, its maps reach [`CUBE_FACE_REACH`]; its photons stay within it.
    pub fn for_light(light: &Light, generators: (Vec3, Vec3), scene: (Vec3, Vec3)) -> Vec<LightView> {
        let (lo, hi) = (scene.0.min(generators.0), scene.1.max(generators.1));
        let corners = box_corners(lo, hi);
        let size = (hi - lo).length().max(1e-3);
        match light.kind {
            LightKind::Directional { direction, .. } => {
                let forward = direction.normalize_or(Vec3::NEG_Y);
                let (right, up) = view_basis(forward);
                let center = 0.5 * (lo + hi);
                let mut view = LightView {
                    projection: Projection::Orthographic { half_extent: Vec2::ONE },
                    origin: center,
                    right,
                    up,
                    forward,
                    near: 0.0,
                    far: 1.0,
                    emission: 1.0,
                };
                let extent = |points: &[Vec3]| {
                    points.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(a, b), &c| {
                        let v = view.to_view(c);
                        (a.min(v), b.max(v))
                    })
                };
                let (vlo, vhi) = extent(&corners);
                // Across the beam: the generators' shadow grown by half its size on each
                // side (where the light they bend lands), within the scene.
                let (glo, ghi) = extent(&box_corners(generators.0, generators.1));
                let grow = 0.5 * (ghi - glo).truncate();
                let across_lo = (glo.truncate() - grow).max(vlo.truncate());
                let across_hi = (ghi.truncate() + grow).min(vhi.truncate());
                let pad = 1e-3 * size;
                let mid = 0.5 * (across_lo + across_hi);
                view.origin = center + right * mid.x + up * mid.y;
                let half = 0.5 * (across_hi - across_lo) + pad;
                view.projection = Projection::Orthographic { half_extent: half.max(Vec2::splat(1e-4)) };
                (view.near, view.far) = (vlo.z - 2.0 * pad, vhi.z + 2.0 * pad);
                vec![view]
            }
            LightKind::Spot { position, direction, outer_angle, .. } if outer_angle <= MAX_SPOT_HALF_ANGLE => {
                let forward = direction.normalize_or(Vec3::NEG_Y);
                let (right, up) = view_basis(forward);
                let tan_half_fov = (outer_angle.max(1e-3).tan() * 1.01).max(1e-3);
                let view = perspective(position, right, up, forward, tan_half_fov, &corners, size);
                if frustum_meets_box(&view, generators) { vec![view] } else { vec![] }
            }
            LightKind::Point { position, .. } | LightKind::Spot { position, .. } => {
                let axes = [Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z];
                axes.iter()
                    .map(|&forward| {
                        let (right, up) = view_basis(forward);
                        let face = perspective(position, right, up, forward, 1.0, &corners, size);
                        let reach = face_reach(&face, &corners);
                        LightView { projection: Projection::Perspective { tan_half_fov: reach }, emission: 1.0 / reach, ..face }
                    })
                    .filter(|view| frustum_meets_box(view, generators))
                    .collect()
            }
        }
    }
}

/// `right` and `up` across `forward` with `right × up = −forward`, a camera's frame: a
/// triangle wound counter-clockwise about a normal that faces the light stays
/// counter-clockwise on the map, Bevy's front face.
pub fn view_basis(forward: Vec3) -> (Vec3, Vec3) {
    let (t, b) = orthonormal_basis(forward);
    (t, -b)
}

fn box_corners(lo: Vec3, hi: Vec3) -> [Vec3; 8] {
    std::array::from_fn(|i| Vec3::new([lo.x, hi.x][i & 1], [lo.y, hi.y][(i >> 1) & 1], [lo.z, hi.z][i >> 2]))
}

/// A perspective view from `position` whose depth range covers every corner of the scene.
fn perspective(position: Vec3, right: Vec3, up: Vec3, forward: Vec3, tan_half_fov: f32, corners: &[Vec3; 8], size: f32) -> LightView {
    let far = corners.iter().map(|&c| (c - position).length()).fold(0.0, f32::max).max(1e-3 * size) * 1.01;
    LightView { projection: Projection::Perspective { tan_half_fov }, origin: position, right, up, forward, near: (1e-4 * far).max(1e-6), far, emission: 1.0 }
}

/// How far a cube face's maps reach (the tangent of their half-angle): the face's own
/// 1 where the scene's box lies within it, [`CUBE_FACE_REACH`] where it extends past.
fn face_reach(face: &LightView, corners: &[Vec3; 8]) -> f32 {
    let within = corners.iter().all(|&c| {
        let v = face.to_view(c);
        v.z > 0.0 && v.x.abs().max(v.y.abs()) <= v.z
    });
    if within { 1.0 } else { CUBE_FACE_REACH }
}

/// Whether `view`'s photon frustum may meet the box `(lo, hi)`: no frustum plane has all eight
/// corners outside (conservative), or the light is inside the box.
fn frustum_meets_box(view: &LightView, (lo, hi): (Vec3, Vec3)) -> bool {
    if view.origin.cmpge(lo).all() && view.origin.cmple(hi).all() {
        return true;
    }
    let t = view.half_extent().x * view.emission;
    let corners = box_corners(lo, hi).map(|c| view.to_view(c));
    let outside = |f: &dyn Fn(Vec3) -> bool| corners.iter().all(|&c| f(c));
    !(outside(&|c| c.z <= view.near)
        || outside(&|c| c.z > view.far)
        || outside(&|c| c.x > t * c.z)
        || outside(&|c| c.x < -t * c.z)
        || outside(&|c| c.y > t * c.z)
        || outside(&|c| c.y < -t * c.z))
}

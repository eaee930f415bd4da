//! Tight bounding prisms for caustic volumes (§4.3), with a box fallback.

use glam::Vec3;

/// A convex hexahedron bounding a caustic volume, as eight world-space corners: the
/// top face `0..4` and the bottom face `4..8` (corner `4 + i` below corner `i`). A
/// prism repeats its last top and bottom corners, so that one index list draws both.
/// Corners are ordered so that [`HEXAHEDRON_TRIANGLES`] faces outwards with
/// counter-clockwise front faces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundingShape {
    /// The eight corners: the top face `0..4`, the bottom face `4..8`.
    pub corners: [Vec3; 8],
    /// Whether this is the tight prism of §4.3 (`false`: the fallback box).
    pub is_prism: bool,
}

/// The twelve triangles of a hexahedron with the corner layout of [`BoundingShape`].
pub const HEXAHEDRON_TRIANGLES: [[u32; 3]; 12] =
    [[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6], [0, 4, 5], [0, 5, 1], [1, 5, 6], [1, 6, 2], [2, 6, 7], [2, 7, 3], [3, 7, 4], [3, 4, 0]];

impl BoundingShape {
    /// No shape: every corner at the origin, so that it rasterises no pixel.
    pub const EMPTY: Self = Self { corners: [Vec3::ZERO; 8], is_prism: false };

    /// The world-space axis-aligned bounds of the corners.
    pub fn aabb(&self) -> (Vec3, Vec3) {
        let lo = self.corners.iter().copied().reduce(Vec3::min).unwrap_or(Vec3::ZERO);
        let hi = self.corners.iter().copied().reduce(Vec3::max).unwrap_or(Vec3::ZERO);
        (lo, hi)
    }

    /// The bounding shape of a volume given in its local frame: the three top vertices
    /// `v` (all at one y: 0 for the whole beam, deeper for a slice of it), the scaled
    /// rays `r` (y = 1) and the depth below the top. `to_world` maps local points to
    /// world space.
    #[cfg(test)]
    pub(crate) fn new(v: [Vec3; 3], r: [Vec3; 3], depth: f32, to_world: impl Fn(Vec3) -> Vec3) -> Self {
        Self::local(v, r, depth).to_world(to_world)
    }

    /// [`Self::new`] in the local frame, before its corners are oriented.
    pub(crate) fn local(v: [Vec3; 3], r: [Vec3; 3], depth: f32) -> Self {
        let b = [v[0] + depth * r[0], v[1] + depth * r[1], v[2] + depth * r[2]];
        let bx = local_box(&v, &b, depth);
        match tight_prism(&v, &b, depth) {
            Some(prism) if prism_volume(&prism) <= box_volume(&bx) => Self { corners: prism, is_prism: true },
            _ => Self { corners: bx, is_prism: false },
        }
    }

    /// The shape with its local corners mapped to world space by `to_world`, ordered to
    /// face outwards.
    pub(crate) fn to_world(self, to_world: impl Fn(Vec3) -> Vec3) -> Self {
        let mut corners = self.corners.map(&to_world);
        orient_outwards(&mut corners);
        Self { corners, ..self }
    }
}

/// §4.3: for each edge, the plane through the edge and one bottom vertex that keeps
/// all three bottom vertices on its inner side (the three candidates must all be
/// tried: a converging volume can cross itself). The prism's side lines are the
/// intersections of adjacent planes. `None` when an edge has no such plane or the
/// bottom face would turn over.
fn tight_prism(v: &[Vec3; 3], b: &[Vec3; 3], depth: f32) -> Option<[Vec3; 8]> {
    let mut planes = [(Vec3::ZERO, 0.0f32); 3];
    for (e, plane) in planes.iter_mut().enumerate() {
        let (v0, v1, v2) = (v[e], v[(e + 1) % 3], v[(e + 2) % 3]);
        let edge = v1 - v0;
        *plane = b.iter().find_map(|&bk| {
            let mut n = edge.cross(bk - v0);
            if n.length_squared() <= 1e-20 * edge.length_squared() * (bk - v0).length_squared() {
                return None;
            }
            n = n.normalize();
            let mut d = -n.dot(v0);
            if n.dot(v2) + d > 0.0 {
                n = -n;
                d = -d;
            }
            let tolerance = 1e-5 * (1.0 + depth);
            b.iter().all(|&bj| n.dot(bj) + d <= tolerance).then_some((n, d))
        })?;
    }
    // Vertex i lies on the planes of edges (i−1, i) and (i, i+1).
    let mut bottom = [Vec3::ZERO; 3];
    for i in 0..3 {
        let (na, nb) = (planes[(i + 2) % 3].0, planes[i].0);
        let dir = na.cross(nb);
        if dir.y.abs() < 1e-6 * dir.length() || dir.length_squared() == 0.0 {
            return None;
        }
        bottom[i] = v[i] + dir * (depth / dir.y);
    }
    let top_area = signed_area_xz(v);
    let bottom_area = signed_area_xz(&bottom);
    if top_area * bottom_area <= 0.0 || !bottom.iter().all(|p| p.is_finite()) {
        return None;
    }
    Some([v[0], v[1], v[2], v[2], bottom[0], bottom[1], bottom[2], bottom[2]])
}

/// The fallback: the box `[x, z ranges of top and bottom] × [top, top + depth]` in the
/// local frame.
fn local_box(v: &[Vec3; 3], b: &[Vec3; 3], depth: f32) -> [Vec3; 8] {
    let all = v.iter().chain(b);
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for p in all {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let y = v[0].y;
    let top = [Vec3::new(lo.x, y, lo.z), Vec3::new(hi.x, y, lo.z), Vec3::new(hi.x, y, hi.z), Vec3::new(lo.x, y, hi.z)];
    let bottom = top.map(|p| p + Vec3::Y * depth);
    [top[0], top[1], top[2], top[3], bottom[0], bottom[1], bottom[2], bottom[3]]
}

fn signed_area_xz(p: &[Vec3; 3]) -> f32 {
    let (a, b) = (p[1] - p[0], p[2] - p[0]);
    a.z * b.x - a.x * b.z
}

/// Volume of a prism with parallel top and bottom triangles and planar sides (a
/// frustum-like solid): Simpson's rule on the cross-section area, exact for quadratics.
fn prism_volume(p: &[Vec3; 8]) -> f32 {
    let top = [p[0], p[1], p[2]];
    let bottom = [p[4], p[5], p[6]];
    let mid = [0, 1, 2].map(|i| 0.5 * (top[i] + bottom[i]));
    let depth = p[4].y - p[0].y;
    let area = |t: &[Vec3; 3]| 0.5 * signed_area_xz(t).abs();
    depth / 6.0 * (area(&top) + 4.0 * area(&mid) + area(&bottom))
}

fn box_volume(p: &[Vec3; 8]) -> f32 {
    (p[1] - p[0]).length() * (p[3] - p[0]).length() * (p[4] - p[0]).length()
}

/// Reorders corners, if needed, so that the fixed triangle list faces outwards.
fn orient_outwards(c: &mut [Vec3; 8]) {
    let centre = c.iter().copied().sum::<Vec3>() / 8.0;
    let [a, b, d] = HEXAHEDRON_TRIANGLES[0].map(|i| c[i as usize]);
    let outward = (b - a).cross(d - a).dot(a - centre);
    if outward < 0.0 {
        c.swap(1, 3);
        c.swap(5, 7);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prism_of_a_parallel_beam_is_the_beam() {
        let v = [Vec3::ZERO, Vec3::X, Vec3::Z];
        let r = [Vec3::Y; 3];
        let shape = BoundingShape::new(v, r, 2.0, |p| p);
        assert!(shape.is_prism);
        assert_eq!(shape.aabb(), (Vec3::ZERO, Vec3::new(1.0, 2.0, 1.0)));
    }
}

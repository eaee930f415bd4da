//! Indexed triangle meshes with smooth vertex normals, validated on construction, and
//! the procedural generators used by tests, examples and the bench.

use glam::{Affine3A, Vec2, Vec3};
use thiserror::Error;

/// Why a mesh was refused. Nothing is changed or partially built on error.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum MeshError {
    /// The mesh has no triangles.
    #[error("mesh has no triangles")]
    Empty,
    /// `normals.len() != positions.len()`.
    #[error("mesh has {positions} positions but {normals} normals")]
    NormalCount {
        /// Number of positions.
        positions: usize,
        /// Number of normals.
        normals: usize,
    },
    /// A triangle refers to a vertex that does not exist.
    #[error("triangle {triangle} refers to vertex {index}, but the mesh has {vertices} vertices")]
    IndexOutOfRange {
        /// Index of the triangle.
        triangle: usize,
        /// The vertex index it holds.
        index: u32,
        /// Number of vertices the mesh has.
        vertices: usize,
    },
    /// A position is NaN or infinite.
    #[error("vertex {0} has a position that is not finite")]
    NonFinitePosition(usize),
    /// A coordinate lies farther than [`MAX_COORDINATE`] from the origin.
    #[error("vertex {index} has a coordinate of {value:e} m, past the ±1e12 m within which areas, volumes and BVH costs stay finite")]
    PositionTooLarge {
        /// Index of the vertex.
        index: usize,
        /// The coordinate (m).
        value: f32,
    },
    /// A normal is NaN, infinite or zero.
    #[error("vertex {0} has a normal that is NaN, infinite or zero")]
    BadNormal(usize),
    /// A line of a Wavefront OBJ text that does not parse.
    #[error("OBJ line {line}: {reason}")]
    Obj {
        /// Line number, counted from 1.
        line: usize,
        /// What is wrong with it.
        reason: String,
    },
}

/// The largest coordinate a mesh may have (m): a product of three coordinates (a
/// volume, a determinant) stays below `f32::MAX`, and every area and squared distance
/// the techniques form from them far below. Beyond the solar system; a game's world
/// is some 10⁶ times smaller.
pub const MAX_COORDINATE: f32 = 1e12;

/// Vertices closer than this fraction of a mesh's bounding-box diagonal are one corner
/// for [`TriMesh::is_closed`]. Above what storage rounds to (f32 round trips exactly,
/// six printed digits leave 10⁻⁶, 16-bit quantised positions 1.5·10⁻⁵ of the extent)
/// and below any gap light could pass through at caustic-map resolution (0.1 mm on a
/// 1 m object, a tenth of a texel of a 1024² map over it).
pub const WELD_TOLERANCE: f32 = 1e-4;

/// One id per position, equal for positions within `weld` of a kept representative:
/// a grid of cell `weld`, each position compared with the representatives in its own
/// and the 26 neighbouring cells.
fn weld_positions(positions: &[Vec3], weld: f32) -> Vec<u32> {
    let cell = weld.max(f32::MIN_POSITIVE);
    let mut grid: std::collections::HashMap<[i64; 3], Vec<u32>> = std::collections::HashMap::new();
    let mut representatives: Vec<Vec3> = Vec::new();
    positions
        .iter()
        .map(|&p| {
            let key = (p / cell).floor().as_dvec3().to_array().map(|c| c as i64);
            let near = (-1..=1).flat_map(|dx| (-1..=1).flat_map(move |dy| (-1..=1).map(move |dz| [key[0] + dx, key[1] + dy, key[2] + dz])));
            let found = near.filter_map(|k| grid.get(&k)).flatten().copied().find(|&id| representatives[id as usize].distance(p) <= weld);
            found.unwrap_or_else(|| {
                let id = representatives.len() as u32;
                representatives.push(p);
                grid.entry(key).or_default().push(id);
                id
            })
        })
        .collect()
}

/// A triangle mesh in one coordinate frame, with unit vertex normals that are
/// interpolated across each triangle as Bevy's PBR shading does (barycentric
/// interpolation, then renormalisation). Read from JSON through [`TriMesh::new`], so
/// a file cannot make a mesh that code could not.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "MeshFields")]
pub struct TriMesh {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
}

/// A [`TriMesh`]'s fields as JSON has them, before they are checked.
#[derive(serde::Deserialize)]
struct MeshFields {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
}

impl TryFrom<MeshFields> for TriMesh {
    type Error = MeshError;

    fn try_from(m: MeshFields) -> Result<Self, MeshError> {
        TriMesh::new(m.positions, m.normals, m.triangles)
    }
}

impl TriMesh {
    /// Builds a mesh, checking every index, position and normal. Normals are
    /// normalised (unit ones kept as they are); zero, NaN or infinite normals are an error, and so are positions
    /// past [`MAX_COORDINATE`].
    pub fn new(positions: Vec<Vec3>, normals: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Result<Self, MeshError> {
        if triangles.is_empty() {
            return Err(MeshError::Empty);
        }
        if normals.len() != positions.len() {
            return Err(MeshError::NormalCount { positions: positions.len(), normals: normals.len() });
        }
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::NonFinitePosition(i));
        }
        if let Some(index) = positions.iter().position(|p| p.abs().max_element() > MAX_COORDINATE) {
            return Err(MeshError::PositionTooLarge { index, value: positions[index].abs().max_element() });
        }
        let normals = normals
            .iter()
            .enumerate()
            // A unit normal is kept bit for bit (a mesh read back is the mesh written).
            .map(|(i, n)| {
                let unit = (n.length_squared() - 1.0).abs() <= 4.0 * f32::EPSILON;
                if unit { Some(*n) } else { n.try_normalize() }.ok_or(MeshError::BadNormal(i))
            })
            .collect::<Result<Vec<_>, _>>()?;
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&index) = tri.iter().find(|&&i| i as usize >= positions.len()) {
                return Err(MeshError::IndexOutOfRange { triangle: t, index, vertices: positions.len() });
            }
        }
        Ok(Self { positions, normals, triangles })
    }

    /// Builds a mesh whose normals are the area-weighted average of the face normals
    /// around each vertex (what a modelling tool's "smooth shading" writes).
    pub fn with_smooth_normals(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Result<Self, MeshError> {
        let mut normals = vec![Vec3::ZERO; positions.len()];
        for tri in &triangles {
            let [a, b, c] = tri.map(|i| positions.get(i as usize).copied().unwrap_or(Vec3::ZERO));
            let face = (b - a).cross(c - a);
            for &i in tri {
                if let Some(n) = normals.get_mut(i as usize) {
                    *n += face;
                }
            }
        }
        Self::new(positions, normals, triangles)
    }

    /// A closed box between `-half` and `half`, each face split into quads of at most
    /// `cell` metres with their own flat normals, its edges matching face to face.
    pub fn tiled_box(half: Vec3, cell: f32) -> Self {
        let faces = [
            (Vec3::Y, Vec3::Z * half.z, Vec3::X * half.x),
            (Vec3::NEG_Y, Vec3::X * half.x, Vec3::Z * half.z),
            (Vec3::X, Vec3::Y * half.y, Vec3::Z * half.z),
            (Vec3::NEG_X, Vec3::Z * half.z, Vec3::Y * half.y),
            (Vec3::Z, Vec3::X * half.x, Vec3::Y * half.y),
            (Vec3::NEG_Z, Vec3::Y * half.y, Vec3::X * half.x),
        ];
        let mut mesh: Option<Self> = None;
        for (n, u, v) in faces {
            let (nu, nv) = ((2.0 * u.length() / cell).ceil().max(1.0) as usize, (2.0 * v.length() / cell).ceil().max(1.0) as usize);
            for (i, j) in (0..nu).flat_map(|i| (0..nv).map(move |j| (i, j))) {
                let centre = n * n.abs().dot(half) + u * ((2 * i + 1) as f32 / nu as f32 - 1.0) + v * ((2 * j + 1) as f32 / nv as f32 - 1.0);
                let quad = Self::quad(centre, u / nu as f32, v / nv as f32);
                match mesh.as_mut() {
                    Some(m) => m.append(&quad),
                    None => mesh = Some(quad),
                }
            }
        }
        mesh.expect("six faces")
    }

    /// The same surface flat-shaded: every triangle with its own three vertices and
    /// its face normal as theirs (a degenerate one keeps its vertex normals), so that
    /// shading sees the geometry a ray tracer does.
    pub fn faceted(&self) -> Self {
        let mut positions = Vec::with_capacity(3 * self.triangles.len());
        let mut normals = Vec::with_capacity(3 * self.triangles.len());
        for tri in &self.triangles {
            let [a, b, c] = tri.map(|i| self.positions[i as usize]);
            let face = (b - a).cross(c - a).try_normalize();
            for &i in tri {
                positions.push(self.positions[i as usize]);
                normals.push(face.unwrap_or(self.normals[i as usize]));
            }
        }
        let triangles = (0..self.triangles.len() as u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect();
        Self { positions, normals, triangles }
    }

    /// Vertex positions.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// Unit vertex normals.
    pub fn normals(&self) -> &[Vec3] {
        &self.normals
    }

    /// Triangles as vertex index triples (counter-clockwise seen from the front).
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The three corner positions of triangle `t`.
    #[inline]
    pub fn corners(&self, t: usize) -> [Vec3; 3] {
        self.triangles[t].map(|i| self.positions[i as usize])
    }

    /// The smooth shading normal at barycentric `(u, v)` of triangle `t`
    /// (weights `1 − u − v`, `u`, `v` on its corners), renormalised. Falls back to the
    /// geometric normal where the interpolated normals cancel out.
    #[inline]
    pub fn shading_normal(&self, t: usize, uv: Vec2) -> Vec3 {
        let [a, b, c] = self.triangles[t].map(|i| self.normals[i as usize]);
        let n = a * (1.0 - uv.x - uv.y) + b * uv.x + c * uv.y;
        n.try_normalize().unwrap_or_else(|| {
            let [p0, p1, p2] = self.corners(t);
            (p1 - p0).cross(p2 - p0).normalize_or(Vec3::Y)
        })
    }

    /// The mesh with `transform` applied (normals by the inverse transpose).
    pub fn transformed(&self, transform: &Affine3A) -> Self {
        let normal_matrix = transform.matrix3.inverse().transpose();
        Self {
            positions: self.positions.iter().map(|&p| transform.transform_point3(p)).collect(),
            normals: self.normals.iter().map(|&n| (normal_matrix * n).normalize_or(n)).collect(),
            triangles: self.triangles.clone(),
        }
    }

    /// Axis-aligned bounds `(min, max)`.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| (lo.min(p), hi.max(p)))
    }

    /// Total surface area.
    pub fn area(&self) -> f32 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.corners(t);
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }

    /// A regular grid over x, z ∈ [−size/2, size/2] with `n × n` vertices at heights
    /// `height(x, z)` and normals `normal(x, z)`. Vertex `p = j·n + i` (i along x, j
    /// along z); each cell is split into (p, p+n, p+1) and (p+1, p+n, p+n+1), so the
    /// front faces +y.
    pub fn heightfield(n: usize, size: f32, height: impl Fn(f32, f32) -> f32, normal: impl Fn(f32, f32) -> Vec3) -> Result<Self, MeshError> {
        let n = n.max(2);
        let step = size / (n - 1) as f32;
        let mut positions = Vec::with_capacity(n * n);
        let mut normals = Vec::with_capacity(n * n);
        for j in 0..n {
            for i in 0..n {
                let x = -0.5 * size + i as f32 * step;
                let z = -0.5 * size + j as f32 * step;
                positions.push(Vec3::new(x, height(x, z), z));
                normals.push(normal(x, z));
            }
        }
        let mut triangles = Vec::with_capacity(2 * (n - 1) * (n - 1));
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let p = (j * n + i) as u32;
                let n = n as u32;
                triangles.push([p, p + n, p + 1]);
                triangles.push([p + 1, p + n, p + n + 1]);
            }
        }
        Self::new(positions, normals, triangles)
    }

    /// A flat rectangle centred at `center`, spanned by `half_u` and `half_v`
    /// (its normal is `half_u × half_v`).
    pub fn quad(center: Vec3, half_u: Vec3, half_v: Vec3) -> Self {
        let n = half_u.cross(half_v).normalize_or(Vec3::Y);
        let positions = vec![center - half_u - half_v, center + half_u - half_v, center + half_u + half_v, center - half_u + half_v];
        Self { positions, normals: vec![n; 4], triangles: vec![[0, 1, 2], [0, 2, 3]] }
    }

    /// A mesh from Wavefront OBJ text: its `v` positions and `f` faces (1-based or
    /// negative indices, `v/vt/vn` forms read for the position; polygons fanned into
    /// triangles), with smooth normals. Other statements are ignored; a line that does
    /// not parse is an error naming it.
    pub fn from_obj(text: &str) -> Result<Self, MeshError> {
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        let mut face_lines = Vec::new();
        for (number, line) in text.lines().enumerate() {
            let err = |reason: String| MeshError::Obj { line: number + 1, reason };
            let mut words = line.split_whitespace();
            match words.next() {
                Some("v") => {
                    let xyz: Vec<f32> = words.take(3).map(|w| w.parse::<f32>().map_err(|e| err(format!("{w:?}: {e}")))).collect::<Result<_, _>>()?;
                    let [x, y, z] = xyz[..] else { return Err(err("a vertex needs three coordinates".into())) };
                    positions.push(Vec3::new(x, y, z));
                }
                Some("f") => {
                    let corners = words
                        .map(|w| {
                            let index = w.split('/').next().unwrap_or("");
                            let i: i64 = index.parse().map_err(|e| err(format!("{w:?}: {e}")))?;
                            let resolved = if i < 0 { positions.len() as i64 + i } else { i - 1 };
                            u32::try_from(resolved).map_err(|_| err(format!("vertex index {i} is out of range")))
                        })
                        .collect::<Result<Vec<u32>, _>>()?;
                    if corners.len() < 3 {
                        return Err(err("a face needs three vertices".into()));
                    }
                    triangles.extend((1..corners.len() - 1).map(|k| [corners[0], corners[k], corners[k + 1]]));
                    face_lines.resize(triangles.len(), number + 1);
                }
                _ => {}
            }
        }
        if let Some((t, &i)) = triangles.iter().enumerate().find_map(|(t, tri)| tri.iter().find(|&&i| i as usize >= positions.len()).map(|i| (t, i))) {
            return Err(MeshError::Obj { line: face_lines[t], reason: format!("vertex {} does not exist ({} vertices)", i + 1, positions.len()) });
        }
        Self::with_smooth_normals(positions, triangles)
    }

    /// A closed axis-aligned box between the corners `lo` and `hi`, each face wound
    /// counter-clockwise seen from outside, with its own flat normals.
    pub fn cuboid(lo: Vec3, hi: Vec3) -> Self {
        let c = 0.5 * (lo + hi);
        let h = 0.5 * (hi - lo);
        let mut mesh = Self::quad(c + Vec3::Y * h.y, Vec3::Z * h.z, Vec3::X * h.x);
        for (n, u, v) in [
            (Vec3::NEG_Y, Vec3::X * h.x, Vec3::Z * h.z),
            (Vec3::X, Vec3::Y * h.y, Vec3::Z * h.z),
            (Vec3::NEG_X, Vec3::Z * h.z, Vec3::Y * h.y),
            (Vec3::Z, Vec3::X * h.x, Vec3::Y * h.y),
            (Vec3::NEG_Z, Vec3::Y * h.y, Vec3::X * h.x),
        ] {
            mesh.append(&Self::quad(c + n * n.abs().dot(h), u, v));
        }
        mesh
    }

    /// A UV sphere with `rings` latitude bands and `segments` longitude slices and
    /// exact outward normals.
    pub fn uv_sphere(center: Vec3, radius: f32, rings: usize, segments: usize) -> Self {
        let (rings, segments) = (rings.max(2), segments.max(3));
        let mut positions = Vec::new();
        let mut normals = Vec::new();
        for r in 0..=rings {
            let theta = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..=segments {
                let phi = std::f32::consts::TAU * s as f32 / segments as f32;
                let n = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
                positions.push(center + radius * n);
                normals.push(n);
            }
        }
        let row = (segments + 1) as u32;
        let mut triangles = Vec::new();
        for r in 0..rings as u32 {
            for s in 0..segments as u32 {
                let a = r * row + s;
                let (b, c, d) = (a + row, a + 1, a + row + 1);
                if r != 0 {
                    triangles.push([a, c, b]);
                }
                if r + 1 != rings as u32 {
                    triangles.push([c, d, b]);
                }
            }
        }
        Self { positions, normals, triangles }
    }

    /// The inner wall of an open cylinder (a ring seen from inside: normals point to
    /// the axis), axis along +y, standing on `base`.
    pub fn ring(base: Vec3, radius: f32, height: f32, segments: usize) -> Self {
        let segments = segments.max(3);
        let mut positions = Vec::new();
        let mut normals = Vec::new();
        for s in 0..=segments {
            let phi = std::f32::consts::TAU * s as f32 / segments as f32;
            let out = Vec3::new(phi.cos(), 0.0, phi.sin());
            for y in [0.0, height] {
                positions.push(base + radius * out + Vec3::Y * y);
                normals.push(-out);
            }
        }
        let mut triangles = Vec::new();
        for s in 0..segments as u32 {
            let (a, b, c, d) = (2 * s, 2 * s + 1, 2 * s + 2, 2 * s + 3);
            // Counter-clockwise seen from the axis, the side the normals face.
            triangles.push([a, c, b]);
            triangles.push([c, d, b]);
        }
        Self { positions, normals, triangles }
    }

    /// A closed solid ring (a napkin ring), axis along +y, standing on `base`: the inner
    /// wall (normals to the axis), the outer wall (normals away) and the top and bottom
    /// annuli, `segments` around, smooth around the circle.
    pub fn solid_ring(base: Vec3, inner_radius: f32, outer_radius: f32, height: f32, segments: usize) -> Self {
        let segments = segments.max(3);
        let mut mesh = Self::ring(base, inner_radius, height, segments);
        let mut outer = Self::ring(base, outer_radius, height, segments);
        for n in &mut outer.normals {
            *n = -*n;
        }
        for t in &mut outer.triangles {
            t.swap(1, 2);
        }
        mesh.append(&outer);
        for (y, up) in [(height, Vec3::Y), (0.0, Vec3::NEG_Y)] {
            let offset = mesh.positions.len() as u32;
            for s in 0..=segments {
                let phi = std::f32::consts::TAU * s as f32 / segments as f32;
                let out = Vec3::new(phi.cos(), 0.0, phi.sin());
                for r in [inner_radius, outer_radius] {
                    mesh.positions.push(base + r * out + Vec3::Y * y);
                    mesh.normals.push(up);
                }
            }
            for s in 0..segments as u32 {
                let (a, b, c, d) = (offset + 2 * s, offset + 2 * s + 1, offset + 2 * s + 2, offset + 2 * s + 3);
                let (t1, t2) = if up.y > 0.0 { ([a, c, b], [b, c, d]) } else { ([a, b, c], [b, d, c]) };
                mesh.triangles.push(t1);
                mesh.triangles.push(t2);
            }
        }
        mesh
    }

    /// Whether the mesh is watertight: once vertices closer than [`WELD_TOLERANCE`] of
    /// the bounding-box diagonal are merged, every edge is shared by exactly two
    /// triangles, once in each direction (a consistently wound 2-manifold). Triangles
    /// that collapse when welded are ignored. Exporters split vertices at UV seams and
    /// hard edges, so the same corner comes as several vertices; welding by position
    /// sees through that.
    pub fn is_closed(&self) -> bool {
        let (lo, hi) = self.bounds();
        let weld = WELD_TOLERANCE * (hi - lo).length();
        let ids = weld_positions(&self.positions, weld);
        let mut edges: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
        for tri in &self.triangles {
            let [a, b, c] = tri.map(|i| ids[i as usize]);
            if a == b || b == c || c == a {
                continue;
            }
            for (from, to) in [(a, b), (b, c), (c, a)] {
                *edges.entry((from, to)).or_insert(0) += 1;
            }
        }
        !edges.is_empty() && edges.iter().all(|(&(from, to), &n)| n == 1 && edges.get(&(to, from)) == Some(&1))
    }

    /// Appends `other` to this mesh.
    pub fn append(&mut self, other: &TriMesh) {
        let offset = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.triangles.extend(other.triangles.iter().map(|t| t.map(|i| i + offset)));
    }
}

//! Splatting gathered photons into a caustic map, and reading it back as irradiance
//! (Wyman 2008 §3.3).
//!
//! Every splat is a tent `(1 − |s|)(1 − |t|)` over its footprint, `(s, t) = A⁻¹(q − c)`
//! for texel centre `q`, splat centre `c` and the splat's half-axes `A` (a symmetric
//! 2×2 matrix, in texels), normalised by its discrete sum, so a splat deposits exactly
//! its photon's flux (less what falls off the map); `A = I` is bilinear splatting.
//! **Fixed** splats are round, `A = (D/2)·I` for one diameter `D` in the
//! full-resolution map. **Variable** splats take their footprint from the photon's
//! divergence (§3.3), past the paper anisotropically: `A = √(J Jᵀ)` for the columns of
//! `J` the photon's spacing to its neighbours along the buffer's rows and along its
//! columns (central differences, in caustic-map texels), so that on a locally affine
//! mapping the splats tile the map as bilinear splats tile a grid. The paper's round
//! splat of twice the largest neighbour distance (its approximation of eqs. 1–2) covers
//! that, and where photons converge in one direction and spread in the other (the
//! focal lines) it blurs the converged direction by the spread: on `mirror_bunny` at
//! the defaults it read 0.210 relative L1 against the anisotropic splats' 0.14. A photon
//! missing its neighbours along a row or a column keeps the round splat. A splat goes
//! into level `L = ⌊log₂ max(1, D/5)⌋` of a mipmap pyramid of maps, `D` the diameter of
//! the round splat of its area (`2√det A`), or higher until its longer half-axis is
//! at most [`MAX_SPLAT_RADIUS`] texels of its level; there its half-axes are `A/2ᴸ`,
//! each between 1 and [`MAX_SPLAT_RADIUS`] texels. The levels are summed as
//! `C = Σ Cᵢ/4ⁱ` (eq. 3), each upsampled bilinearly (which keeps each level's sum
//! exactly). The paper drops splats above level 3; [`LevelOverflow`] measures that
//! against clamping them into the top level.
//!
//! Flux accumulates in fixed point (2⁻²⁰ of a photon unit, 64 bits): sums do not
//! depend on the order photons arrive in, so gathers that hand on the same photons
//! make the same map, bit for bit, on the CPU as on the GPU's integer atomics.

use super::hierarchy::{GatherEntry, PhotonPyramid, children};
use super::light_maps::{LightMaps, NO_SURFACE};
use super::light_view::LightView;
use super::photons::PhotonBuffer;
use super::{LevelOverflow, MIN_SPLAT_DIAMETER, SPLAT_LEVEL_THRESHOLD, Splats};
use glam::{Mat2, Vec2, Vec3};

/// Fixed-point units per photon flux unit.
pub const FLUX_UNITS: f32 = 1_048_576.0;

/// Largest splat radius, in texels of its level, that a clamped splat keeps.
pub const MAX_SPLAT_RADIUS: f32 = 16.0;

/// A multi-resolution caustic map: level `i` is `(resolution >> i)²` texels of
/// fixed-point flux, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct CausticMap {
    /// Side of level 0, the full-resolution map, in texels.
    pub resolution: u32,
    /// Level `i`'s `(resolution >> i)²` texels, row-major, of fixed-point flux
    /// ([`FLUX_UNITS`] per photon unit).
    pub levels: Vec<Vec<u64>>,
}

/// What splatting did with the flux it was handed (photon units, f64).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SplatStats {
    /// Splats written to each level.
    pub per_level: Vec<u64>,
    /// Flux handed to the splats.
    pub flux_in: f64,
    /// Flux of the splats above the top level that were dropped (the paper's cap).
    pub flux_dropped_by_cap: f64,
    /// Flux of kernels that fell off the map.
    pub flux_off_map: f64,
}

/// A splat: where, how much and its footprint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Splat {
    /// Caustic-map coordinates of its centre, in `[0, 1]²`.
    pub uv: Vec2,
    /// Flux in photon units.
    pub flux: f32,
    /// Its half-axes in full-resolution texels, a symmetric matrix (module docs).
    pub axes: Mat2,
}

impl Splat {
    /// A round splat of `diameter` full-resolution texels.
    pub fn round(uv: Vec2, flux: f32, diameter: f32) -> Self {
        Self { uv, flux, axes: round_axes(diameter) }
    }

    /// The diameter of the round splat of the same area, `2√det A`, in full-resolution
    /// texels: what picks the splat's level.
    pub fn diameter(&self) -> f32 {
        2.0 * self.axes.determinant().abs().sqrt()
    }
}

/// The half-axes of a round splat of `diameter` texels.
pub fn round_axes(diameter: f32) -> Mat2 {
    Mat2::from_diagonal(Vec2::splat(0.5 * diameter))
}

/// The level of a splat of `diameter` full-resolution texels: `⌊log₂ max(1, D/5)⌋`,
/// by exact doublings so that the CPU and the GPU agree at powers of two.
#[inline]
pub fn splat_level(diameter: f32) -> u32 {
    let mut level = 0;
    while level < 31 && diameter >= SPLAT_LEVEL_THRESHOLD * (2u32 << level) as f32 {
        level += 1;
    }
    level
}

/// The level of `splat` in a map whose top level is `top`: [`splat_level`] of its
/// diameter, raised (up to `top`) until its longer half-axis fits in
/// [`MAX_SPLAT_RADIUS`] texels of the level. It passes `top` only where the diameter
/// alone does (the caller then drops or clamps the splat).
pub fn splat_level_of(splat: &Splat, top: u32) -> u32 {
    let mut level = splat_level(splat.diameter());
    let longer = half_axis_lengths(splat.axes).1;
    while level < top && longer > MAX_SPLAT_RADIUS * (1u32 << level) as f32 {
        level += 1;
    }
    level
}

/// Diameter of a round variable splat for photon `(x, y)`: twice the largest distance
/// to its valid 4-neighbours in caustic-map texels, or where it has none twice `M/P`
/// texels (the spacing of a photon buffer spread over the whole map); at least
/// [`MIN_SPLAT_DIAMETER`].
pub fn divergence_diameter(photons: &PhotonBuffer, x: u32, y: u32, map_resolution: u32) -> f32 {
    let n = photons.resolution;
    let here = photons.photon(x, y).uv;
    let mut largest = -1.0f32;
    let neighbours = [(x.wrapping_sub(1), y), (x + 1, y), (x, y.wrapping_sub(1)), (x, y + 1)];
    for (nx, ny) in neighbours {
        if nx < n && ny < n {
            let p = photons.photon(nx, ny);
            if p.is_valid() {
                largest = largest.max(((p.uv - here) * map_resolution as f32).length());
            }
        }
    }
    let spacing = if largest < 0.0 { map_resolution as f32 / n as f32 } else { largest };
    (2.0 * spacing).max(MIN_SPLAT_DIAMETER)
}

/// The half-axes of photon `(x, y)`'s variable splat, in full-resolution texels:
/// `√(J Jᵀ)` for its spacings `J` along the buffer's row and column (the central
/// difference of the two neighbours, or the one valid), or the round splat of
/// [`divergence_diameter`] where a row or a column has no valid neighbour.
pub fn divergence_axes(photons: &PhotonBuffer, x: u32, y: u32, map_resolution: u32) -> Mat2 {
    let n = photons.resolution;
    let here = photons.photon(x, y).uv;
    let offset = |nx: u32, ny: u32| {
        let p = (nx < n && ny < n).then(|| photons.photon(nx, ny)).filter(|p| p.is_valid());
        p.map(|p| (p.uv - here) * map_resolution as f32)
    };
    let spacing = |before: Option<Vec2>, after: Option<Vec2>| match (before, after) {
        (Some(b), Some(a)) => Some(0.5 * (a - b)),
        (None, Some(a)) => Some(a),
        (Some(b), None) => Some(-b),
        (None, None) => None,
    };
    let row = spacing(offset(x.wrapping_sub(1), y), offset(x + 1, y));
    let column = spacing(offset(x, y.wrapping_sub(1)), offset(x, y + 1));
    match row.zip(column) {
        Some((u, v)) => {
            let j = Mat2::from_cols(u, v);
            spd_sqrt(j * j.transpose())
        }
        None => round_axes(divergence_diameter(photons, x, y, map_resolution)),
    }
}

/// The square root of a symmetric positive semi-definite 2×2 matrix `M`:
/// `(M + √det M · I) / √(tr M + 2√det M)`; zero for zero.
pub fn spd_sqrt(m: Mat2) -> Mat2 {
    let s = m.determinant().max(0.0).sqrt();
    let t = (m.x_axis.x + m.y_axis.y + 2.0 * s).sqrt();
    if t > 0.0 { (m + Mat2::from_diagonal(Vec2::splat(s))) * (1.0 / t) } else { Mat2::ZERO }
}

/// The shorter and the longer half-axis of symmetric `a` (its eigenvalues).
pub fn half_axis_lengths(a: Mat2) -> (f32, f32) {
    let (mean, gap) = eigen_spread(a);
    (mean - gap, mean + gap)
}

/// Half the trace of symmetric `a` and half its eigenvalues' difference.
fn eigen_spread(a: Mat2) -> (f32, f32) {
    let mean = 0.5 * (a.x_axis.x + a.y_axis.y);
    let half_difference = 0.5 * (a.x_axis.x - a.y_axis.y);
    (mean, half_difference.hypot(a.y_axis.x))
}

/// Symmetric `a` with its eigenvalues clamped to `[low, high]`: `c₂I + (c₁ − c₂)vvᵀ`
/// for the clamped eigenvalues `c₁ ≥ c₂` and `v` the unit eigenvector of the larger.
pub fn clamp_half_axes(a: Mat2, low: f32, high: f32) -> Mat2 {
    let (mean, gap) = eigen_spread(a);
    let (longer, shorter) = ((mean + gap).clamp(low, high), (mean - gap).clamp(low, high));
    let (p, b, r) = (a.x_axis.x, a.y_axis.x, a.y_axis.y);
    let v = if p >= r { Vec2::new(mean + gap - r, b) } else { Vec2::new(b, mean + gap - p) };
    let length = v.length();
    if !(length > 0.0) {
        return Mat2::from_diagonal(Vec2::splat(shorter));
    }
    let v = v / length;
    let d = longer - shorter;
    Mat2::from_cols(Vec2::new(shorter + d * v.x * v.x, d * v.x * v.y), Vec2::new(d * v.x * v.y, shorter + d * v.y * v.y))
}

/// The splat of a gathered entry.
pub fn entry_splat(photons: &PhotonBuffer, pyramid: &PhotonPyramid, entry: GatherEntry, splats: Splats, map_resolution: u32) -> Splat {
    let node = pyramid.node(entry.level, entry.node);
    let fixed = match splats {
        Splats::Fixed { diameter } => Some(diameter.max(MIN_SPLAT_DIAMETER)),
        Splats::Variable { .. } => None,
    };
    if entry.level == 0 {
        let (x, y) = (entry.node % photons.resolution, entry.node / photons.resolution);
        let photon = photons.photon(x, y);
        match fixed {
            Some(diameter) => Splat::round(photon.uv, photon.flux, diameter),
            None => Splat { uv: photon.uv, flux: photon.flux, axes: divergence_axes(photons, x, y, map_resolution) },
        }
    } else {
        // Converged photons share a texel: a cluster is as narrow as a splat gets.
        Splat::round(node.moment / node.flux, node.flux, fixed.unwrap_or(MIN_SPLAT_DIAMETER))
    }
}

/// The columns of row `y` that a footprint centred at `p` may cover, within `columns`
/// (inclusive, empty where the first passes the last): the `x` with `|s|, |t| ≤ 1` for
/// `(s, t) = to_footprint · ((x, y) − p)`, a parallelogram's chord, widened by a
/// hundredth of a texel so that rounding never drops a texel of positive weight. A
/// splat walks these rather than its box, whose corners a long, slanted footprint
/// leaves empty.
pub fn row_span(to_footprint: Mat2, p: Vec2, y: f32, columns: (f32, f32)) -> (f32, f32) {
    let dy = y - p.y;
    let (mut low, mut high) = (columns.0 - p.x, columns.1 - p.x);
    for (a, b) in [(to_footprint.x_axis.x, to_footprint.y_axis.x), (to_footprint.x_axis.y, to_footprint.y_axis.y)] {
        // |a·dx + b·dy| ≤ 1.
        let c = b * dy;
        if a != 0.0 {
            let (u, v) = ((-1.0 - c) / a, (1.0 - c) / a);
            (low, high) = (low.max(u.min(v)), high.min(u.max(v)));
        } else if c.abs() > 1.0 {
            return (1.0, 0.0);
        }
    }
    ((p.x + low - 0.01).ceil().max(columns.0), (p.x + high + 0.01).floor().min(columns.1))
}

/// The tent's weight at `t` footprint radii from its centre.
#[inline]
fn tent(t: f32) -> f32 {
    (1.0 - t.abs()).max(0.0)
}

impl CausticMap {
    /// An empty map with levels `0..=top_level`.
    pub fn new(resolution: u32, top_level: u32) -> Self {
        let levels = (0..=top_level).map(|l| vec![0u64; ((resolution >> l).max(1) as usize).pow(2)]).collect();
        Self { resolution, levels }
    }

    /// An empty map with the levels `splats` write to: level 0 for fixed splats, up to
    /// `max_level` for variable ones.
    pub fn for_splats(splats: Splats, resolution: u32) -> Self {
        let top = match splats {
            Splats::Fixed { .. } => 0,
            Splats::Variable { max_level, .. } => max_level.min(resolution.ilog2()),
        };
        Self::new(resolution, top)
    }

    /// Splats every entry into a new map ([`Self::splat_entries`]).
    pub fn splat_all(photons: &PhotonBuffer, pyramid: &PhotonPyramid, entries: &[GatherEntry], splats: Splats, resolution: u32) -> (Self, SplatStats) {
        let mut map = Self::for_splats(splats, resolution);
        let mut stats = SplatStats::default();
        map.splat_entries(photons, pyramid, entries, splats, &mut stats);
        (map, stats)
    }

    /// Adds the splat of every entry, and counts it in `stats`. Fixed splats use level
    /// 0; variable ones the level their diameter picks, up to the map's top level.
    pub fn splat_entries(&mut self, photons: &PhotonBuffer, pyramid: &PhotonPyramid, entries: &[GatherEntry], splats: Splats, stats: &mut SplatStats) {
        let top = self.levels.len() as u32 - 1;
        stats.per_level.resize(self.levels.len(), 0);
        for &entry in entries {
            let splat = entry_splat(photons, pyramid, entry, splats, self.resolution);
            stats.flux_in += splat.flux as f64;
            let mut level = splat_level_of(&splat, top);
            if level > top {
                match splats {
                    Splats::Variable { overflow: LevelOverflow::Discard, .. } => {
                        stats.flux_dropped_by_cap += splat.flux as f64;
                        continue;
                    }
                    _ => level = top,
                }
            }
            stats.per_level[level as usize] += 1;
            stats.flux_off_map += self.splat(splat, level);
        }
    }

    /// Adds one splat to `level`, its half-axes `A/2ᴸ` there clamped to
    /// `[1, MAX_SPLAT_RADIUS]` texels; returns the flux that fell off the map.
    pub fn splat(&mut self, splat: Splat, level: u32) -> f64 {
        let width = (self.resolution >> level).max(1);
        let axes = clamp_half_axes(splat.axes * (1.0 / (1u32 << level) as f32), 1.0, MAX_SPLAT_RADIUS);
        let to_footprint = axes.inverse();
        let p = splat.uv * width as f32 - 0.5;
        // The footprint's box: the parallelogram `p + A[−1, 1]²`.
        let reach = axes.x_axis.abs() + axes.y_axis.abs();
        let (x0, x1) = ((p.x - reach.x).floor() as i64, (p.x + reach.x).ceil() as i64);
        let (y0, y1) = ((p.y - reach.y).floor() as i64, (p.y + reach.y).ceil() as i64);
        let weight = |x: i64, y: i64| {
            let st = to_footprint * (Vec2::new(x as f32, y as f32) - p);
            tent(st.x) * tent(st.y)
        };
        let row = |y: i64| {
            let (from, to) = row_span(to_footprint, p, y as f32, (x0 as f32, x1 as f32));
            (from as i64, to as i64)
        };
        let mut sum = 0.0f32;
        for y in y0..=y1 {
            let (from, to) = row(y);
            for x in from..=to {
                sum += weight(x, y);
            }
        }
        let scale = splat.flux * FLUX_UNITS / sum;
        let texels = &mut self.levels[level as usize];
        let mut off_map = 0.0f64;
        for y in y0..=y1 {
            let (from, to) = row(y);
            for x in from..=to {
                let w = weight(x, y);
                if w <= 0.0 {
                    continue;
                }
                if x < 0 || y < 0 || x >= width as i64 || y >= width as i64 {
                    off_map += (splat.flux * w / sum) as f64;
                    continue;
                }
                texels[(y as u32 * width + x as u32) as usize] += fixed_point(scale * w);
            }
        }
        off_map
    }

    /// Level `level`'s texel `(x, y)` in photon units.
    #[inline]
    pub fn value(&self, level: u32, x: u32, y: u32) -> f32 {
        let width = (self.resolution >> level).max(1);
        from_fixed_point(self.levels[level as usize][(y * width + x) as usize])
    }

    /// The full-resolution map `C = Σᵢ Cᵢ / 4ⁱ` (eq. 3), each level bilinearly
    /// upsampled to the full-resolution texel centres (clamped at the edges): photon
    /// units per full-resolution texel, row-major.
    pub fn resolve(&self) -> Vec<f32> {
        let m = self.resolution;
        (0..m * m)
            .map(|i| {
                let (x, y) = (i % m, i / m);
                let mut c = 0.0f32;
                for level in 0..self.levels.len() as u32 {
                    let width = (m >> level).max(1);
                    let q = (Vec2::new(x as f32, y as f32) + 0.5) / (1u32 << level) as f32 - 0.5;
                    let v = bilinear(q, width, |tx, ty| self.value(level, tx, ty));
                    c += v / (1u32 << (2 * level)) as f32;
                }
                c
            })
            .collect()
    }

    /// Total flux in the map (eq. 3's sum over the full-resolution texels, exactly:
    /// each level's sum).
    pub fn total_flux(&self) -> f64 {
        self.levels.iter().flatten().map(|&v| v as f64 / FLUX_UNITS as f64).sum()
    }
}

/// Fixed-point units of a non-negative flux, rounded to nearest, as the GPU splits it
/// into two 32-bit words.
#[inline]
pub fn fixed_point(value: f32) -> u64 {
    let x = value + 0.5;
    let high = (x * (1.0 / 4_294_967_296.0)).floor();
    let low = x - high * 4_294_967_296.0;
    ((high as u64) << 32) + low as u64
}

/// Photon units of a fixed-point sum, as the GPU converts its two words.
#[inline]
pub fn from_fixed_point(units: u64) -> f32 {
    ((units >> 32) as f32 * 4_294_967_296.0 + (units & 0xffff_ffff) as f32) / FLUX_UNITS
}

/// Bilinear interpolation of a `width²` grid at continuous texel coordinates `q`
/// (texel centres at integers), clamped to the edge texels.
#[inline]
pub fn bilinear(q: Vec2, width: u32, at: impl Fn(u32, u32) -> f32) -> f32 {
    let last = (width - 1) as f32;
    let q = q.clamp(Vec2::ZERO, Vec2::splat(last));
    let base = q.floor();
    let f = q - base;
    let (x0, y0) = (base.x as u32, base.y as u32);
    let (x1, y1) = ((x0 + 1).min(width - 1), (y0 + 1).min(width - 1));
    let top = at(x0, y0) + (at(x1, y0) - at(x0, y0)) * f.x;
    let bottom = at(x0, y1) + (at(x1, y1) - at(x0, y1)) * f.x;
    top + (bottom - top) * f.y
}

/// Whether `p` (with unit normal `n`) is the receiver surface the light sees, not one
/// hidden behind it: its depth is within a slope-scaled bias of the receiver map's.
pub fn visible_from_light(view: &LightView, maps: &LightMaps, p: Vec3, n: Vec3) -> bool {
    let Some(uv) = view.uv(p) else { return false };
    let Some((x, y)) = super::photons::texel_of(uv, maps.map_resolution) else { return false };
    let surface = maps.receiver(x, y);
    if surface >= NO_SURFACE {
        return false;
    }
    let z = view.depth(p);
    let cos = n.dot(view.ray(uv).1).abs().max(0.1);
    let tan = (1.0 - cos * cos).sqrt() / cos;
    z <= surface + view.texel_size(z, maps.map_resolution) * (1.0 + tan) + 1e-5 * z.abs()
}

/// Caustic irradiance at receiver point `p` (unit normal `n`) from a resolved map of
/// `view` (photons traced at `photon_resolution`, a light of `intensity`: irradiance
/// for parallel light, intensity per steradian for a point light): zero where the light
/// does not see `p`. Photon units per texel become flux per image-plane area by
/// `(M·emission/P)²` (a photon's measure over a texel's), and irradiance by the receiver's
/// Jacobian.
pub fn irradiance_at(view: &LightView, maps: &LightMaps, resolved: &[f32], photon_resolution: u32, intensity: f32, p: Vec3, n: Vec3) -> f32 {
    if !visible_from_light(view, maps, p, n) {
        return 0.0;
    }
    let m = maps.map_resolution;
    let Some(uv) = view.uv(p) else { return 0.0 };
    let c = bilinear(uv * m as f32 - 0.5, m, |x, y| resolved[(y * m + x) as usize]);
    let ratio = view.map_texels_per_photon(photon_resolution, m);
    c * intensity * ratio * ratio * view.receiver_jacobian(p, n)
}

/// The photon buffer texels (row-major indices) below node `index` of pyramid level `level`.
pub fn photons_below(pyramid: &PhotonPyramid, level: u32, index: u32) -> Vec<u32> {
    let mut nodes = vec![index];
    for l in (1..=level).rev() {
        let width = pyramid.width(l);
        nodes = nodes.iter().flat_map(|&i| children(i % width, i / width).map(|(x, y)| y * 2 * width + x)).collect();
    }
    nodes
}

//! The photon pyramid and its traversal (Wyman 2008 §3.1–3.2).
//!
//! The pyramid is a mipmap of the photon buffer in which a node knows whether any
//! photon below it is valid, which caustic-map texel its photons all land in (if they
//! do), their summed flux and flux-weighted mean position. The hierarchical gather
//! walks it breadth first from the level of `16²` nodes (§3.1: coarser levels discard
//! too little to pay), dropping every node with no valid photon below it and handing
//! the children of the others to the next level; what reaches the photon buffer's own
//! level is gathered photon by photon. With clustering (§3.2), a node whose photons
//! all land in one caustic-map texel is gathered as one photon that carries their
//! flux, instead of descending: at the last level only (the paper's "combine last") or
//! at every level ("combine all"). The flat gather, the baseline, processes every
//! photon of the buffer.
//!
//! Past the paper: a cluster carries the exact sum of its photons' flux (the paper
//! multiplies one photon's intensity by `4ⁱ`, which assumes its children are all valid
//! and equally bright) at their flux-weighted mean position, and a node with a single
//! valid photon is not clustered (that photon keeps its own splat). [`gather`] is the
//! CPU twin of the GPU's traversal: given the same photon buffer it gathers the same
//! photons and the same clusters.

use super::photons::PhotonBuffer;
use super::{Clustering, Gather};
use glam::Vec2;

/// [`Node::texel`] of a node with no valid photon below it.
pub const EMPTY: u32 = u32::MAX - 1;
/// [`Node::texel`] of a node whose photons land in more than one caustic-map texel.
pub const DIVERSE: u32 = u32::MAX;

/// One node of the pyramid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// The caustic-map texel (`row · resolution + column`) all its photons land in,
    /// [`EMPTY`] or [`DIVERSE`].
    pub texel: u32,
    /// Summed flux of its photons.
    pub flux: f32,
    /// Summed `flux · uv`.
    pub moment: Vec2,
    /// How many photons (exact up to 2²⁴).
    pub count: f32,
}

impl Node {
    /// A node with no valid photon below it.
    pub const EMPTY: Self = Self { texel: EMPTY, flux: 0.0, moment: Vec2::ZERO, count: 0.0 };

    /// The node of one photon buffer texel in a `map_resolution²` caustic map.
    #[inline]
    pub fn of_photon(photon: &super::photons::Photon, map_resolution: u32) -> Self {
        if !photon.is_valid() {
            return Self::EMPTY;
        }
        let t = (photon.uv * map_resolution as f32).as_uvec2().min(glam::UVec2::splat(map_resolution - 1));
        Self { texel: t.y * map_resolution + t.x, flux: photon.flux, moment: photon.uv * photon.flux, count: 1.0 }
    }

    /// The parent of four children, summed in the order given (the GPU's order).
    #[inline]
    pub fn parent(children: [Node; 4]) -> Self {
        let texel = children.iter().fold(EMPTY, |acc, c| match (acc, c.texel) {
            (_, EMPTY) => acc,
            (EMPTY, t) => t,
            (a, t) if a == t => a,
            _ => DIVERSE,
        });
        let [a, b, c, d] = children;
        Self {
            texel,
            flux: ((a.flux + b.flux) + c.flux) + d.flux,
            moment: ((a.moment + b.moment) + c.moment) + d.moment,
            count: ((a.count + b.count) + c.count) + d.count,
        }
    }

    /// Whether any valid photon lies below.
    #[inline]
    pub fn is_occupied(&self) -> bool {
        self.texel != EMPTY
    }

    /// Whether its photons converge: at least two, all in one caustic-map texel (§3.2).
    #[inline]
    pub fn converges(&self) -> bool {
        self.texel < EMPTY && self.count >= 2.0
    }
}

/// The mipmap of a photon buffer: `levels[0]` is the buffer itself, `levels[k]` has
/// `(resolution >> k)²` nodes, row-major, up to a single root.
#[derive(Clone, Debug, PartialEq)]
pub struct PhotonPyramid {
    /// Side of the photon buffer (level 0), in nodes.
    pub resolution: u32,
    /// Level `k`'s `(resolution >> k)²` nodes, row-major.
    pub levels: Vec<Vec<Node>>,
}

/// The four children of node `(x, y)`, in summation order.
#[inline]
pub fn children(x: u32, y: u32) -> [(u32, u32); 4] {
    [(2 * x, 2 * y), (2 * x + 1, 2 * y), (2 * x, 2 * y + 1), (2 * x + 1, 2 * y + 1)]
}

impl PhotonPyramid {
    /// Builds the pyramid of `photons` (a power-of-two square) for a
    /// `map_resolution²` caustic map.
    pub fn new(photons: &PhotonBuffer, map_resolution: u32) -> Self {
        Self::up_to(photons, map_resolution, u32::MAX)
    }

    /// What `gather` reads of the pyramid: the photon buffer's own level for the flat
    /// gather (which needs no hierarchy, on the GPU either), every level otherwise.
    pub fn for_gather(photons: &PhotonBuffer, map_resolution: u32, gather: Gather) -> Self {
        let top = if gather == Gather::Flat { 0 } else { u32::MAX };
        Self::up_to(photons, map_resolution, top)
    }

    fn up_to(photons: &PhotonBuffer, map_resolution: u32, top: u32) -> Self {
        let mut levels = vec![photons.photons.iter().map(|p| Node::of_photon(p, map_resolution)).collect::<Vec<_>>()];
        let mut width = photons.resolution;
        while width > 1 && (levels.len() as u32) <= top {
            let below = levels.last().expect("level 0 exists");
            let half = width / 2;
            let level = (0..half * half).map(|i| Node::parent(children(i % half, i / half).map(|(x, y)| below[(y * width + x) as usize]))).collect();
            levels.push(level);
            width = half;
        }
        Self { resolution: photons.resolution, levels }
    }

    /// Number of levels above the photon buffer.
    pub fn top_level(&self) -> u32 {
        self.levels.len() as u32 - 1
    }

    /// Node `index` (row-major) of `level`.
    #[inline]
    pub fn node(&self, level: u32, index: u32) -> Node {
        self.levels[level as usize][index as usize]
    }

    /// Width of `level` in nodes.
    #[inline]
    pub fn width(&self, level: u32) -> u32 {
        self.resolution >> level
    }
}

/// The level the hierarchical gather starts from: the one `start_resolution` nodes
/// wide (or the buffer itself, if it is no wider).
pub fn start_level(resolution: u32, start_resolution: u32) -> u32 {
    (resolution.max(1).ilog2()).saturating_sub(start_resolution.max(1).ilog2())
}

/// One gathered photon or cluster: node `node` (row-major) of pyramid level `level`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct GatherEntry {
    /// Pyramid level: 0 is the photon buffer.
    pub level: u32,
    /// Row-major index of the node within its level.
    pub node: u32,
}

impl GatherEntry {
    /// An entry of the GPU's gathered list: the level in the top eight bits, the node
    /// (below 2²⁴) in the rest.
    pub fn unpacked(packed: u32) -> Self {
        Self { level: packed >> 24, node: packed & 0x00ff_ffff }
    }
}

/// How many nodes each stage processed: the count the paper's speed-up comes from,
/// the same on any hardware.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GatherStats {
    /// Nodes examined at each level (index = level; level 0: photons).
    pub processed: Vec<u64>,
    /// Photons gathered one by one.
    pub photons: u64,
    /// Clusters gathered.
    pub clusters: u64,
    /// Photons the clusters stand for.
    pub clustered_photons: u64,
}

impl GatherStats {
    /// Nodes examined in all.
    pub fn total_processed(&self) -> u64 {
        self.processed.iter().sum()
    }

    /// Splats the gather hands on.
    pub fn splats(&self) -> u64 {
        self.photons + self.clusters
    }

    /// Adds `other`'s counts (another photon buffer's gather into the same map).
    pub fn add(&mut self, other: &Self) {
        if self.processed.len() < other.processed.len() {
            self.processed.resize(other.processed.len(), 0);
        }
        self.processed.iter_mut().zip(&other.processed).for_each(|(a, b)| *a += b);
        self.photons += other.photons;
        self.clusters += other.clusters;
        self.clustered_photons += other.clustered_photons;
    }
}

/// The photons and clusters to splat, in traversal order, with what the traversal
/// processed. Photons are gathered at level 0; clusters at the level they converge.
pub fn gather(pyramid: &PhotonPyramid, gather: Gather) -> (Vec<GatherEntry>, GatherStats) {
    // One count per level of the photon buffer's mipmap, built or not.
    let levels = pyramid.resolution.max(1).ilog2() as usize + 1;
    let mut stats = GatherStats { processed: vec![0; levels], ..GatherStats::default() };
    let mut entries = Vec::new();
    let (start, clustering) = match gather {
        Gather::Flat => (0, Clustering::Off),
        Gather::Hierarchical { clustering } => (start_level(pyramid.resolution, super::START_RESOLUTION), clustering),
    };
    let width = pyramid.width(start);
    let mut list: Vec<u32> = (0..width * width).collect();
    for level in (1..=start).rev() {
        stats.processed[level as usize] = list.len() as u64;
        let width = pyramid.width(level);
        let clusters_here = match clustering {
            Clustering::Off => false,
            Clustering::LastLevel => level == 1,
            Clustering::AllLevels => true,
        };
        let mut next = Vec::with_capacity(list.len() * 4);
        for &index in &list {
            let node = pyramid.node(level, index);
            if !node.is_occupied() {
                continue;
            }
            if clusters_here && node.converges() {
                entries.push(GatherEntry { level, node: index });
                stats.clusters += 1;
                stats.clustered_photons += node.count as u64;
                continue;
            }
            for (x, y) in children(index % width, index / width) {
                next.push(y * (2 * width) + x);
            }
        }
        list = next;
    }
    stats.processed[0] = list.len() as u64;
    for &index in &list {
        if pyramid.node(0, index).is_occupied() {
            entries.push(GatherEntry { level: 0, node: index });
            stats.photons += 1;
        }
    }
    (entries, stats)
}

//! Illumination textures (Iwasaki, Dobashi, Yoshimoto & Nishita, "A Fast Rendering
//! Technique of Transparent Objects and Caustics"): caustics from a rigid transparent
//! object, through a light transport table precomputed once per mesh (§3, after
//! Iwasaki et al. 2004 [12]), onto virtual planes around the receivers (§4).
//!
//! This stop brings the table ([`LightTransportTable`]); the virtual planes, their
//! illumination textures and the lookup at receiver points follow (issue 11).

mod transport;

pub use transport::{
    CacheOutcome, DirectionGrid, LightTransportTable, TRANSPORT_CACHE_VERSION, TransportBuild, TransportError, TransportStats,
    Transported,
};

//! Illumination textures (Iwasaki, Dobashi, Yoshimoto & Nishita, "A Fast Rendering
//! Technique of Transparent Objects and Caustics"): caustics from a rigid transparent
//! object, through a light transport table precomputed once per mesh (§3, after
//! Iwasaki et al. 2004 [12]), onto virtual planes around the receivers (§4).
//!
//! Here: the table ([`LightTransportTable`]) and the CPU twin of the virtual planes,
//! their illumination textures and the lookup at receiver points
//! ([`IlluminationTextures`]); `caustics_bevy::illumination_textures` draws the same
//! on the GPU.

mod planes;
mod transport;

pub use planes::{
    Cosine, IlluminationPlane, IlluminationSettings, IlluminationTextures, IlluminationVolume, MAX_MAGNIFICATION, SHADOW_SLACK_TEXELS, SOLID_SPANS, SeenSurface,
};
pub use transport::{CacheOutcome, DirectionGrid, LightTransportTable, TRANSPORT_CACHE_VERSION, TransportBuild, TransportError, TransportStats, Transported};

//! What the CPU algorithms see of a scene: lights, specular generators and diffuse
//! receivers, all in world space. The Bevy crate builds one from the ECS; the
//! procedural scenes in [`crate::scenes`] build one in code.

use crate::mesh::TriMesh;
use crate::params::{ParamError, SpecularInteraction, check_finite};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The emitting part of a light. Flux units follow the light's own: with Bevy's lux
/// and lumens, irradiance comes out in lux.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum LightKind {
    /// Parallel light travelling along `direction`, with irradiance `irradiance` on a
    /// plane perpendicular to the beam.
    Directional {
        /// The way the light travels; any non-zero length.
        direction: Vec3,
        /// Irradiance on a plane perpendicular to the beam (lux).
        irradiance: f32,
    },
    /// Isotropic point source of radiant intensity `intensity` (per steradian), so
    /// irradiance at distance r under normal incidence is `intensity / r²`.
    Point {
        /// Where the light is (m).
        position: Vec3,
        /// Intensity per steradian (candela).
        intensity: f32,
    },
    /// A point source restricted to a cone along `direction`, with Bevy's falloff
    /// between `inner_angle` and `outer_angle` (half-angles, radians).
    Spot {
        /// Where the light is (m).
        position: Vec3,
        /// The cone's axis, the way the light points; any non-zero length.
        direction: Vec3,
        /// Intensity per steradian inside the inner cone (candela).
        intensity: f32,
        /// Half-angle at which the falloff starts (radians).
        inner_angle: f32,
        /// Half-angle at which the light ends (radians).
        outer_angle: f32,
    },
}

/// The largest irradiance or intensity a light may have in any colour channel (lux or
/// candela): 10¹⁵ times the sun's illuminance, so that the irradiance 1 µm from a point
/// light (`I/r²`, r² clamped at 10⁻¹²) times any area or magnification the techniques
/// apply stays far below `f32::MAX`.
pub const MAX_LIGHT_POWER: f32 = 1e20;

/// A light with a linear RGB colour that scales its flux per channel.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Light {
    /// What the light emits, and from where.
    pub kind: LightKind,
    /// Linear RGB colour: scales the flux per channel.
    pub color: Vec3,
    /// A point or spot light's range (m), as Bevy's `PointLight::range`: its light
    /// fades out towards it ([`Self::range_attenuation`]). Infinite: no end (`null`
    /// in JSON, which has no infinity).
    #[serde(with = "range_or_null")]
    pub range: f32,
}

impl Light {
    /// A white light without a range.
    pub fn white(kind: LightKind) -> Self {
        Self { kind, color: Vec3::ONE, range: f32::INFINITY }
    }

    /// A white linear light, a tube from `a` to `b` of total intensity `intensity`, as
    /// `n` point lights at the middles of `n` equal pieces, each with `intensity / n`
    /// (Iwasaki et al. Fig. 6(d)): every technique then draws it light by light.
    pub fn linear(a: Vec3, b: Vec3, intensity: f32, n: usize) -> Vec<Self> {
        let n = n.max(1);
        (0..n).map(|k| Self::white(LightKind::Point { position: a.lerp(b, (k as f32 + 0.5) / n as f32), intensity: intensity / n as f32 })).collect()
    }

    /// Checks that directions are non-zero, every number finite and non-negative, and
    /// the light no stronger than [`MAX_LIGHT_POWER`].
    pub fn validate(&self) -> Result<(), ParamError> {
        let finite = |name, v: Vec3| {
            check_finite(name, v.x)?;
            check_finite(name, v.y)?;
            check_finite(name, v.z)
        };
        for channel in self.color.to_array() {
            crate::params::check_coefficient("light colour", channel)?;
        }
        if self.range.is_nan() || self.range <= 0.0 {
            return Err(ParamError::OutOfRange { name: "light range", value: self.range, expected: "positive (infinite: no range)" });
        }
        match self.kind {
            LightKind::Directional { direction, irradiance } => {
                finite("light direction", direction)?;
                nonzero(direction)?;
                crate::params::check_coefficient("irradiance", irradiance)?;
            }
            LightKind::Point { position, intensity } => {
                finite("light position", position)?;
                crate::params::check_coefficient("intensity", intensity)?;
            }
            LightKind::Spot { position, direction, intensity, inner_angle, outer_angle } => {
                finite("light position", position)?;
                finite("light direction", direction)?;
                nonzero(direction)?;
                crate::params::check_coefficient("intensity", intensity)?;
                crate::params::check_coefficient("spot inner angle", inner_angle)?;
                crate::params::check_coefficient("spot outer angle", outer_angle)?;
            }
        }
        let (LightKind::Directional { irradiance: power, .. } | LightKind::Point { intensity: power, .. } | LightKind::Spot { intensity: power, .. }) =
            self.kind;
        let strongest = power * self.color.max_element();
        if strongest > MAX_LIGHT_POWER {
            let expected = "at most 1e20 (lux or candela, times the colour's largest channel)";
            return Err(ParamError::OutOfRange { name: "light intensity × colour", value: strongest, expected });
        }
        Ok(())
    }

    /// Bevy's spot cone attenuation: `s = saturate((cos θ − cos θₒ)/(cos θᵢ − cos θₒ))`, squared
    /// (`bevy_pbr` `spot_light` in `lighting.wgsl`). One for other lights.
    pub fn cone_attenuation(&self, dir_from_light: Vec3) -> f32 {
        match self.kind {
            LightKind::Spot { direction, inner_angle, outer_angle, .. } => {
                let (cos_outer, cos_inner) = (outer_angle.cos(), inner_angle.min(outer_angle).cos());
                let scale = 1.0 / (cos_inner - cos_outer).max(1e-4);
                let cd = dir_from_light.dot(direction.normalize_or(Vec3::NEG_Y));
                let s = ((cd - cos_outer) * scale).clamp(0.0, 1.0);
                s * s
            }
            _ => 1.0,
        }
    }

    /// Bevy's window on a point or spot light's inverse-square falloff, for light that
    /// has travelled `distance` metres from it: `saturate(1 − (d/range)⁴)²` (`bevy_pbr`
    /// `getRangeFalloff` in `pbr_lighting.wgsl`), so its light ends at `range`. Caustic
    /// light takes `d` along its whole path, light to generator to receiver, so that a
    /// surface that bends nothing passes exactly Bevy's direct light. One for a
    /// directional light or an infinite range.
    pub fn range_attenuation(&self, distance: f32) -> f32 {
        range_window(distance * distance, self.inverse_range_squared())
    }

    /// `1/range²` of a point or spot light with a range, 0 otherwise (no window).
    pub fn inverse_range_squared(&self) -> f32 {
        match self.kind {
            LightKind::Point { .. } | LightKind::Spot { .. } if self.range.is_finite() => 1.0 / (self.range * self.range),
            _ => 0.0,
        }
    }

    /// Light arriving at `p`: its travel direction and the irradiance on a plane
    /// perpendicular to it (a point or spot light's `I/d²` with the spot's cone; no
    /// range window, which depends on the whole path).
    pub fn incident(&self, p: Vec3) -> (Vec3, f32) {
        match self.kind {
            LightKind::Directional { direction, irradiance } => (direction.normalize(), irradiance),
            LightKind::Point { position, intensity } | LightKind::Spot { position, intensity, .. } => {
                let d = p - position;
                let r2 = d.length_squared().max(1e-12);
                let dir = d / r2.sqrt();
                (dir, intensity / r2 * self.cone_attenuation(dir))
            }
        }
    }

    /// The light's position; `None` for a directional light.
    pub fn position(&self) -> Option<Vec3> {
        match self.kind {
            LightKind::Point { position, .. } | LightKind::Spot { position, .. } => Some(position),
            LightKind::Directional { .. } => None,
        }
    }
}

/// [`Light::range_attenuation`] from the squared distance and `1/range²` (0: none).
#[inline]
pub fn range_window(distance_squared: f32, inverse_range_squared: f32) -> f32 {
    if inverse_range_squared <= 0.0 {
        return 1.0;
    }
    let f = distance_squared * inverse_range_squared;
    let s = (1.0 - f * f).clamp(0.0, 1.0);
    s * s
}

fn nonzero(v: Vec3) -> Result<(), ParamError> {
    if v.length_squared() > 0.0 { Ok(()) } else { Err(ParamError::NotFinite { name: "zero-length light direction", value: 0.0 }) }
}

/// A specular surface that reflects or refracts light into caustics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Generator {
    /// The surface, in world space.
    pub mesh: TriMesh,
    /// Whether it reflects or refracts, and how.
    pub interaction: SpecularInteraction,
    /// glTF's `doubleSided`: whether an open surface reflects or refracts on its back
    /// too ([`Sides`]). The front is the side its vertex normals face and its
    /// triangles wind counter-clockwise on.
    pub double_sided: bool,
}

impl Generator {
    /// A one-sided generator (glTF's default).
    pub fn new(mesh: TriMesh, interaction: SpecularInteraction) -> Self {
        Self { mesh, interaction, double_sided: false }
    }

    /// Which sides of its faces take part in caustics (welds the mesh to tell).
    pub fn sides(&self) -> Sides {
        Sides::of(self.mesh.is_closed(), self.double_sided)
    }
}

/// Which sides of a generator's faces take part in caustics: glTF's `doubleSided` read
/// as offline renderers read a one-sided surface (a one-sided conductor is black from
/// behind), on the surfaces where a back can be lit from outside.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Sides {
    /// A watertight mesh ([`TriMesh::is_closed`]), whatever `doubleSided` says: its
    /// back faces lie inside it. A refractor's are where light leaves it (glTF's
    /// default `doubleSided: false` is on most closed glass); a mirror's are never lit.
    Closed,
    /// An open surface with `doubleSided: false` (glTF's default): light reaching its
    /// back is absorbed.
    #[default]
    Front,
    /// An open surface with `doubleSided: true`: both sides reflect or refract.
    Both,
}

impl Sides {
    /// The sides of a `closed` (watertight) or open mesh with glTF's `doubleSided`.
    pub fn of(closed: bool, double_sided: bool) -> Self {
        match (closed, double_sided) {
            (true, _) => Sides::Closed,
            (false, false) => Sides::Front,
            (false, true) => Sides::Both,
        }
    }

    /// Whether a face lit from behind (the light arriving against its normal's side)
    /// casts caustics: both sides of an open double-sided surface, and a closed
    /// refractor's faces, which light crosses from inside.
    pub fn lit_from_behind(self, interaction: &SpecularInteraction) -> bool {
        match self {
            Sides::Closed => matches!(interaction, SpecularInteraction::Refract { .. }),
            Sides::Front => false,
            Sides::Both => true,
        }
    }
}

/// A diffuse surface on which caustics land (and which blocks light).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Receiver {
    /// The surface, in world space.
    pub mesh: TriMesh,
    /// Linear RGB albedo, used when a view is shaded.
    pub albedo: Vec3,
}

/// A light's range in JSON: a number, or `null` for an infinite one.
mod range_or_null {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(range: &f32, s: S) -> Result<S::Ok, S::Error> {
        range.is_finite().then_some(*range).serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
        Ok(Option::<f32>::deserialize(d)?.unwrap_or(f32::INFINITY))
    }
}

/// Why a scene was refused.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum SceneError {
    /// A light is invalid.
    #[error("light {index}: {source}")]
    Light {
        /// Index into [`Scene::lights`].
        index: usize,
        /// What is wrong with it.
        source: ParamError,
    },
    /// A generator's interaction is invalid.
    #[error("generator {index}: {source}")]
    Generator {
        /// Index into [`Scene::generators`].
        index: usize,
        /// What is wrong with it.
        source: ParamError,
    },
    /// The scene has no lights.
    #[error("the scene has no lights")]
    NoLights,
}

/// Lights, generators and receivers in world space. Its JSON form is what
/// [`crate::view::SceneView`] saves.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Scene {
    /// The lights, in world space.
    pub lights: Vec<Light>,
    /// The specular surfaces that cast caustics.
    pub generators: Vec<Generator>,
    /// The diffuse surfaces caustics land on.
    pub receivers: Vec<Receiver>,
}

impl Scene {
    /// Checks every light and generator; the first problem is returned.
    pub fn validate(&self) -> Result<(), SceneError> {
        if self.lights.is_empty() {
            return Err(SceneError::NoLights);
        }
        for (index, l) in self.lights.iter().enumerate() {
            l.validate().map_err(|source| SceneError::Light { index, source })?;
        }
        for (index, g) in self.generators.iter().enumerate() {
            g.interaction.validate().map_err(|source| SceneError::Generator { index, source })?;
        }
        Ok(())
    }

    /// Bounds `(min, max)` of all generator geometry, `None` without generators.
    pub fn generator_bounds(&self) -> Option<(Vec3, Vec3)> {
        self.generators.iter().map(|g| g.mesh.bounds()).reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
    }
}

/// What a surface does in caustics, judged from its PBR material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SurfaceRole {
    /// A specular surface that makes caustics.
    Generator(SpecularInteraction),
    /// A diffuse surface that shows them.
    Receiver,
}

/// The glTF 2.0 convention: a material with `KHR_materials_transmission` (transmission
/// ≥ ½) refracts with its `KHR_materials_ior` index; a smooth metal (metallic ≥ 0.99,
/// perceptual roughness ≤ 0.05) is a mirror; everything else is a receiver. An
/// impossible IOR is an error, so that the caller can report it and skip the surface.
pub fn role_from_material(transmission: f32, ior: f32, metallic: f32, perceptual_roughness: f32) -> Result<SurfaceRole, ParamError> {
    if transmission >= 0.5 {
        crate::params::check_ior(ior)?;
        Ok(SurfaceRole::Generator(SpecularInteraction::Refract { ior, dispersion: None }))
    } else if metallic >= 0.99 && perceptual_roughness <= 0.05 {
        Ok(SurfaceRole::Generator(SpecularInteraction::Reflect))
    } else {
        Ok(SurfaceRole::Receiver)
    }
}

//! Shading a camera view on the CPU: receivers lit by the lights (with shadows) and
//! by caustic irradiance from a [`PhotonMap`], seen directly or through the
//! generators (Whitted-style specular paths). This is the reference image a GPU
//! technique's frame is compared with, pixel by pixel.

use crate::bvh::Surface;
use crate::convolution::ripples::{Impulse, RippleSettings};
use crate::estimate::PhotonMap;
use crate::optics::{Refraction, fresnel_reflectance, reflect, refract};
use crate::params::MediumCoefficients;
use crate::scene::{LightKind, Scene};
use crate::tracer::PhotonTracer;
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::PI;

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PinholeCamera {
    /// Where the camera is (world space).
    pub position: Vec3,
    /// The point it looks at.
    pub look_at: Vec3,
    /// Which way is up in the image; not parallel to the view direction.
    pub up: Vec3,
    /// Vertical field of view, radians.
    pub fov_y: f32,
    /// Image width in pixels, 1 to [`MAX_VIEW_SIDE`].
    pub width: u32,
    /// Image height in pixels, 1 to [`MAX_VIEW_SIDE`].
    pub height: u32,
}

impl PinholeCamera {
    /// Origin and unit direction of the ray through pixel centre `(x, y)` (y down).
    pub fn ray(&self, x: u32, y: u32) -> (Vec3, Vec3) {
        let forward = (self.look_at - self.position).normalize_or(Vec3::NEG_Z);
        let right = forward.cross(self.up).normalize_or(Vec3::X);
        let up = right.cross(forward);
        let half_h = (0.5 * self.fov_y).tan();
        let half_w = half_h * self.width as f32 / self.height.max(1) as f32;
        let sx = (2.0 * (x as f32 + 0.5) / self.width as f32 - 1.0) * half_w;
        let sy = (1.0 - 2.0 * (y as f32 + 0.5) / self.height as f32) * half_h;
        (self.position, (forward + right * sx + up * sy).normalize())
    }
}

/// The most pixels a side of a [`SceneView`]'s camera may have.
pub const MAX_VIEW_SIDE: u32 = 16384;

impl PinholeCamera {
    /// Checks that the camera can make rays: finite placement, a direction to look in
    /// that `up` is not parallel to, a field of view strictly between 0 and π, and 1 to
    /// [`MAX_VIEW_SIDE`] pixels a side.
    pub fn validate(&self) -> Result<(), String> {
        let forward = self.look_at - self.position;
        if ![self.position, self.look_at, self.up].iter().all(|v| v.is_finite()) {
            return Err("the camera's position, target and up are not all finite".into());
        }
        if forward.length_squared() == 0.0 || forward.cross(self.up).length_squared() <= 1e-12 * forward.length_squared() * self.up.length_squared() {
            return Err("the camera looks at its own position, or along its up".into());
        }
        if !(self.fov_y > 0.0 && self.fov_y < PI) {
            return Err(format!("the camera's field of view {} is not between 0 and π", self.fov_y));
        }
        if !(1..=MAX_VIEW_SIDE).contains(&self.width) || !(1..=MAX_VIEW_SIDE).contains(&self.height) {
            return Err(format!("the camera's {}×{} pixels are not 1 to {MAX_VIEW_SIDE} a side", self.width, self.height));
        }
        Ok(())
    }
}

/// A scene and the camera that looked at it: a game's frame as the ground-truth
/// comparison traced it, saved so that another program (`caustics bench`) can measure
/// the same view again. The receivers from `shown` on block light but are not
/// measured (in a game, meshes that cast shadows but are no `CausticReceiver`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SceneView {
    /// The scene the frame showed, in world space.
    pub scene: Scene,
    /// How many of the scene's receivers, from the first, are measured.
    pub shown: usize,
    /// The camera that looked at it.
    pub camera: PinholeCamera,
    /// The generators that are a rippling pool's water: the mesh alone would lose what
    /// convolution caustics draw from.
    #[serde(default)]
    pub pools: Vec<PoolView>,
    /// The participating media (the light shafts; a generator's technique follows them).
    #[serde(default)]
    pub media: Vec<MediumView>,
}

/// A homogeneous participating medium of a [`SceneView`] (Ernst et al. 2005 §3.5): its
/// coefficients, filling the unit cube `[-½, ½]³` that `transform` places.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MediumView {
    /// World from medium space: places the unit cube the medium fills.
    pub transform: glam::Affine3A,
    /// Its scattering, absorption and phase asymmetry.
    pub coefficients: MediumCoefficients,
}

/// A generator of a [`SceneView`] that is a rippling pool's water (Trendall & Stewart
/// 2000 §4.3): the pool's settings (as the Bevy crate's `PoolRipples` has them) and
/// its live impulses, from which its water is made again as the frame saw it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PoolView {
    /// The generator (its index in the scene) that is this pool's water.
    pub generator: usize,
    /// World from pool space: the water's rest level at y = 0, centred on the origin.
    pub transform: glam::Affine3A,
    /// Texel columns of the pool (along x).
    pub columns: u32,
    /// Texel rows of the pool (along z).
    pub rows: u32,
    /// Side of one square texel (m).
    pub cell_size: f32,
    /// The wave each impulse sends out.
    pub waves: RippleSettings,
    /// `d`: depth of the floor below the water's rest level (m).
    pub depth: f32,
    /// `n`: the convolution form's cosine exponent
    /// ([`crate::convolution::ConvolutionSettings::exponent`]).
    pub exponent: f32,
    /// `ε`: extinction coefficient of the water (1/m).
    pub extinction: f32,
    /// `r`: the kernel covers the `(2r + 1)²` texels around a floor point.
    pub kernel_radius: u32,
    /// The impulses live in the frame (pool coordinates, times on the pool's clock).
    pub impulses: Vec<Impulse>,
    /// The pool's clock in the frame (s).
    pub time: f32,
}

impl SceneView {
    /// The view as JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("a scene view is plain data")
    }

    /// Reads a view written by [`Self::to_json`], checking the scene (every mesh,
    /// light and generator), the camera and `shown`.
    pub fn from_json(text: &str) -> Result<Self, String> {
        let view: Self = serde_json::from_str(text).map_err(|e| format!("scene view does not parse: {e}"))?;
        view.scene.validate().map_err(|e| e.to_string())?;
        view.camera.validate()?;
        if view.shown > view.scene.receivers.len() {
            return Err(format!("{} receivers are shown, but the scene has {}", view.shown, view.scene.receivers.len()));
        }
        for (i, pool) in view.pools.iter().enumerate() {
            if pool.generator >= view.scene.generators.len() || view.pools[..i].iter().any(|p| p.generator == pool.generator) {
                return Err(format!("pool {i} is generator {}, which the scene lacks or another pool is", pool.generator));
            }
            if !pool.transform.is_finite() || !pool.time.is_finite() {
                return Err(format!("pool {i}'s placement or clock is not finite"));
            }
        }
        for (i, medium) in view.media.iter().enumerate() {
            medium.coefficients.validate().map_err(|e| format!("medium {i}: {e}"))?;
            if !medium.transform.is_finite() {
                return Err(format!("medium {i}'s placement is not finite"));
            }
        }
        Ok(view)
    }

    /// Whether `text` is a scene view rather than another JSON scene format: it has a
    /// camera and a scene.
    pub fn is_scene_view(text: &str) -> bool {
        serde_json::from_str::<serde_json::Value>(text).is_ok_and(|v| v.get("camera").is_some() && v.get("scene").is_some())
    }
}

/// A rendered view: linear radiance and the caustic irradiance seen at each pixel.
#[derive(Clone, Debug)]
pub struct ViewImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Outgoing radiance towards the camera, linear RGB.
    pub radiance: Vec<Vec3>,
    /// Caustic irradiance on the receiver seen at each pixel (zero elsewhere).
    pub caustic: Vec<Vec3>,
}

/// Radiance of the sky seen through the generators or past the scene.
const BACKGROUND: Vec3 = Vec3::new(0.02, 0.025, 0.03);
/// Most specular bounces a camera path follows.
const MAX_VIEW_DEPTH: u32 = 6;

/// Renders `camera`'s view: Lambertian receivers under direct light (shadowed by all
/// geometry) plus the caustic irradiance of `photons` — radiance `albedo/π · E`.
pub fn render_view(tracer: &PhotonTracer, scene: &Scene, camera: &PinholeCamera, photons: &PhotonMap) -> ViewImage {
    let pixels: Vec<(Vec3, Vec3)> = (0..camera.width * camera.height)
        .into_par_iter()
        .map(|i| {
            let (o, d) = camera.ray(i % camera.width, i / camera.width);
            shade(tracer, scene, photons, o, d, 0)
        })
        .collect();
    let (radiance, caustic) = pixels.into_iter().unzip();
    ViewImage { width: camera.width, height: camera.height, radiance, caustic }
}

/// Radiance along a ray and, if it ends on a receiver seen directly, that point's caustic irradiance.
fn shade(tracer: &PhotonTracer, scene: &Scene, photons: &PhotonMap, o: Vec3, d: Vec3, depth: u32) -> (Vec3, Vec3) {
    let Some(hit) = tracer.bvh().intersect(o, d, 0.0, f32::INFINITY) else {
        return (BACKGROUND, Vec3::ZERO);
    };
    let p = o + d * hit.t;
    let ng = hit.geometric_normal;
    let eps = 1e-4 * (1.0 + p.abs().max_element());
    match hit.surface {
        Surface::Receiver(r) => {
            let n = if ng.dot(d) > 0.0 { -ng } else { ng };
            let p = p + n * eps;
            let caustic = photons.irradiance_at(p, n);
            let direct = direct_irradiance(tracer, scene, p, n);
            let albedo = scene.receivers[r as usize].albedo;
            (albedo / PI * (direct + caustic), if depth == 0 { caustic } else { Vec3::ZERO })
        }
        Surface::Generator(g) if depth < MAX_VIEW_DEPTH => {
            let generator = &scene.generators[g as usize];
            let ns = generator.mesh.shading_normal(hit.triangle as usize, hit.uv);
            let leave = |dir: Vec3| p + if dir.dot(ng) >= 0.0 { ng } else { -ng } * eps;
            let reflected = reflect(d, ns);
            match generator.interaction.ior_at(crate::optics::RGB_WAVELENGTHS_UM[1]) {
                None => (shade(tracer, scene, photons, leave(reflected), reflected, depth + 1).0, Vec3::ZERO),
                Some(ior) => {
                    let eta = if d.dot(ng) < 0.0 { 1.0 / ior } else { ior };
                    let r = fresnel_reflectance(d.dot(ns), eta);
                    let mut l = Vec3::ZERO;
                    if r > 0.01 {
                        l += r * shade(tracer, scene, photons, leave(reflected), reflected, depth + 1).0;
                    }
                    if let Refraction::Transmitted(t) = refract(d, ns, eta) {
                        l += (1.0 - r) * shade(tracer, scene, photons, leave(t), t, depth + 1).0;
                    }
                    (l, Vec3::ZERO)
                }
            }
        }
        Surface::Generator(_) => (BACKGROUND, Vec3::ZERO),
    }
}

/// Irradiance from the lights at `p` with normal `n`, zero where anything blocks the
/// light (generators included: their light arrives as caustics instead).
fn direct_irradiance(tracer: &PhotonTracer, scene: &Scene, p: Vec3, n: Vec3) -> Vec3 {
    scene
        .lights
        .iter()
        .map(|light| {
            let (to_light, distance, e) = match light.kind {
                LightKind::Directional { direction, irradiance } => (-direction.normalize(), f32::INFINITY, irradiance),
                LightKind::Point { position, intensity } | LightKind::Spot { position, intensity, .. } => {
                    let v = position - p;
                    let r = v.length();
                    let att = light.cone_attenuation(-v / r) * light.range_attenuation(r);
                    (v / r, r, intensity * att / (r * r).max(1e-8))
                }
            };
            let cos = n.dot(to_light);
            if cos <= 0.0 || e <= 0.0 || tracer.bvh().intersect(p, to_light, 0.0, distance).is_some() { Vec3::ZERO } else { light.color * e * cos }
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Light;
    use crate::scenes::glass_sphere;

    fn sphere_view() -> SceneView {
        let mut scene = glass_sphere(16).scene;
        scene.lights.push(Light { range: 7.5, ..Light::white(LightKind::Point { position: Vec3::new(1.0, 3.0, 0.0), intensity: 40.0 }) });
        let camera = PinholeCamera { position: Vec3::new(0.0, 2.0, 2.0), look_at: Vec3::ZERO, up: Vec3::Y, fov_y: 0.8, width: 64, height: 48 };
        let pool = PoolView {
            generator: 0,
            transform: glam::Affine3A::from_translation(Vec3::Y),
            columns: 8,
            rows: 8,
            cell_size: 0.1,
            waves: RippleSettings::default(),
            depth: 1.0,
            exponent: 100.0,
            extinction: 0.0,
            kernel_radius: 4,
            impulses: vec![Impulse { position: glam::Vec2::new(0.2, 0.3), strength: 0.01, time: 1.5 }],
            time: 2.0,
        };
        let medium = MediumView {
            transform: glam::Affine3A::from_scale(Vec3::new(4.0, 1.0, 4.0)),
            coefficients: MediumCoefficients { scattering: 0.25, absorption: Vec3::splat(0.05), asymmetry: 0.6 },
        };
        SceneView { scene, shown: 1, camera, pools: vec![pool], media: vec![medium] }
    }

    #[test]
    fn a_scene_view_survives_json() {
        let view = sphere_view();
        assert!(view.scene.lights[0].range.is_infinite());
        let json = view.to_json();
        assert!(SceneView::is_scene_view(&json));
        assert!(SceneView::from_json(&json).unwrap() == view, "the view read back differs from the one written");
    }

    #[test]
    fn a_scene_view_that_code_could_not_make_is_refused_with_the_reason() {
        let json = sphere_view().to_json();
        let with = |from: &str, to: &str| {
            assert!(json.contains(from), "{from}");
            SceneView::from_json(&json.replacen(from, to, 1)).unwrap_err()
        };
        assert!(with("\"shown\":1", "\"shown\":2").contains("2 receivers are shown"));
        assert!(with("\"fov_y\":0.8", "\"fov_y\":4.0").contains("field of view"));
        assert!(with("\"width\":64", "\"width\":0").contains("pixels"));
        assert!(with("\"intensity\":40.0", "\"intensity\":-40.0").contains("light 1"));
        assert!(with("\"triangles\":[[", "\"triangles\":[[9999,0,0],[").contains("vertex 9999"));
        assert!(with("\"ior\":1.5", "\"ior\":0.5").contains("generator 0"));
        assert!(with("\"generator\":0", "\"generator\":1").contains("pool 0 is generator 1"));
        assert!(with("\"scattering\":0.25", "\"scattering\":-0.25").contains("medium 0"));
        assert!(SceneView::from_json("{\"scene\": 3}").unwrap_err().contains("does not parse"));
        assert!(!SceneView::is_scene_view("{\"name\": \"pool\", \"light\": {}}"));
    }
}

//! The rippling pond of Trendall & Stewart 2000 §4.3: each pebble dropped on the
//! water starts an impulse whose wave, at time `t` after the drop and distance `d`
//! from it, is
//! `h(t, d) = exp(−β(f(t) − d)) exp(−αt) sin(Kd − ωt)`,
//! damped with time (α) and with distance behind its wavefront `f(t)` (β). Impulses
//! add up. The four walls reflect the waves: each impulse is also placed at its mirror
//! image across each wall, and — beyond the paper — across each pair of adjacent walls
//! (the four corners), so that a wave reflected off one wall is also reflected off
//! its neighbours and the height's normal derivative vanishes along the whole of both
//! walls of a corner. It vanishes at a wall until the images beyond the opposite wall
//! (a pool's length away) reach it.
//!
//! The paper leaves `f(t)` open; here the front travels at the phase speed,
//! `f(t) = ωt/K`, so the wave starts at height 0 (`sin 0`) and is 0 ahead of its front
//! (`d > f(t)`), where the β term would otherwise grow.
//!
//! Pool coordinates: `x ∈ [0, width]`, `z ∈ [0, length]` (m), matching [`Heightfield`]'s
//! texel centres. Heights are sums in `f64` in a fixed order: the same drops at the same
//! times give bit-identical heights.

use super::Heightfield;
use super::heightfield::check_grid;
use crate::params::{ParamError, check_finite};
use glam::{DVec2, Vec2};
use rayon::prelude::*;

/// The wave of one impulse.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RippleSettings {
    /// `K`: wave number (rad/m); the wavelength is `2π/K`.
    pub wave_number: f32,
    /// `ω`: angular frequency (rad/s); crests and front travel at `ω/K`.
    pub angular_frequency: f32,
    /// `α`: damping with time (1/s).
    pub time_damping: f32,
    /// `β`: damping with distance behind the wavefront (1/m).
    pub front_damping: f32,
    /// An impulse is removed once it can no longer change any height in the pool by this
    /// much (m), ([`PoolRipples::remove_expired`]).
    pub expiry_height: f32,
}

impl Default for RippleSettings {
    fn default() -> Self {
        Self { wave_number: 25.0, angular_frequency: 12.5, time_damping: 1.0, front_damping: 2.0, expiry_height: 1.0e-5 }
    }
}

impl RippleSettings {
    /// Checks every value: `K`, `ω` and the expiry height must be finite and > 0, `α`
    /// and `β` finite and ≥ 0 and not both 0 (an undamped wave never fades, so its
    /// impulse would never be removed).
    pub fn validate(&self) -> Result<(), ParamError> {
        let positive = [
            ("wave number K", self.wave_number, "a finite number > 0 (rad/m)"),
            ("angular frequency ω", self.angular_frequency, "a finite number > 0 (rad/s)"),
            ("expiry height", self.expiry_height, "a finite height > 0 (m)"),
        ];
        for (name, value, expected) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(ParamError::OutOfRange { name, value, expected });
            }
        }
        let damping = [
            ("time damping α", self.time_damping, "a finite number ≥ 0 (1/s), > 0 when β = 0"),
            ("front damping β", self.front_damping, "a finite number ≥ 0 (1/m), > 0 when α = 0"),
        ];
        for (name, value, expected) in damping {
            if !(value.is_finite() && value >= 0.0) {
                return Err(ParamError::OutOfRange { name, value, expected });
            }
        }
        if self.time_damping == 0.0 && self.front_damping == 0.0 {
            let expected = "> 0 when β = 0: undamped ripples never fade";
            return Err(ParamError::OutOfRange { name: "time damping α", value: 0.0, expected });
        }
        Ok(())
    }

    /// The distance `f(t) = ωt/K` of the wavefront from its impulse (m).
    pub fn front_distance(&self, elapsed: f64) -> f64 {
        self.angular_frequency as f64 * elapsed / self.wave_number as f64
    }

    /// `h(t, d)` of a unit impulse `elapsed` seconds after its drop, `distance` from it
    /// (m); 0 before the drop and ahead of the front.
    pub fn impulse_height(&self, elapsed: f64, distance: f64) -> f64 {
        let front = self.front_distance(elapsed);
        if elapsed <= 0.0 || distance > front {
            return 0.0;
        }
        let (k, omega) = (self.wave_number as f64, self.angular_frequency as f64);
        let envelope = -(self.front_damping as f64) * (front - distance) - self.time_damping as f64 * elapsed;
        envelope.exp() * (k * distance - omega * elapsed).sin()
    }
}

/// A pebble's impulse.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Impulse {
    /// Where it fell, in pool coordinates (m).
    pub position: Vec2,
    /// Its height scale (m); negative inverts the wave.
    pub strength: f32,
    /// When it fell (s).
    pub time: f32,
}

/// An impulse at `position` and its eight mirror images across the walls of a pool
/// `size` wide: `x ∈ {x, −x, 2·width − x}` times `z ∈ {z, −z, 2·length − z}`, the
/// impulse itself first.
pub fn mirror_images(position: Vec2, size: Vec2) -> [DVec2; 9] {
    let (p, s) = (position.as_dvec2(), size.as_dvec2());
    let xs = [p.x, -p.x, 2.0 * s.x - p.x];
    let zs = [p.y, -p.y, 2.0 * s.y - p.y];
    std::array::from_fn(|i| DVec2::new(xs[i % 3], zs[i / 3]))
}

/// The surface of a rectangular pool of `columns × rows` texels, rippled by pebbles.
#[derive(Clone, Debug, PartialEq)]
pub struct PoolRipples {
    columns: usize,
    rows: usize,
    cell_size: f32,
    settings: RippleSettings,
    impulses: Vec<Impulse>,
}

impl PoolRipples {
    /// A still pool. Errors: invalid settings or grid (as [`Heightfield::new`]).
    pub fn new(columns: usize, rows: usize, cell_size: f32, settings: RippleSettings) -> Result<Self, ParamError> {
        check_grid(columns, rows, cell_size)?;
        settings.validate()?;
        Ok(Self { columns, rows, cell_size, settings, impulses: Vec::new() })
    }

    /// The pool's `(width, length)` along x and z (m).
    pub fn size(&self) -> Vec2 {
        Vec2::new(self.columns as f32, self.rows as f32) * self.cell_size
    }

    /// The wave settings.
    pub fn settings(&self) -> &RippleSettings {
        &self.settings
    }

    /// The live impulses, in the order they were dropped.
    pub fn impulses(&self) -> &[Impulse] {
        &self.impulses
    }

    /// Drops a pebble at `position` (pool coordinates) at `time`. Errors: a position
    /// outside the pool, a strength or time that is not finite.
    pub fn drop_pebble(&mut self, position: Vec2, strength: f32, time: f32) -> Result<(), ParamError> {
        let size = self.size();
        let expected = "inside the pool (0 to its size, m)";
        for (name, value, limit) in [("pebble x", position.x, size.x), ("pebble z", position.y, size.y)] {
            if !(value.is_finite() && (0.0..=limit).contains(&value)) {
                return Err(ParamError::OutOfRange { name, value, expected });
            }
        }
        check_finite("pebble strength", strength)?;
        check_finite("pebble time", time)?;
        self.impulses.push(Impulse { position, strength, time });
        Ok(())
    }

    /// The most one impulse can add to any height in the pool at `time`: nine images
    /// of `|s| exp(−αt)`, each at most `exp(−β(f(t) − D))` behind its front once the
    /// front is past `D`, twice the pool's diagonal (no image is farther from a point
    /// of the pool).
    pub fn impulse_bound(&self, impulse: &Impulse, time: f32) -> f64 {
        let elapsed = (time as f64 - impulse.time as f64).max(0.0);
        let farthest = 2.0 * self.size().as_dvec2().length();
        let behind = (self.settings.front_distance(elapsed) - farthest).max(0.0);
        let envelope = -(self.settings.time_damping as f64) * elapsed - self.settings.front_damping as f64 * behind;
        9.0 * (impulse.strength as f64).abs() * envelope.exp()
    }

    /// Removes the impulses whose [`Self::impulse_bound`] at `time` is below the expiry
    /// height (never one dropped after `time`), keeping the others in order; returns how
    /// many were removed. No height in the pool changes by more than the expiry height
    /// per removed impulse, then or later.
    pub fn remove_expired(&mut self, time: f32) -> usize {
        let before = self.impulses.len();
        let expiry = self.settings.expiry_height as f64;
        let impulses = std::mem::take(&mut self.impulses);
        self.impulses = impulses.into_iter().filter(|i| i.time > time || self.impulse_bound(i, time) >= expiry).collect();
        before - self.impulses.len()
    }

    /// The surface height at `point` (pool coordinates) at `time` (m).
    pub fn height_at(&self, point: Vec2, time: f32) -> f32 {
        let point = point.as_dvec2();
        let mut height = 0.0;
        for impulse in &self.impulses {
            let elapsed = time as f64 - impulse.time as f64;
            let strength = impulse.strength as f64;
            for image in mirror_images(impulse.position, self.size()) {
                height += strength * self.settings.impulse_height(elapsed, point.distance(image));
            }
        }
        height as f32
    }

    /// The surface at `time` sampled at the texel centres. Errors: a height that is not
    /// finite (strengths so large that their sum overflows).
    pub fn heightfield(&self, time: f32) -> Result<Heightfield, ParamError> {
        let centre = |i: usize| (i as f32 + 0.5) * self.cell_size;
        let heights = (0..self.columns * self.rows)
            .into_par_iter()
            .map(|texel| self.height_at(Vec2::new(centre(texel % self.columns), centre(texel / self.columns)), time))
            .collect();
        Heightfield::new(self.columns, self.rows, self.cell_size, heights)
    }
}

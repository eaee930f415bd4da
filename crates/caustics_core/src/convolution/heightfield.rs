//! The water surface as a regular grid of heights, with normals by finite differences
//! (Trendall & Stewart 2000 §4.1).

use super::Boundary;
use crate::params::ParamError;
use glam::{DVec2, Vec3};

/// The most texels along either side of a [`Heightfield`].
pub const MAX_HEIGHTFIELD_SIDE: usize = 8192;

/// A water surface `y = h(x, z)` sampled at texel centres: `heights()[row * columns + column]`
/// is the height (m) above the rest level `y = 0` at `x = (column + ½)·cell_size`,
/// `z = (row + ½)·cell_size`. Every height is finite.
#[derive(Clone, Debug, PartialEq)]
pub struct Heightfield {
    columns: usize,
    rows: usize,
    cell_size: f32,
    heights: Vec<f32>,
}

impl Heightfield {
    /// A heightfield from row-major `heights`. Errors: a side of zero or beyond
    /// [`MAX_HEIGHTFIELD_SIDE`], a cell size that is not a finite length > 0, a number of
    /// heights other than `columns × rows`, a height that is not finite.
    pub fn new(columns: usize, rows: usize, cell_size: f32, heights: Vec<f32>) -> Result<Self, ParamError> {
        check_grid(columns, rows, cell_size)?;
        if heights.len() != columns * rows {
            let expected = "columns × rows heights";
            return Err(ParamError::OutOfRange { name: "number of heights", value: heights.len() as f32, expected });
        }
        if let Some(&bad) = heights.iter().find(|h| !h.is_finite()) {
            return Err(ParamError::NotFinite { name: "height", value: bad });
        }
        Ok(Self { columns, rows, cell_size, heights })
    }

    /// A still surface at the rest level.
    pub fn flat(columns: usize, rows: usize, cell_size: f32) -> Result<Self, ParamError> {
        check_grid(columns, rows, cell_size)?;
        Ok(Self { columns, rows, cell_size, heights: vec![0.0; columns * rows] })
    }

    /// A heightfield sampling `height(x, z)` at the texel centres.
    pub fn from_fn(columns: usize, rows: usize, cell_size: f32, height: impl Fn(f32, f32) -> f32) -> Result<Self, ParamError> {
        check_grid(columns, rows, cell_size)?;
        let centre = |i: usize| (i as f32 + 0.5) * cell_size;
        let heights = (0..rows).flat_map(|row| (0..columns).map(move |column| (column, row)));
        let heights = heights.map(|(column, row)| height(centre(column), centre(row))).collect();
        Self::new(columns, rows, cell_size, heights)
    }

    /// Texels along x.
    pub fn columns(&self) -> usize {
        self.columns
    }

    /// Texels along z.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Side of a square texel (m).
    pub fn cell_size(&self) -> f32 {
        self.cell_size
    }

    /// The heights, row-major.
    pub fn heights(&self) -> &[f32] {
        &self.heights
    }

    /// The height at a texel.
    pub fn height(&self, column: usize, row: usize) -> f32 {
        self.heights[row * self.columns + column]
    }

    /// The slope `(∂h/∂x, ∂h/∂z)` at a texel by central differences, the neighbours past
    /// an edge taken from the surface `boundary` extends it to. §4.1 takes the plane
    /// through `h(i, j)`, `h(i+1, j)` and `h(i, j+1)`, whose normal belongs half a texel
    /// away; the central difference is centred on the texel and keeps a mirrored surface
    /// mirrored. In `f64`: the difference of two finite heights over any cell size is finite.
    pub fn slope(&self, column: usize, row: usize, boundary: Boundary) -> DVec2 {
        let at = |c: isize, r: isize| {
            let (c, _) = boundary.fold(c, self.columns);
            let (r, _) = boundary.fold(r, self.rows);
            self.height(c, r) as f64
        };
        let (c, r) = (column as isize, row as isize);
        let span = 2.0 * self.cell_size as f64;
        DVec2::new((at(c + 1, r) - at(c - 1, r)) / span, (at(c, r + 1) - at(c, r - 1)) / span)
    }

    /// The upward unit normal `(−∂h/∂x, 1, −∂h/∂z) / ‖·‖` at a texel (§4.1, from
    /// [`Self::slope`]); normalised in `f64`, so finite for any finite heights.
    pub fn normal(&self, column: usize, row: usize, boundary: Boundary) -> Vec3 {
        let slope = self.slope(column, row, boundary);
        let scale = slope.abs().max_element().max(1.0);
        let n = glam::DVec3::new(-slope.x / scale, 1.0 / scale, -slope.y / scale).normalize();
        n.as_vec3()
    }
}

/// Checks the sides and the cell size of a grid.
pub(super) fn check_grid(columns: usize, rows: usize, cell_size: f32) -> Result<(), ParamError> {
    let expected = "a whole number of texels from 1 to 8192";
    for (name, side) in [("heightfield columns", columns), ("heightfield rows", rows)] {
        if side == 0 || side > MAX_HEIGHTFIELD_SIDE {
            return Err(ParamError::OutOfRange { name, value: side as f32, expected });
        }
    }
    if cell_size.is_finite() && cell_size > 0.0 {
        Ok(())
    } else {
        Err(ParamError::OutOfRange { name: "cell size", value: cell_size, expected: "a finite length > 0 (m)" })
    }
}

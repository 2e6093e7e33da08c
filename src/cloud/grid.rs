//! [`NearGrid`]: "is some point within `r` of `q`?" answered on a uniform grid of buckets.
//!
//! FAKIR's model → data terms (the occupancy term of `fakir::lm`, the occupancy score and the
//! seeding's surface cost of `fakir::solver`) ask, for every sample on a bone's surface, how
//! far the nearest data point is, and then clamp that distance: a sample nearer than a slack
//! costs nothing. Most samples of a bone lying on the data are that near, and for them the
//! nearest point itself is never needed. The grid answers that question (the points of the 27
//! cells around `q` are tested, `r` at most one cell) more cheaply than a nearest-point query
//! of the k-d tree; the callers query the tree only when the grid says no. Since the grid
//! answers "within" only for a radius a little under the slack ([`NearGrid::within_below`]),
//! a "yes" means that the tree's nearest point is within the slack too, whatever the rounding
//! of either distance: the callers' sums are the same bits as with the tree alone.
//!
//! (`cloud::normals` has a voxel grid of its own for its visibility rays: occupancy bits and
//! mean normals per voxel, a different question.)
//!
//! Inputs: points, a cell size. Output: `any_within(q, r)`. Built in O(n) (a counting sort of
//! the points into cells); `None` when there are no points, the cell is not a positive finite
//! size, or the points' box would take more than [`MAX_CELLS_PER_POINT`] cells per point (a
//! few far outliers): the callers then use the tree alone.

use crate::math::Vec3;

/// Upper bound on cells per point (see the module docs).
pub const MAX_CELLS_PER_POINT: usize = 64;

/// The radius [`NearGrid::within_below`] tests instead of the slack: `slack × (1 − 1e-5)`, far
/// above the relative rounding of a squared distance in `f32` (about `1e-7`), so that a point
/// found within it is within the slack however either side rounds.
pub const BELOW: f32 = 1.0 - 1e-5;

/// A uniform grid over points (see the module docs).
#[derive(Clone, Debug)]
pub struct NearGrid {
    origin: Vec3,
    cell: f32,
    inv_cell: f32,
    dims: [usize; 3],
    /// `starts[c]..starts[c + 1]`: the points of cell `c` in `points`.
    starts: Vec<u32>,
    points: Vec<Vec3>,
}

impl NearGrid {
    /// A grid of cubic cells of edge `cell` over `points` (see the module docs for `None`).
    pub fn new(points: &[Vec3], cell: f32) -> Option<NearGrid> {
        if points.is_empty() || !(cell.is_finite() && cell > 0.0) {
            return None;
        }
        if points.iter().any(|p| !p.is_finite()) {
            return None;
        }
        let bounds = super::Aabb::of(points)?;
        let inv_cell = 1.0 / cell;
        let size = bounds.size() * inv_cell;
        let dim = |x: f32| x.floor() as usize + 1;
        let dims = [dim(size.x), dim(size.y), dim(size.z)];
        let cells = dims[0]
            .checked_mul(dims[1])
            .and_then(|c| c.checked_mul(dims[2]))?;
        if cells > MAX_CELLS_PER_POINT.saturating_mul(points.len()) {
            return None;
        }
        let mut grid = NearGrid {
            origin: bounds.min,
            cell,
            inv_cell,
            dims,
            starts: vec![0; cells + 1],
            points: vec![Vec3::ZERO; points.len()],
        };
        let index: Vec<usize> = points.iter().map(|&p| grid.cell_of(p)).collect();
        for &c in &index {
            grid.starts[c + 1] += 1;
        }
        for c in 0..cells {
            grid.starts[c + 1] += grid.starts[c];
        }
        let mut next: Vec<u32> = grid.starts[..cells].to_vec();
        for (&c, &p) in index.iter().zip(points) {
            grid.points[next[c] as usize] = p;
            next[c] += 1;
        }
        Some(grid)
    }

    /// Integer coordinates of the cell holding `p`, clamped into the grid.
    fn coords(&self, p: Vec3) -> [usize; 3] {
        let u = (p - self.origin) * self.inv_cell;
        let c = |x: f32, n: usize| (x.floor().max(0.0) as usize).min(n - 1);
        [
            c(u.x, self.dims[0]),
            c(u.y, self.dims[1]),
            c(u.z, self.dims[2]),
        ]
    }

    fn cell_of(&self, p: Vec3) -> usize {
        let [x, y, z] = self.coords(p);
        (z * self.dims[1] + y) * self.dims[0] + x
    }

    /// Whether some point lies within `r` of `q` (`|p − q|² ≤ r²`), for `r` up to one cell (a
    /// larger `r` answers `false`). A "yes" is never wrong: it is that distance test itself.
    /// A "no" can miss a point at a cell border that rounding put two cells from `q`'s; the
    /// callers then ask the tree, so a miss costs time, not bits. A query outside the points'
    /// box is clamped to its border cells (a point within one cell of `q` lies in the cells
    /// next to `q`'s clamped cell).
    pub fn any_within(&self, q: Vec3, r: f32) -> bool {
        if !(r <= self.cell) || !q.is_finite() {
            return false;
        }
        let r2 = r * r;
        // Outside the box by more than `r` on some axis: no point can be that near.
        let u = (q - self.origin) * self.inv_cell;
        let margin = r * self.inv_cell;
        let top = Vec3::new(
            self.dims[0] as f32,
            self.dims[1] as f32,
            self.dims[2] as f32,
        ) + margin;
        if u.cmplt(Vec3::splat(-margin)).any() || u.cmpgt(top).any() {
            return false;
        }
        let [cx, cy, cz] = self.coords(q);
        let range = |c: usize, n: usize| c.saturating_sub(1)..=(c + 1).min(n - 1);
        for z in range(cz, self.dims[2]) {
            for y in range(cy, self.dims[1]) {
                let row = (z * self.dims[1] + y) * self.dims[0];
                let xs = range(cx, self.dims[0]);
                let (a, b) = (
                    self.starts[row + xs.start()] as usize,
                    self.starts[row + xs.end() + 1] as usize,
                );
                // The cells of one row of x are contiguous in `points`.
                if self.points[a..b]
                    .iter()
                    .any(|p| (*p - q).length_squared() <= r2)
                {
                    return true;
                }
            }
        }
        false
    }

    /// [`NearGrid::any_within`] at [`BELOW`] times `slack`: a "yes" means that the nearest
    /// point is within `slack` however its distance is rounded (see the module docs).
    pub fn within_below(&self, q: Vec3, slack: f32) -> bool {
        self.any_within(q, BELOW * slack)
    }
}

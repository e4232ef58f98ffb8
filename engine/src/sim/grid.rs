//! A uniform grid for fixed-radius neighbour queries, rebuilt every step by counting sort
//! (notes §8; not in the book).
//!
//! - Cell key = floor(p / cell), with floor rather than truncation so negative coordinates get
//!   their own cells instead of sharing cell 0 with the positives.
//! - Cells are dense over the points' bounding box, numbered x fastest, so the three cells of a
//!   row of the 3×3×3 neighbourhood are one contiguous run of the sorted array: a query reads nine
//!   runs, not 27 cells.
//! - Build: cell of every point (parallel), count per cell, prefix sum, scatter in index order, so
//!   within a cell points keep ascending index and the build is deterministic. The positions are
//!   copied in cell order, so the distance filter of a query streams through memory.
//! - The cell is the build radius times (1 + 2⁻¹²): two points within the radius then never
//!   land two cells apart through the rounding of p / cell (that needs an error of about
//!   2⁻²³ per cell of distance from the origin, so this holds out to ~500 cells), and a point
//!   exactly on a border is found from both sides. If the box would need far more cells than
//!   points (one boid far away), the cell doubles: queries stay correct, only slower.

use glam::Vec3;
use rayon::prelude::*;

#[derive(Debug, Clone, Default)]
pub struct Grid {
    cell: f32,
    inv_cell: f32,
    radius: f32,
    min_cell: [i32; 3],
    dims: [usize; 3],
    /// Points of cell c are `order[cell_start[c]..cell_start[c + 1]]`.
    cell_start: Vec<u32>,
    order: Vec<u32>,
    /// Inverse of `order`: where point i sits in it.
    rank: Vec<u32>,
    /// Positions in `order`'s order, with the point's index in the fourth float's bits: a query
    /// reads one 16-byte record per candidate from one array.
    points: Vec<[f32; 4]>,
    /// Scratch: linear cell of each point.
    cell_of: Vec<u32>,
    /// Cell coordinates of each point (relative to `min_cell`), so a query about a point of the
    /// build needs no divisions; `sorted_xyz` has them in `order`'s order.
    cell_xyz: Vec<[u32; 3]>,
    sorted_xyz: Vec<[u32; 3]>,
}

/// Cells in the grid at most this many times the points (plus a floor for small sets).
const CELLS_PER_POINT: usize = 8;
const MIN_CELLS: usize = 4096;

/// floor(v / cell), as floor(v · (1 / cell)): a multiply where a divide would take several
/// times as long, and still monotonic in v, which is all the build and the queries need of it
/// (the cell's 2⁻¹² margin covers the rounding). Truncation, one down for negatives with a
/// fraction: `f32::floor` is a libm call without SSE4.1, and this runs for every point and query.
fn cell_coord(v: f32, inv_cell: f32) -> i32 {
    let t = v * inv_cell;
    let i = t as i32;
    i - ((i as f32) > t) as i32
}

impl Grid {
    pub fn new() -> Grid {
        Grid::default()
    }

    /// The cell edge actually used (at least the build radius).
    pub fn cell_size(&self) -> f32 {
        self.cell
    }

    /// Point indices in cell order (ascending within a cell).
    pub fn order(&self) -> &[u32] {
        &self.order
    }

    /// Position of each point in `order`.
    pub fn rank(&self) -> &[u32] {
        &self.rank
    }

    pub fn cell_count(&self) -> usize {
        self.dims.iter().product()
    }

    /// Sorts the points into cells for queries of radius up to `radius`.
    pub fn build(&mut self, px: &[f32], py: &[f32], pz: &[f32], radius: f32) {
        let n = px.len();
        assert!(py.len() == n && pz.len() == n, "coordinate arrays differ in length");
        assert!(radius > 0.0 && radius.is_finite(), "grid radius must be positive: {radius}");
        self.radius = radius;
        let (lo, hi) = bounds(px, py, pz);
        let mut cell = radius * (1.0 + 1.0 / 4096.0);
        let limit = CELLS_PER_POINT * n + MIN_CELLS;
        loop {
            let inv = 1.0 / cell;
            let lo_c = [cell_coord(lo.x, inv), cell_coord(lo.y, inv), cell_coord(lo.z, inv)];
            let hi_c = [cell_coord(hi.x, inv), cell_coord(hi.y, inv), cell_coord(hi.z, inv)];
            let dims: [usize; 3] = std::array::from_fn(|a| (hi_c[a] as i64 - lo_c[a] as i64 + 1).max(1) as usize);
            if dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d)).is_some_and(|c| c <= limit) {
                (self.cell, self.inv_cell, self.min_cell, self.dims) = (cell, inv, lo_c, dims);
                break;
            }
            cell *= 2.0;
        }
        let cells = self.cell_count();

        self.cell_of.resize(n, 0);
        self.cell_xyz.resize(n, [0; 3]);
        let (inv, mc, d) = (self.inv_cell, self.min_cell, self.dims);
        self.cell_of.par_iter_mut().zip(self.cell_xyz.par_iter_mut()).enumerate().with_min_len(4096).for_each(|(i, (c, xyz))| {
            let x = (cell_coord(px[i], inv) - mc[0]) as usize;
            let y = (cell_coord(py[i], inv) - mc[1]) as usize;
            let z = (cell_coord(pz[i], inv) - mc[2]) as usize;
            *c = (x + d[0] * (y + d[1] * z)) as u32;
            *xyz = [x as u32, y as u32, z as u32];
        });

        // Counting sort: counts shifted by one, prefix sum to starts, scatter with cursors that
        // end one cell later (cell_start[c + 1] is used as cell c's cursor, then restored).
        self.cell_start.clear();
        self.cell_start.resize(cells + 1, 0);
        for &c in &self.cell_of {
            self.cell_start[c as usize + 1] += 1;
        }
        // A running sum in a register: `cell_start[c + 1] += cell_start[c]` would wait on the
        // store of the previous iteration.
        let mut acc = 0u32;
        for s in self.cell_start.iter_mut() {
            acc += *s;
            *s = acc;
        }
        self.order.resize(n, 0);
        // Scatter backwards from each cell's end, visiting points in descending index, so each
        // cell ends up ascending.
        let mut cursor = std::mem::take(&mut self.cell_start);
        for i in (0..n).rev() {
            let c = self.cell_of[i] as usize + 1;
            cursor[c] -= 1;
            self.order[cursor[c] as usize] = i as u32;
        }
        // Every cursor moved back by its cell's count: cursor[c + 1] is now cell c's start.
        cursor.rotate_left(1);
        cursor[cells] = n as u32;
        self.cell_start = cursor;

        self.rank.resize(n, 0);
        for (k, &i) in self.order.iter().enumerate() {
            self.rank[i as usize] = k as u32;
        }
        self.points.resize(n, [0.0; 4]);
        self.sorted_xyz.resize(n, [0; 3]);
        let (order, xyz) = (&self.order, &self.cell_xyz);
        self.points.par_iter_mut().zip(self.sorted_xyz.par_iter_mut()).zip(order.par_iter()).with_min_len(4096).for_each(|((pt, c), &i)| {
            let i = i as usize;
            *pt = [px[i], py[i], pz[i], f32::from_bits(i as u32)];
            *c = xyz[i];
        });
    }

    /// Appends to `out` every point j != `exclude` with |p_j − p|² < radius², in cell order.
    /// Returns how many points the query examined (the cost, for the bench).
    pub fn neighbours(&self, p: Vec3, radius: f32, exclude: Option<u32>, out: &mut Vec<u32>) -> usize {
        debug_assert!(radius <= self.radius, "query radius {radius} above the build radius {}", self.radius);
        let r2 = radius * radius;
        let c = [
            cell_coord(p.x, self.inv_cell) - self.min_cell[0],
            cell_coord(p.y, self.inv_cell) - self.min_cell[1],
            cell_coord(p.z, self.inv_cell) - self.min_cell[2],
        ];
        let d = self.dims;
        let Some([(x0, x1), (y0, y1), (z0, z1)]) = self.spans(c) else {
            return 0;
        };
        let mut examined = 0;
        for z in z0..=z1 {
            for y in y0..=y1 {
                let row = d[0] * (y + d[1] * z);
                let (s, e) = (self.cell_start[row + x0] as usize, self.cell_start[row + x1 + 1] as usize);
                examined += e - s;
                for &[x, y, z, j] in &self.points[s..e] {
                    let (dx, dy, dz, j) = (x - p.x, y - p.y, z - p.z, j.to_bits());
                    if dx * dx + dy * dy + dz * dz < r2 && Some(j) != exclude {
                        out.push(j);
                    }
                }
            }
        }
        examined
    }

    /// As `neighbours`, but appends each found point as the sort key
    /// `(|p_j − p|² as bits) << 32 | j` (the squared distance is non-negative, so its bits order as
    /// the number), computed with the same arithmetic as `neighbours` uses for its test. The
    /// inner loop appends without a branch: every candidate is written, and the count only
    /// advances past the ones that pass. `out` is a scratch buffer that only grows (its length is
    /// its usable size, so no clearing per query): the keys are `out[..found]`.
    /// Returns (found, examined).
    pub fn neighbour_keys(&self, p: Vec3, radius: f32, exclude: u32, out: &mut Vec<u64>) -> (usize, usize) {
        let c = [
            cell_coord(p.x, self.inv_cell) - self.min_cell[0],
            cell_coord(p.y, self.inv_cell) - self.min_cell[1],
            cell_coord(p.z, self.inv_cell) - self.min_cell[2],
        ];
        self.keys_around(c, p, radius, exclude, out)
    }

    /// `neighbour_keys` about the point at position `k` of `order` (excluding itself), using
    /// the cell the build found for it: walking k upward reads the query points sequentially.
    pub fn sorted_point_neighbour_keys(&self, k: usize, radius: f32, out: &mut Vec<u64>) -> (usize, usize) {
        let c = self.sorted_xyz[k].map(|v| v as i32);
        let [x, y, z, i] = self.points[k];
        self.keys_around(c, Vec3::new(x, y, z), radius, i.to_bits(), out)
    }

    /// Per axis, the clamped 3-cell range around cell `c`; None if it misses the grid.
    fn spans(&self, c: [i32; 3]) -> Option<[(usize, usize); 3]> {
        let d = self.dims;
        let span = |a: usize| -> Option<(usize, usize)> {
            let lo = (c[a] - 1).max(0);
            let hi = (c[a] + 1).min(d[a] as i32 - 1);
            (lo <= hi).then_some((lo as usize, hi as usize))
        };
        Some([span(0)?, span(1)?, span(2)?])
    }

    fn keys_around(&self, c: [i32; 3], p: Vec3, radius: f32, exclude: u32, out: &mut Vec<u64>) -> (usize, usize) {
        debug_assert!(radius <= self.radius, "query radius {radius} above the build radius {}", self.radius);
        let r2 = radius * radius;
        let d = self.dims;
        let Some([(x0, x1), (y0, y1), (z0, z1)]) = self.spans(c) else {
            return (0, 0);
        };
        // The (up to nine) runs first, so the buffer is sized once and the loop below keeps its
        // count in a register.
        let mut runs = [(0usize, 0usize); 9];
        let (mut nruns, mut examined) = (0, 0);
        for z in z0..=z1 {
            for y in y0..=y1 {
                let row = d[0] * (y + d[1] * z);
                let (s, e) = (self.cell_start[row + x0] as usize, self.cell_start[row + x1 + 1] as usize);
                runs[nruns] = (s, e);
                nruns += (e > s) as usize;
                examined += e - s;
            }
        }
        if out.len() < examined {
            out.resize(examined + 64, 0);
        }
        let buf = &mut out[..examined];
        let mut len = 0;
        for &(s, e) in &runs[..nruns] {
            for &[x, y, z, j] in &self.points[s..e] {
                let (dx, dy, dz, j) = (x - p.x, y - p.y, z - p.z, j.to_bits());
                let d2 = dx * dx + dy * dy + dz * dz;
                buf[len] = (d2.to_bits() as u64) << 32 | j as u64;
                len += (d2 < r2 && j != exclude) as usize;
            }
        }
        (len, examined)
    }
}

/// The O(N) scan with the same test as `Grid::neighbours`, in index order.
pub fn brute_force_neighbours(px: &[f32], py: &[f32], pz: &[f32], p: Vec3, radius: f32, exclude: Option<u32>, out: &mut Vec<u32>) {
    let r2 = radius * radius;
    for j in 0..px.len() {
        let (dx, dy, dz) = (px[j] - p.x, py[j] - p.y, pz[j] - p.z);
        if dx * dx + dy * dy + dz * dz < r2 && Some(j as u32) != exclude {
            out.push(j as u32);
        }
    }
}

fn bounds(px: &[f32], py: &[f32], pz: &[f32]) -> (Vec3, Vec3) {
    if px.is_empty() {
        return (Vec3::ZERO, Vec3::ZERO);
    }
    (0..px.len())
        .into_par_iter()
        .with_min_len(8192)
        .fold(
            || (Vec3::INFINITY, Vec3::NEG_INFINITY),
            |(lo, hi), i| {
                let p = Vec3::new(px[i], py[i], pz[i]);
                (lo.min(p), hi.max(p))
            },
        )
        .reduce(|| (Vec3::INFINITY, Vec3::NEG_INFINITY), |a, b| (a.0.min(b.0), a.1.max(b.1)))
}

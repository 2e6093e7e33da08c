//! The point-to-bone assignment `P_k` (thesis §2.2.2, paper 001 §3.2).
//!
//! Each point goes to the bone with the smallest normal-constrained distance `d_k = |p − p̃_k|`,
//! **preferring a cone part over a cap** when the distances are similar (paper 001: "if `p`
//! projects on the spherical part of the closest bone and if it also projects on the conical
//! part of another bone with a similar distance, we assign it to this second bone").
//!
//! **Choice:** "similar" means `d_cone ≤ (1 + cone_slack) · d_best + cone_abs`, with
//! `cone_slack = 0.2` and `cone_abs = 0.002 ×` the statue's height by default.
//!
//! The assignment keeps the distance of every point to every bone (one contiguous row of
//! `f32` per point) and whether each projection falls on a cone part, so after a parameter
//! change only the distances to the bones that moved are recomputed, then the argmin is
//! redone ([`Assignment::refresh`]). **Culling** (exact): a moved bone is only projected on
//! when a lower bound of its distance — the distance from the point to the bone's bounding
//! sphere — could beat the point's best distance among the bones that did not move (with the
//! cone-preference slack); otherwise that lower bound is stored, which cannot change the
//! argmin. **Shortcut** (exact, [`Assignment::update`]): a point whose nearest bone did not
//! move and whose preference window no moved bone enters or leaves keeps its label without
//! its row being scanned, so a refresh costs the moved bones' entries, not every bone's, for
//! most points. Work is split by point ranges so the registration can bound each
//! work unit; every loop over points is a rayon loop over fixed-size chunks and writes only its
//! own slots, so results do not depend on the thread count.

use crate::geometry::{Part, PreparedBone};
use crate::math::Vec3;
use rayon::prelude::*;

/// Points per parallel chunk.
pub const CHUNK: usize = 2048;

/// Assignment parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AssignParams {
    /// Relative slack of the cone preference.
    pub cone_slack: f32,
    /// Absolute slack of the cone preference (length units).
    pub cone_abs: f32,
}

/// Points come as parallel arrays of positions, normals and cloud indices.
fn check_lengths(positions: &[Vec3], normals: &[Vec3], source: &[u32]) {
    let k = positions.len();
    assert!(
        normals.len() == k && source.len() == k,
        "unequal point arrays: {k} positions, {} normals, {} indices",
        normals.len(),
        source.len()
    );
}

/// The assignment of a set of points (see the module docs).
#[derive(Clone, Debug)]
pub struct Assignment {
    /// Positions of the assigned points.
    pub positions: Vec<Vec3>,
    /// Their normals (zero vectors when unknown).
    pub normals: Vec<Vec3>,
    /// Indices of these points in the full cloud.
    pub source: Vec<u32>,
    n_bones: usize,
    /// `dist[i * n_bones + b]`: constrained distance of point `i` to bone `b` (or a lower
    /// bound of it when the bone cannot be the point's nearest).
    dist: Vec<f32>,
    /// `cone[i * n_bones + b]`: whether that projection lies on the cone part.
    cone: Vec<bool>,
    /// `bound[i * n_bones + b]`: the stored distance is only a lower bound.
    bound: Vec<bool>,
    /// Bone of each point.
    pub label: Vec<u32>,
    /// Bones that may receive points (others are ignored by the argmin).
    pub enabled: Vec<bool>,
    pub params: AssignParams,
    /// Each point's nearest bone (the argmin before the cone preference) as of its last
    /// [`Assignment::update`]; `u32::MAX` when its next update must take the whole row.
    nearest: Vec<u32>,
    /// `enabled` and `params` as `nearest` knows them.
    state_enabled: Vec<bool>,
    state_params: AssignParams,
}

impl Assignment {
    /// An assignment of the given points to `n_bones` bones; distances start at infinity and
    /// labels at 0 until the first [`Assignment::refresh`].
    pub fn new(
        positions: Vec<Vec3>,
        normals: Vec<Vec3>,
        source: Vec<u32>,
        n_bones: usize,
        params: AssignParams,
    ) -> Self {
        check_lengths(&positions, &normals, &source);
        let mut a = Assignment::with_capacity(0, n_bones, params);
        (a.positions, a.normals, a.source) = (positions, normals, source);
        a.grow_rows();
        a
    }

    /// An assignment without points yet, with room for `capacity` of them: [`Assignment::push`]
    /// adds them in bounded steps (a 100k-point assignment holds millions of distances).
    pub fn with_capacity(capacity: usize, n_bones: usize, params: AssignParams) -> Self {
        Assignment {
            positions: Vec::with_capacity(capacity),
            normals: Vec::with_capacity(capacity),
            source: Vec::with_capacity(capacity),
            n_bones,
            dist: Vec::with_capacity(capacity * n_bones),
            cone: Vec::with_capacity(capacity * n_bones),
            bound: Vec::with_capacity(capacity * n_bones),
            label: Vec::with_capacity(capacity),
            enabled: vec![true; n_bones],
            params,
            nearest: Vec::with_capacity(capacity),
            state_enabled: vec![true; n_bones],
            state_params: params,
        }
    }

    /// Appends points (positions, normals and indices in the full cloud, of equal lengths),
    /// their distances at infinity and labels 0 until the next refresh.
    pub fn push(&mut self, positions: &[Vec3], normals: &[Vec3], source: &[u32]) {
        check_lengths(positions, normals, source);
        self.positions.extend_from_slice(positions);
        self.normals.extend_from_slice(normals);
        self.source.extend_from_slice(source);
        self.grow_rows();
    }

    /// Gives the points added since the last call their rows: distances at infinity, labels 0.
    fn grow_rows(&mut self) {
        let rows = self.len() * self.n_bones;
        self.dist.resize(rows, f32::INFINITY);
        self.cone.resize(rows, false);
        self.bound.resize(rows, false);
        self.label.resize(self.len(), 0);
        self.nearest.resize(self.len(), u32::MAX);
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when there is no point.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Number of bones.
    pub fn n_bones(&self) -> usize {
        self.n_bones
    }

    /// Recomputes the distances to `bones_to_update` for the points in `range` (with the
    /// culling described in the module docs) and relabels those points.
    ///
    /// **Shortcut** (exact; same distances and labels as recomputing every row): a point whose
    /// nearest bone (the argmin before the cone preference, remembered from its last update)
    /// did not move, and none of whose moved bones enters or leaves its preference window,
    /// keeps its window — so its label — as it was; only the moved bones' entries are
    /// written. Every other point goes through the whole row: the nearest unmoved distance for
    /// the culling, the exact entries of the window, the argmin with the cone preference.
    /// (When the nearest bone did not move, the nearest unmoved distance *is* the remembered
    /// nearest distance: every other entry is exact and no smaller, or a bound beyond the
    /// window.) Points relabelled by [`Assignment::relabel`], new points and a change of
    /// `enabled` or `params` take the whole row at their next update.
    pub fn update(
        &mut self,
        bones: &[PreparedBone],
        bones_to_update: &[usize],
        range: std::ops::Range<usize>,
    ) {
        let nb = self.n_bones;
        if self.state_enabled != self.enabled || self.state_params != self.params {
            self.nearest.fill(u32::MAX);
            self.state_enabled.clone_from(&self.enabled);
            self.state_params = self.params;
        }
        let mut moved = vec![false; nb];
        for &b in bones_to_update {
            moved[b] = true;
        }
        // Bounding spheres of the moved bones.
        let spheres: Vec<(usize, Vec3, f32)> = bones_to_update
            .iter()
            .map(|&b| {
                let (c, r) = bones[b].bone.bounding_sphere();
                (b, c, r)
            })
            .collect();
        let row_ctx = RowContext {
            bones,
            moved: &moved,
            spheres: &spheres,
            enabled: &self.enabled,
            params: self.params,
        };
        let pos = &self.positions[range.clone()];
        let nrm = &self.normals[range.clone()];
        let dist = &mut self.dist[range.start * nb..range.end * nb];
        let cone = &mut self.cone[range.start * nb..range.end * nb];
        let bound = &mut self.bound[range.start * nb..range.end * nb];
        let label = &mut self.label[range.clone()];
        let nearest = &mut self.nearest[range.clone()];
        dist.par_chunks_mut(CHUNK * nb)
            .zip(cone.par_chunks_mut(CHUNK * nb))
            .zip(bound.par_chunks_mut(CHUNK * nb))
            .zip(
                label
                    .par_chunks_mut(CHUNK)
                    .zip(nearest.par_chunks_mut(CHUNK)),
            )
            .zip(pos.par_chunks(CHUNK).zip(nrm.par_chunks(CHUNK)))
            .for_each(|((((d, c), bd), (l, near)), (p, nn))| {
                for k in 0..p.len() {
                    let mut row = Row {
                        dist: &mut d[k * nb..(k + 1) * nb],
                        cone: &mut c[k * nb..(k + 1) * nb],
                        bound: &mut bd[k * nb..(k + 1) * nb],
                    };
                    if let Some(written) = row_ctx.shortcut(&mut row, near[k], p[k], nn[k]) {
                        (l[k], near[k]) = row_ctx.whole_row(&mut row, written, p[k], nn[k]);
                    }
                }
            });
    }

    /// Redoes the argmin (with the cone preference) for the points in `range`, from the
    /// distances as they are (those points take the whole row at their next
    /// [`Assignment::update`]).
    pub fn relabel(&mut self, range: std::ops::Range<usize>) {
        let nb = self.n_bones;
        let dist = &self.dist;
        let cone = &self.cone;
        let enabled = &self.enabled;
        let params = self.params;
        let start = range.start;
        self.nearest[range.clone()].fill(u32::MAX);
        self.label[range]
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(ci, labels)| {
                for (k, l) in labels.iter_mut().enumerate() {
                    let i = start + ci * CHUNK + k;
                    let row = &dist[i * nb..(i + 1) * nb];
                    let crow = &cone[i * nb..(i + 1) * nb];
                    *l = label_of(row, crow, enabled, params).0;
                }
            });
    }

    /// Recomputes the columns of `moved` bones for all points and relabels them.
    pub fn refresh(&mut self, bones: &[PreparedBone], moved: &[usize]) {
        let n = self.len();
        self.update(bones, moved, 0..n);
    }

    /// Distance of point `i` to bone `b` (as last computed).
    pub fn distance(&self, b: usize, i: usize) -> f32 {
        self.dist[i * self.n_bones + b]
    }

    /// Distance of point `i` to its assigned bone.
    pub fn own_distance(&self, i: usize) -> f32 {
        self.dist[i * self.n_bones + self.label[i] as usize]
    }

    /// Indices of the points assigned to each bone, in increasing order.
    pub fn members(&self) -> Vec<Vec<u32>> {
        let mut m = Vec::new();
        self.members_into(&mut m);
        m
    }

    /// [`Assignment::members`] written into `m`, whose lists keep their capacity (the solver
    /// rebuilds them after every refresh without allocating once they have grown).
    pub fn members_into(&self, m: &mut Vec<Vec<u32>>) {
        m.resize_with(self.n_bones, Vec::new);
        for list in m.iter_mut() {
            list.clear();
        }
        for (i, &l) in self.label.iter().enumerate() {
            m[l as usize].push(i as u32);
        }
    }

    /// Mean distance of the points to their bones (thesis eq. 2.16), summed in a fixed order.
    pub fn mean_distance(&self) -> f64 {
        if self.is_empty() {
            return 0.0;
        }
        let n = self.len();
        let partial: Vec<f64> = (0..n)
            .into_par_iter()
            .chunks(CHUNK)
            .map(|idx| {
                idx.iter()
                    .map(|&i| self.own_distance(i) as f64)
                    .sum::<f64>()
            })
            .collect();
        partial.iter().sum::<f64>() / n as f64
    }
}

/// The entries of one point's row.
struct Row<'a> {
    dist: &'a mut [f32],
    cone: &'a mut [bool],
    bound: &'a mut [bool],
}

/// What every row of an [`Assignment::update`] shares.
struct RowContext<'a> {
    bones: &'a [PreparedBone],
    moved: &'a [bool],
    /// The moved bones with their bounding spheres (centre, radius).
    spheres: &'a [(usize, Vec3, f32)],
    enabled: &'a [bool],
    params: AssignParams,
}

impl RowContext<'_> {
    #[inline]
    fn limit(&self, best: f32) -> f32 {
        window_limit(self.params, best)
    }

    /// Writes the moved bones' entries of `row`: the exact distance, or the lower bound of the
    /// bounding sphere when that cannot come within `limit` of the nearest unmoved distance.
    #[inline]
    fn write_moved(&self, row: &mut Row, limit: f32, p: Vec3, n: Vec3) {
        for &(b, centre, radius) in self.spheres {
            let lower = ((p - centre).length() - radius).max(0.0);
            if lower > limit {
                row.dist[b] = lower;
                row.cone[b] = false;
                row.bound[b] = true;
            } else {
                let proj = self.bones[b].project_constrained(p, n);
                row.dist[b] = proj.distance;
                row.cone[b] = proj.part == Part::Cone && proj.on_surface;
                row.bound[b] = false;
            }
        }
    }

    /// The shortcut of [`Assignment::update`]: `None` when the point's label and window stay
    /// as they were (its moved entries written); `Some(written)` when the whole row must be
    /// redone, `written` telling whether the moved entries are already written (just as
    /// [`RowContext::whole_row`] would write them).
    #[inline]
    fn shortcut(&self, row: &mut Row, nearest: u32, p: Vec3, n: Vec3) -> Option<bool> {
        if nearest == u32::MAX || self.moved[nearest as usize] {
            return Some(false);
        }
        let limit = self.limit(row.dist[nearest as usize]);
        // A moved, enabled bone inside the window before.
        let inside = |row: &Row| {
            self.spheres
                .iter()
                .any(|&(b, _, _)| self.enabled[b] && row.dist[b] <= limit)
        };
        if inside(row) {
            return Some(false);
        }
        self.write_moved(row, limit, p, n);
        // Or inside it now.
        inside(row).then_some(true)
    }

    /// Redoes the whole row of a point: moved entries (culled against the nearest unmoved
    /// distance), exact entries throughout the window, then the label with the cone
    /// preference (`written`: the moved entries are already written, by the shortcut, whose
    /// nearest distance was the nearest unmoved one). Returns the label and the nearest bone
    /// (`u32::MAX` when none).
    fn whole_row(&self, row: &mut Row, written: bool, p: Vec3, n: Vec3) -> (u32, u32) {
        let nb = row.dist.len();
        let (enabled, moved) = (self.enabled, self.moved);
        if !written {
            let mut best_unmoved = f32::INFINITY;
            for b in 0..nb {
                if !moved[b] && enabled[b] && row.dist[b] < best_unmoved {
                    best_unmoved = row.dist[b];
                }
            }
            self.write_moved(row, self.limit(best_unmoved), p, n);
        }
        // Every entry inside the argmin's preference window must be exact (a bound stored
        // earlier may have become competitive when its rival moved away).
        loop {
            let best = (0..nb)
                .filter(|&b| enabled[b])
                .map(|b| row.dist[b])
                .fold(f32::INFINITY, f32::min);
            let limit = self.limit(best);
            let Some(b) = (0..nb).find(|&b| enabled[b] && row.bound[b] && row.dist[b] <= limit)
            else {
                break;
            };
            let proj = self.bones[b].project_constrained(p, n);
            row.dist[b] = proj.distance;
            row.cone[b] = proj.part == Part::Cone && proj.on_surface;
            row.bound[b] = false;
        }
        label_of(row.dist, row.cone, enabled, self.params)
    }
}

/// The preference window's limit for the nearest distance `best`: the distances a cone part
/// may have and still be preferred ("similar", see the module docs).
#[inline]
fn window_limit(params: AssignParams, best: f32) -> f32 {
    (1.0 + params.cone_slack) * best + params.cone_abs
}

/// The label of a point from its row: the nearest enabled bone, or the nearest enabled cone
/// part within the preference window when the nearest projection is not on a cone part (0
/// when no bone is enabled or every distance is infinite). Also returns the nearest bone
/// (`u32::MAX` when none).
#[inline]
fn label_of(row: &[f32], crow: &[bool], enabled: &[bool], params: AssignParams) -> (u32, u32) {
    let nb = row.len();
    let mut best = u32::MAX;
    let mut best_d = f32::INFINITY;
    for b in 0..nb {
        if enabled[b] && row[b] < best_d {
            best_d = row[b];
            best = b as u32;
        }
    }
    let nearest = best;
    if best != u32::MAX && !crow[best as usize] {
        // Prefer a cone part with a similar distance.
        let limit = window_limit(params, best_d);
        let mut alt = u32::MAX;
        let mut alt_d = f32::INFINITY;
        for b in 0..nb {
            if enabled[b] && crow[b] && row[b] <= limit && row[b] < alt_d {
                alt_d = row[b];
                alt = b as u32;
            }
        }
        if alt != u32::MAX {
            best = alt;
        }
    }
    (if best == u32::MAX { 0 } else { best }, nearest)
}

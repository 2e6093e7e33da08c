//! Point clouds: the [`PointCloud`] container (structure of arrays), PLY input/output
//! ([`ply`]), normal estimation ([`normals`]), the statue's base ([`base`]) and a grid for
//! near-point tests ([`grid`]).

pub mod base;
pub mod grid;
pub mod normals;
pub mod ply;

use crate::math::Vec3;

/// A scanned statue as a structure of arrays: positions, and optionally one normal and one
/// colour per point. All arrays, when present, have the same length.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// Point positions, in the file's units and frame.
    pub positions: Vec<Vec3>,
    /// Unit outward normals, one per point, when known.
    pub normals: Option<Vec<Vec3>>,
    /// RGB colours, one per point, when the file has them.
    pub colors: Option<Vec<[u8; 3]>>,
}

/// An axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    /// The box of `points`, or `None` when there are none.
    pub fn of(points: &[Vec3]) -> Option<Aabb> {
        let first = *points.first()?;
        let (min, max) = points
            .iter()
            .fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p)));
        Some(Aabb { min, max })
    }
    /// Edge lengths.
    pub fn size(&self) -> Vec3 {
        self.max - self.min
    }
    /// Centre.
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }
    /// Length of the diagonal.
    pub fn diagonal(&self) -> f32 {
        self.size().length()
    }
}

impl PointCloud {
    /// A cloud of positions only.
    pub fn from_positions(positions: Vec<Vec3>) -> Self {
        PointCloud {
            positions,
            normals: None,
            colors: None,
        }
    }

    /// A cloud with positions and normals (the two vectors must have the same length).
    pub fn with_normals(positions: Vec<Vec3>, normals: Vec<Vec3>) -> Self {
        assert_eq!(positions.len(), normals.len(), "one normal per point");
        PointCloud {
            positions,
            normals: Some(normals),
            colors: None,
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when the cloud has no point.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Bounding box, `None` for an empty cloud.
    pub fn bounding_box(&self) -> Option<Aabb> {
        Aabb::of(&self.positions)
    }

    /// A scale estimate for the statue: the largest edge of the bounding box (its height for
    /// a standing figure). Zero for an empty cloud.
    pub fn scale_estimate(&self) -> f32 {
        self.bounding_box()
            .map(|b| b.size().max_element())
            .unwrap_or(0.0)
    }

    /// Keeps only the points whose index satisfies `keep`, in order, in every array.
    pub fn retain_indices(&mut self, mut keep: impl FnMut(usize) -> bool) {
        let mask: Vec<bool> = (0..self.len()).map(&mut keep).collect();
        fn filter<T: Copy>(v: &mut Vec<T>, mask: &[bool]) {
            let mut i = 0;
            v.retain(|_| {
                let k = mask[i];
                i += 1;
                k
            });
        }
        filter(&mut self.positions, &mask);
        if let Some(n) = self.normals.as_mut() {
            filter(n, &mask);
        }
        if let Some(c) = self.colors.as_mut() {
            filter(c, &mask);
        }
    }

    /// The sub-cloud of the given indices (in the given order).
    pub fn select(&self, indices: &[usize]) -> PointCloud {
        PointCloud {
            positions: indices.iter().map(|&i| self.positions[i]).collect(),
            normals: self
                .normals
                .as_ref()
                .map(|n| indices.iter().map(|&i| n[i]).collect()),
            colors: self
                .colors
                .as_ref()
                .map(|c| indices.iter().map(|&i| c[i]).collect()),
        }
    }
}

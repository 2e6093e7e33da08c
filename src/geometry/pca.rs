//! Principal component analysis of a point set (centroid, principal axes, variances).

use crate::math::{DVec3, Vec3};

/// Principal axes of a point set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pca {
    pub centroid: Vec3,
    /// Unit axes by decreasing variance, forming a right-handed frame.
    pub axes: [Vec3; 3],
    /// Variances along the axes.
    pub variances: [f32; 3],
}

/// PCA of `points` (`None` when empty). Sums are in `f64`, in order.
pub fn pca(points: &[Vec3]) -> Option<Pca> {
    if points.is_empty() {
        return None;
    }
    let n = points.len() as f64;
    let mean = points.iter().fold(DVec3::ZERO, |a, p| a + p.as_dvec3()) / n;
    let mut c = [[0.0f64; 3]; 3];
    for p in points {
        let d = p.as_dvec3() - mean;
        let d = [d.x, d.y, d.z];
        for i in 0..3 {
            for j in 0..3 {
                c[i][j] += d[i] * d[j];
            }
        }
    }
    for row in &mut c {
        for v in row.iter_mut() {
            *v /= n;
        }
    }
    let (vals, vecs) = jacobi3(c);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| vals[b].total_cmp(&vals[a]));
    let a0 = vecs[order[0]].normalize_or(DVec3::X);
    let a1 = vecs[order[1]].normalize_or(DVec3::Y);
    let a2 = a0.cross(a1).normalize_or(DVec3::Z);
    Some(Pca {
        centroid: mean.as_vec3(),
        axes: [a0.as_vec3(), a1.as_vec3(), a2.as_vec3()],
        variances: [
            vals[order[0]] as f32,
            vals[order[1]] as f32,
            vals[order[2]] as f32,
        ],
    })
}

/// Eigen-decomposition of a symmetric 3×3 matrix by cyclic Jacobi rotations.
#[allow(clippy::needless_range_loop)] // index arithmetic mirrors the textbook rotation
fn jacobi3(mut a: [[f64; 3]; 3]) -> ([f64; 3], [DVec3; 3]) {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off < 1e-300 {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for row in &mut v {
                let (vkp, vkq) = (row[p], row[q]);
                row[p] = c * vkp - s * vkq;
                row[q] = s * vkp + c * vkq;
            }
        }
    }
    let vals = [a[0][0], a[1][1], a[2][2]];
    let vecs = [0, 1, 2].map(|j| DVec3::new(v[0][j], v[1][j], v[2][j]));
    (vals, vecs)
}

//! Eight-lane `f32` vectors for the per-frame kernels of skinning ([`super::heightfield`]):
//! plain arrays whose element-wise operations the compiler turns into SIMD instructions (SSE2
//! on any x86-64), with no `unsafe` and no intrinsics. Every operation is the IEEE operation
//! lane by lane (no fused multiply-add is introduced), so a lane computes bit for bit what
//! scalar code would: the kernels can serve one point (a broadcast) or eight alike.

use crate::math::{Mat3, Vec3};
use std::ops::{Add, Div, Mul, Neg, Sub};

/// Lanes per vector.
pub const L: usize = 8;

/// Eight `f32` lanes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(32))]
pub struct F8(pub [f32; L]);

/// Eight lane masks.
pub type M8 = [bool; L];

impl F8 {
    /// Every lane `v`.
    #[inline(always)]
    pub fn splat(v: f32) -> F8 {
        F8([v; L])
    }
    /// Lane-wise `f`.
    #[inline(always)]
    pub fn map(self, f: impl Fn(f32) -> f32) -> F8 {
        let mut r = [0.0; L];
        for (r, a) in r.iter_mut().zip(self.0) {
            *r = f(a);
        }
        F8(r)
    }
    /// Lane-wise `f` of two vectors.
    #[inline(always)]
    pub fn zip(self, o: F8, f: impl Fn(f32, f32) -> f32) -> F8 {
        let mut r = [0.0; L];
        for ((r, a), b) in r.iter_mut().zip(self.0).zip(o.0) {
            *r = f(a, b);
        }
        F8(r)
    }
    /// The first `min(8, s.len())` values of `s`, the other lanes 0.
    #[inline(always)]
    pub fn load(s: &[f32]) -> F8 {
        match s.first_chunk::<L>() {
            Some(a) => F8(*a),
            None => {
                let mut a = [0.0; L];
                for (x, y) in a.iter_mut().zip(s) {
                    *x = *y;
                }
                F8(a)
            }
        }
    }
    /// Writes the first `min(8, out.len())` lanes into `out`.
    #[inline(always)]
    pub fn store(self, out: &mut [f32]) {
        match out.first_chunk_mut::<L>() {
            Some(a) => *a = self.0,
            None => {
                for (y, x) in out.iter_mut().zip(self.0) {
                    *y = x;
                }
            }
        }
    }
    /// Lane-wise square root.
    #[inline(always)]
    pub fn sqrt(self) -> F8 {
        self.map(f32::sqrt)
    }
    /// Lane-wise minimum (`self` where either is NaN... as `if a < b {a} else {b}`).
    #[inline(always)]
    pub fn min(self, o: F8) -> F8 {
        self.zip(o, |a, b| if a < b { a } else { b })
    }
    /// Lane-wise maximum (as `if a > b {a} else {b}`).
    #[inline(always)]
    pub fn max(self, o: F8) -> F8 {
        self.zip(o, |a, b| if a > b { a } else { b })
    }
    /// Lane-wise `self < o`.
    #[inline(always)]
    pub fn lt(self, o: F8) -> M8 {
        let mut r = [false; L];
        for ((r, a), b) in r.iter_mut().zip(self.0).zip(o.0) {
            *r = a < b;
        }
        r
    }
    /// Lane-wise `m ? a : b`.
    #[inline(always)]
    pub fn select(m: M8, a: F8, b: F8) -> F8 {
        let mut r = b.0;
        for ((r, a), m) in r.iter_mut().zip(a.0).zip(m) {
            if m {
                *r = a;
            }
        }
        F8(r)
    }
    /// Lane-wise `eˣ` for `|x| ≤ 80`: `2ⁿ eʳ` with `n` the nearest integer to `x / ln 2` and a
    /// degree-6 polynomial for `|r| ≤ ln 2 / 2` (relative error below 3·10⁻⁷).
    #[inline(always)]
    pub fn exp(self) -> F8 {
        self.map(|x| {
            // Round to nearest with the 1.5·2²³ trick (no rounding instruction needed).
            const MAGIC: f32 = 12_582_912.0;
            let n = (x * std::f32::consts::LOG2_E + MAGIC) - MAGIC;
            let r = x - n * 0.693_145_75 - n * 1.428_606_8e-6;
            let p = 1.0
                + r * (1.0
                    + r * (0.5
                        + r * (1.0 / 6.0
                            + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
            p * f32::from_bits(((n as i32 + 127) << 23) as u32)
        })
    }
}

macro_rules! binop {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for F8 {
            type Output = F8;
            #[inline(always)]
            fn $f(self, o: F8) -> F8 {
                self.zip(o, |a, b| a $op b)
            }
        }
        impl $tr<f32> for F8 {
            type Output = F8;
            #[inline(always)]
            fn $f(self, o: f32) -> F8 {
                self.map(|a| a $op o)
            }
        }
        impl $tr<F8> for f32 {
            type Output = F8;
            #[inline(always)]
            fn $f(self, o: F8) -> F8 {
                o.map(|b| self $op b)
            }
        }
    };
}
binop!(Add, add, +);
binop!(Sub, sub, -);
binop!(Mul, mul, *);
binop!(Div, div, /);

impl Neg for F8 {
    type Output = F8;
    #[inline(always)]
    fn neg(self) -> F8 {
        self.map(|a| -a)
    }
}

/// Eight 3-vectors, structure of arrays.
#[derive(Clone, Copy, Debug, Default)]
pub struct V3 {
    pub x: F8,
    pub y: F8,
    pub z: F8,
}

impl V3 {
    /// Every lane `v`.
    #[inline(always)]
    pub fn splat(v: Vec3) -> V3 {
        V3 {
            x: F8::splat(v.x),
            y: F8::splat(v.y),
            z: F8::splat(v.z),
        }
    }
    /// Lane `i`.
    #[inline(always)]
    pub fn lane(&self, i: usize) -> Vec3 {
        Vec3::new(self.x.0[i], self.y.0[i], self.z.0[i])
    }
    /// Lane-wise dot product.
    #[inline(always)]
    pub fn dot(self, o: V3) -> F8 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// Lane-wise dot product with a constant vector.
    #[inline(always)]
    pub fn dot_c(self, o: Vec3) -> F8 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// Lane-wise cross product `c × self` with a constant vector `c`.
    #[inline(always)]
    pub fn cross_from(self, c: Vec3) -> V3 {
        V3 {
            x: c.y * self.z - c.z * self.y,
            y: c.z * self.x - c.x * self.z,
            z: c.x * self.y - c.y * self.x,
        }
    }
    /// Lane-wise `self · s`.
    #[inline(always)]
    pub fn scale(self, s: F8) -> V3 {
        V3 {
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }
    /// Lane-wise `self + c` with a constant vector.
    #[inline(always)]
    pub fn add_c(self, c: Vec3) -> V3 {
        V3 {
            x: self.x + c.x,
            y: self.y + c.y,
            z: self.z + c.z,
        }
    }
    /// Lane-wise unit vector, `fallback` where the length is zero or not finite (as
    /// [`Vec3::normalize_or`]).
    #[inline(always)]
    pub fn normalize_or(self, fallback: V3) -> V3 {
        let rcp = 1.0 / self.dot(self).sqrt();
        let mut ok = [false; L];
        for (ok, r) in ok.iter_mut().zip(rcp.0) {
            *ok = r.is_finite() && r > 0.0;
        }
        V3 {
            x: F8::select(ok, self.x * rcp, fallback.x),
            y: F8::select(ok, self.y * rcp, fallback.y),
            z: F8::select(ok, self.z * rcp, fallback.z),
        }
    }
    /// Lane-wise `m v` with a constant matrix.
    #[inline(always)]
    pub fn mat(m: &Mat3, v: V3) -> V3 {
        V3 {
            x: v.x * m.x_axis.x + v.y * m.y_axis.x + v.z * m.z_axis.x,
            y: v.x * m.x_axis.y + v.y * m.y_axis.y + v.z * m.z_axis.y,
            z: v.x * m.x_axis.z + v.y * m.y_axis.z + v.z * m.z_axis.z,
        }
    }
    /// Lane-wise `mᵀ v` with a constant matrix.
    #[inline(always)]
    pub fn mat_t(m: &Mat3, v: V3) -> V3 {
        V3 {
            x: v.dot_c(m.x_axis),
            y: v.dot_c(m.y_axis),
            z: v.dot_c(m.z_axis),
        }
    }
}

impl Add for V3 {
    type Output = V3;
    #[inline(always)]
    fn add(self, o: V3) -> V3 {
        V3 {
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }
}

impl Sub for V3 {
    type Output = V3;
    #[inline(always)]
    fn sub(self, o: V3) -> V3 {
        V3 {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }
}

/// `true` when the processor runs AVX2 (checked once, then cached by the standard library):
/// the per-frame kernels then have a copy compiled for it, where eight lanes fill one register
/// instead of two. Both copies give the same results bit for bit (the same IEEE operations,
/// lane by lane; no fused multiply-add either way).
#[inline]
pub fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

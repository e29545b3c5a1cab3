//! A plain 2-vector for the planar model: the few operations the kinematics and the
//! Newton–Euler equations need (rotation, perpendicular, scalar cross product), all `Copy`.

use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

/// A point or vector in the plane of motion, SI units (m, N, m/s …) as the name says.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct V2 {
    pub x: f64,
    pub y: f64,
}

impl V2 {
    pub const ZERO: V2 = V2 { x: 0.0, y: 0.0 };

    #[inline]
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }
    #[inline]
    pub fn from_array(a: [f64; 2]) -> Self {
        Self { x: a[0], y: a[1] }
    }
    #[inline]
    pub fn dot(self, o: V2) -> f64 {
        self.x * o.x + self.y * o.y
    }
    /// Scalar (z) cross product self × o: the moment of force `o` at lever `self`.
    #[inline]
    pub fn cross(self, o: V2) -> f64 {
        self.x * o.y - self.y * o.x
    }
    /// k × self: the vector turned +90°.
    #[inline]
    pub fn perp(self) -> V2 {
        V2::new(-self.y, self.x)
    }
    #[inline]
    pub fn norm2(self) -> f64 {
        self.dot(self)
    }
    #[inline]
    pub fn norm(self) -> f64 {
        self.norm2().sqrt()
    }
}

/// A rotation by θ in the plane, kept as (cos θ, sin θ): no trigonometry after it is formed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rot {
    pub c: f64,
    pub s: f64,
}

impl Rot {
    #[inline]
    pub fn from_angle(theta_rad: f64) -> Self {
        let (s, c) = theta_rad.sin_cos();
        Self { c, s }
    }
    /// The rotation taking direction `from` onto direction `to` (lengths need not match).
    #[inline]
    pub fn between(from: V2, to: V2) -> Self {
        let (c, s) = (from.dot(to), from.cross(to));
        let n = (c * c + s * s).sqrt();
        Self { c: c / n, s: s / n }
    }
    #[inline]
    pub fn apply(self, v: V2) -> V2 {
        V2::new(self.c * v.x - self.s * v.y, self.s * v.x + self.c * v.y)
    }
    /// θ in (−π, π].
    #[inline]
    pub fn angle(self) -> f64 {
        self.s.atan2(self.c)
    }
}

impl Add for V2 {
    type Output = V2;
    #[inline]
    fn add(self, o: V2) -> V2 {
        V2::new(self.x + o.x, self.y + o.y)
    }
}
impl Sub for V2 {
    type Output = V2;
    #[inline]
    fn sub(self, o: V2) -> V2 {
        V2::new(self.x - o.x, self.y - o.y)
    }
}
impl Neg for V2 {
    type Output = V2;
    #[inline]
    fn neg(self) -> V2 {
        V2::new(-self.x, -self.y)
    }
}
impl Mul<f64> for V2 {
    type Output = V2;
    #[inline]
    fn mul(self, k: f64) -> V2 {
        V2::new(self.x * k, self.y * k)
    }
}
impl Mul<V2> for f64 {
    type Output = V2;
    #[inline]
    fn mul(self, v: V2) -> V2 {
        V2::new(self * v.x, self * v.y)
    }
}
impl AddAssign for V2 {
    #[inline]
    fn add_assign(&mut self, o: V2) {
        self.x += o.x;
        self.y += o.y;
    }
}
impl SubAssign for V2 {
    #[inline]
    fn sub_assign(&mut self, o: V2) {
        self.x -= o.x;
        self.y -= o.y;
    }
}

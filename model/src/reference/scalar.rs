//! The number types the rod kinematics run in: `f64`, `f32` (to test the exponential map in the
//! firmware's precision) and [`Dual`], a forward-mode dual number whose derivative part gives the
//! exact Jacobian of the piecewise-constant-strain equations without hand-derived tangent maps.

use core::ops::{Add, Div, Mul, Neg, Sub};

/// Arithmetic and the few functions the kinematics need.
pub trait Scalar:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + PartialOrd
    + core::fmt::Debug
{
    /// Converts a constant.
    fn of(x: f64) -> Self;
    /// The value as f64 (the real part of a dual number).
    fn value(self) -> f64;
    /// Sine.
    fn sin(self) -> Self;
    /// Cosine.
    fn cos(self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
}

impl Scalar for f64 {
    fn of(x: f64) -> Self {
        x
    }
    fn value(self) -> f64 {
        self
    }
    fn sin(self) -> Self {
        libm::sin(self)
    }
    fn cos(self) -> Self {
        libm::cos(self)
    }
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
}

impl Scalar for f32 {
    fn of(x: f64) -> Self {
        x as f32
    }
    fn value(self) -> f64 {
        self as f64
    }
    fn sin(self) -> Self {
        libm::sinf(self)
    }
    fn cos(self) -> Self {
        libm::cosf(self)
    }
    fn sqrt(self) -> Self {
        libm::sqrtf(self)
    }
}

/// Dual number `v + d ε` with `ε² = 0`: carrying `d = ∂v/∂x` through a computation gives the
/// exact derivative along one direction `x`.
#[derive(Clone, Copy, Debug, PartialEq, PartialOrd)]
pub struct Dual {
    /// Value.
    pub v: f64,
    /// Derivative along the seeded direction.
    pub d: f64,
}

impl Dual {
    /// A variable seeded with derivative `d`.
    pub fn new(v: f64, d: f64) -> Self {
        Dual { v, d }
    }
}

impl Add for Dual {
    type Output = Dual;
    fn add(self, o: Dual) -> Dual {
        Dual::new(self.v + o.v, self.d + o.d)
    }
}
impl Sub for Dual {
    type Output = Dual;
    fn sub(self, o: Dual) -> Dual {
        Dual::new(self.v - o.v, self.d - o.d)
    }
}
impl Mul for Dual {
    type Output = Dual;
    fn mul(self, o: Dual) -> Dual {
        Dual::new(self.v * o.v, self.d * o.v + self.v * o.d)
    }
}
impl Div for Dual {
    type Output = Dual;
    fn div(self, o: Dual) -> Dual {
        Dual::new(self.v / o.v, (self.d * o.v - self.v * o.d) / (o.v * o.v))
    }
}
impl Neg for Dual {
    type Output = Dual;
    fn neg(self) -> Dual {
        Dual::new(-self.v, -self.d)
    }
}

impl Scalar for Dual {
    fn of(x: f64) -> Self {
        Dual::new(x, 0.0)
    }
    fn value(self) -> f64 {
        self.v
    }
    fn sin(self) -> Self {
        Dual::new(libm::sin(self.v), self.d * libm::cos(self.v))
    }
    fn cos(self) -> Self {
        Dual::new(libm::cos(self.v), -self.d * libm::sin(self.v))
    }
    fn sqrt(self) -> Self {
        let s = libm::sqrt(self.v);
        Dual::new(s, self.d / (2.0 * s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dual_derivative_matches_the_analytic_one() {
        // f(x) = sin(x) sqrt(x) / (1 + x²): f' by hand.
        let x = 0.7;
        let d = Dual::new(x, 1.0);
        let f = d.sin() * d.sqrt() / (Dual::of(1.0) + d * d);
        let g = libm::sin(x) * libm::sqrt(x);
        let gp = libm::cos(x) * libm::sqrt(x) + libm::sin(x) / (2.0 * libm::sqrt(x));
        let h = 1.0 + x * x;
        let exact = (gp * h - g * 2.0 * x) / (h * h);
        assert!((f.d - exact).abs() < 1e-14, "{} vs {exact}", f.d);
    }
}

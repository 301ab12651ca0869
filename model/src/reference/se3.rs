//! The exponential map of SE(3), `g(s) = exp(ξ̂ s)` (paper Eq. 5), in any [`Scalar`].
//!
//! With `φ = ω s`, `θ = |φ|`: `R = I + A [φ]× + B [φ]×²` and `p = (I + B [φ]× + C [φ]×²) ν s`
//! with `A = sin θ/θ`, `B = (1 − cos θ)/θ²`, `C = (θ − sin θ)/θ³`. All three have a removable
//! singularity at θ = 0, and `C` cancels catastrophically well before it: in `f32` the closed
//! form of `C` is wrong in its first digit below θ ≈ 0.01. Below [`SERIES_BELOW_RAD`] the
//! coefficients come from their Taylor series in θ² (which also keeps dual numbers finite at
//! θ = 0, where `sqrt` has no derivative).

use super::scalar::Scalar;

/// θ below which the coefficients are summed as series, rad. At θ = 1 the closed form's
/// cancellation costs at most a few ulp in `f32` and the ten-term series is exact to f64
/// rounding, so both sides of the switch are accurate in both precisions (tested).
pub const SERIES_BELOW_RAD: f64 = 1.0;

/// Number of series terms (up to θ¹⁸): the first omitted term of `A` at θ = 1 is 1/21! ≈ 2e-20.
const SERIES_TERMS: usize = 10;

/// 3-vector.
pub type V3<S> = [S; 3];

/// Rigid transform: rotation (rows) and translation, m.
#[derive(Clone, Copy, Debug)]
pub struct Pose<S> {
    /// Rotation matrix, row-major.
    pub r: [[S; 3]; 3],
    /// Translation, m.
    pub p: V3<S>,
}

/// `a × b`.
pub fn cross<S: Scalar>(a: V3<S>, b: V3<S>) -> V3<S> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `a · b`.
pub fn dot<S: Scalar>(a: V3<S>, b: V3<S>) -> S {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The coefficients `(A, B, C)` of the exponential map as functions of `θ² = theta_sq`.
pub fn coefficients<S: Scalar>(theta_sq: S) -> (S, S, S) {
    if theta_sq.value() < SERIES_BELOW_RAD * SERIES_BELOW_RAD {
        series(theta_sq, SERIES_TERMS)
    } else {
        closed_form(theta_sq)
    }
}

/// The closed forms of `(A, B, C)`; inaccurate for small θ (kept public so the tests and the
/// docs can show where they fail).
pub fn closed_form<S: Scalar>(theta_sq: S) -> (S, S, S) {
    let t = theta_sq.sqrt();
    let (s, c) = (t.sin(), t.cos());
    (s / t, (S::of(1.0) - c) / theta_sq, (t - s) / (theta_sq * t))
}

/// Taylor series of `(A, B, C)` in θ² with `terms` terms:
/// `A = Σ (−θ²)ⁿ/(2n+1)!`, `B = Σ (−θ²)ⁿ/(2n+2)!`, `C = Σ (−θ²)ⁿ/(2n+3)!`.
pub fn series<S: Scalar>(theta_sq: S, terms: usize) -> (S, S, S) {
    let fact = |k: usize| (1..=k).fold(1.0f64, |f, i| f * i as f64);
    let horner = |off: usize| {
        let mut acc = S::of(0.0);
        for n in (0..terms).rev() {
            let sign = if n % 2 == 0 { 1.0 } else { -1.0 };
            acc = acc * theta_sq + S::of(sign / fact(2 * n + off));
        }
        acc
    };
    // Horner in θ² with alternating signs built into the coefficients.
    (horner(1), horner(2), horner(3))
}

/// `exp(ξ̂ s)` for strain `omega` (1/m), `nu` (dimensionless) over arc length `s_m`.
pub fn exp_map<S: Scalar>(omega: V3<S>, nu: V3<S>, s_m: S) -> Pose<S> {
    let phi = [omega[0] * s_m, omega[1] * s_m, omega[2] * s_m];
    let th2 = dot(phi, phi);
    let (a, b, c) = coefficients(th2);
    let one = S::of(1.0);
    let zero = S::of(0.0);
    // [φ]× and [φ]×².
    let k = [
        [zero, -phi[2], phi[1]],
        [phi[2], zero, -phi[0]],
        [-phi[1], phi[0], zero],
    ];
    let mut k2 = [[zero; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            k2[i][j] = k[i][0] * k[0][j] + k[i][1] * k[1][j] + k[i][2] * k[2][j];
        }
    }
    let mut r = [[zero; 3]; 3];
    let mut v = [[zero; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let id = if i == j { one } else { zero };
            r[i][j] = id + a * k[i][j] + b * k2[i][j];
            v[i][j] = id + b * k[i][j] + c * k2[i][j];
        }
    }
    let nus = [nu[0] * s_m, nu[1] * s_m, nu[2] * s_m];
    let p = [dot(v[0], nus), dot(v[1], nus), dot(v[2], nus)];
    Pose { r, p }
}

impl<S: Scalar> Pose<S> {
    /// The identity.
    pub fn identity() -> Self {
        let (o, z) = (S::of(1.0), S::of(0.0));
        Pose {
            r: [[o, z, z], [z, o, z], [z, z, o]],
            p: [z; 3],
        }
    }

    /// `self · other`.
    pub fn compose(&self, o: &Pose<S>) -> Pose<S> {
        let z = S::of(0.0);
        let mut r = [[z; 3]; 3];
        let mut p = self.p;
        for i in 0..3 {
            for j in 0..3 {
                r[i][j] =
                    self.r[i][0] * o.r[0][j] + self.r[i][1] * o.r[1][j] + self.r[i][2] * o.r[2][j];
            }
            p[i] = p[i] + dot(self.r[i], o.p);
        }
        Pose { r, p }
    }

    /// `Rᵀ x` (a fixed-frame vector in this frame).
    pub fn rotate_back(&self, x: V3<S>) -> V3<S> {
        let r = &self.r;
        [
            r[0][0] * x[0] + r[1][0] * x[1] + r[2][0] * x[2],
            r[0][1] * x[0] + r[1][1] * x[1] + r[2][1] * x[2],
            r[0][2] * x[0] + r[1][2] * x[1] + r[2][2] * x[2],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference coefficients in f64: the series (20 terms) below 1, the closed form above.
    fn reference(theta: f64) -> (f64, f64, f64) {
        if theta < 1.0 {
            series(theta * theta, 20)
        } else {
            closed_form(theta * theta)
        }
    }

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs()
    }

    const THETAS: [f64; 12] = [
        0.0, 1e-8, 1e-4, 1e-2, 0.3, 0.9, 0.999, 1.001, 1.5, 3.0, 6.5, 12.0,
    ];

    #[test]
    fn coefficients_are_accurate_on_both_sides_of_the_switch_in_f64() {
        for &t in &THETAS {
            let (a, b, c) = coefficients(t * t);
            let (ra, rb, rc) = reference(t);
            for (x, y) in [(a, ra), (b, rb), (c, rc)] {
                assert!(rel(x, y) < 1e-14, "f64 θ={t}: {x} vs {y}");
            }
        }
    }

    #[test]
    fn coefficients_are_accurate_on_both_sides_of_the_switch_in_f32() {
        for &t in &THETAS {
            let tf = t as f32;
            let (a, b, c) = coefficients(tf * tf);
            let (ra, rb, rc) = reference(tf as f64);
            for (x, y) in [(a, ra), (b, rb), (c, rc)] {
                // A few ulp of f32 (and the θ² rounding near 12 rad).
                assert!(rel(x as f64, y) < 2e-6, "f32 θ={t}: {x} vs {y}");
            }
        }
    }

    #[test]
    fn the_closed_form_fails_at_small_angles_which_is_why_the_series_exists() {
        // f32: C loses every digit near θ = 1e-3; f64: it has lost half its digits at 1e-4.
        let t = 1e-3f32;
        let c32 = closed_form(t * t).2 as f64;
        assert!(rel(c32, 1.0 / 6.0) > 0.1, "f32 closed form C = {c32}");
        let t = 1e-4f64;
        let c64 = closed_form(t * t).2;
        assert!(rel(c64, 1.0 / 6.0) > 1e-9, "f64 closed form C = {c64}");
        // And at θ = 0 it is 0/0.
        assert!(closed_form(0.0f64).0.is_nan());
    }

    #[test]
    fn pure_bending_is_a_circular_arc_beyond_two_pi() {
        // ω = (0, κ, 0), ν = (0, 0, 1): the centreline is a circle of radius 1/κ in the x-z plane.
        for &kl in &[1e-9, 0.5, 3.0, 7.0, 13.0] {
            let (kappa, l) = (kl / 0.05, 0.05);
            let g = exp_map([0.0, kappa, 0.0], [0.0, 0.0, 1.0], l);
            let (x, z) = (g.p[0], g.p[2]);
            let ex = 2.0 * libm::sin(kl / 2.0) * libm::sin(kl / 2.0) / kappa;
            let ez = libm::sin(kl) / kappa;
            assert!((x - ex).abs() < 1e-12 && (z - ez).abs() < 1e-12, "κL={kl}");
            // Rotation is orthonormal.
            let r = g.r;
            let d = dot(r[0], r[0]) + dot(r[1], r[1]) + dot(r[2], r[2]);
            assert!((d - 3.0).abs() < 1e-12);
        }
    }

    #[test]
    fn exp_of_a_sum_of_parallel_strains_composes() {
        let w = [0.3f64, -2.0, 5.0];
        let n = [0.1f64, 0.2, 1.0];
        let a = exp_map(w, n, 0.02).compose(&exp_map(w, n, 0.03));
        let b = exp_map(w, n, 0.05);
        for i in 0..3 {
            assert!((a.p[i] - b.p[i]).abs() < 1e-15);
            for j in 0..3 {
                assert!((a.r[i][j] - b.r[i][j]).abs() < 1e-14);
            }
        }
    }
}

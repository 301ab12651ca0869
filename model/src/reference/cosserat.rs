//! The Cosserat rod of the paper (Eq. 4–9): strain `ξ = [ω, ν]` (six components, body frame),
//! pose `g(s) = g₀ exp(ξ̂ s)`, wrench balance `K (ξ − ξ*) = W_act + W_ext` with
//! `W_act = F [r × t; t]`, `t` the unit tangent of the actuator path `ν + ω × r` (Eq. 6–8) and
//! `F = F(δ, T)` the TCA push at extension `δ = (|ν + ω × r| − 1) L`.
//!
//! * [`solve_constant`]: constant strain over the whole rod (the paper's model), Newton with the
//!   analytic Jacobian `K − ∂W_act/∂ξ`.
//! * [`solve_piecewise`]: N segments of constant strain, the balance collocated at each
//!   segment's midpoint with a dead tip load carried to it; Newton with the exact Jacobian from
//!   dual numbers (the actuator's extension couples every segment).
//! * [`solve_robust`]: Newton from the given guess, then damped Newton, then continuation in the
//!   load factor (the TCA power / tip load ramped from zero), reporting which one answered.
//!
//! Residuals are scaled by the diagonal of `K` (strain units) so that convergence means the same
//! thing when the stiffness spans many orders (cold PLA versus silicone).

use super::scalar::{Dual, Scalar};
use super::se3::{cross, dot, exp_map, Pose, V3};
use super::tca_physics::ForceAtTemp;
use super::ReferenceError;
use crate::params::LinkParams;
use nalgebra::{DMatrix, DVector};

/// Strain `[ωx, ωy, ωz, νx, νy, νz]`: curvatures (1/m) and stretch/shear (dimensionless).
pub type Strain = [f64; 6];

/// Strain of the straight, unloaded rod `ξ*`.
pub const REFERENCE_STRAIN: Strain = [0.0, 0.0, 0.0, 0.0, 0.0, 1.0];

/// Scaled residual at which Newton stops (strain units: 1/m for curvature, 1 for stretch).
pub const TOLERANCE: f64 = 1e-10;
/// Newton iterations before giving up.
pub const MAX_ITERATIONS: usize = 40;

/// A rod and its loads.
#[derive(Clone, Debug, PartialEq)]
pub struct Rod {
    /// Length, m.
    pub length_m: f64,
    /// Section stiffness `K` (rows/columns in strain order), N m² / N m / N.
    pub stiffness: [[f64; 6]; 6],
    /// Actuator offset `r` in the section, m.
    pub actuator_offset_m: V3<f64>,
    /// Actuator push at the working temperature, if an actuator acts.
    pub actuator: Option<ForceAtTemp>,
    /// Dead tip force in the base frame, N.
    pub tip_force_n: V3<f64>,
    /// Tip moment, N m: in the base frame for the piecewise rod; for the constant-strain rod it
    /// is taken in the body frame (a follower end moment, exact for a moment about a bending axis).
    pub tip_moment_nm: V3<f64>,
}

/// Which method produced a solution.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Plain Newton from the guess.
    Newton,
    /// Newton with a backtracking line search.
    Damped,
    /// Damped Newton along a ramp of the load from zero, in this many steps.
    Continuation(usize),
}

/// A converged equilibrium.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    /// Strain of each segment (one for constant strain).
    pub strains: Vec<Strain>,
    /// Newton iterations in total.
    pub iterations: usize,
    /// The method that converged.
    pub method: Method,
    /// Final scaled residual.
    pub residual: f64,
}

/// Section stiffness of the link of `p`: an effective modulus `E = EI/I` of the whole round
/// section (EI the fitted soft-link stiffness), `G = E/3` (incompressible), so
/// `K = diag(EI, EI, GJ, GA, GA, EA)`. With `pla_temp_c`, the PLA's modulus above its rubbery
/// value at that temperature is added as a rod at `+pla_offset` on the x axis (opposite the TCA),
/// which also couples bending about y with stretch (`K[ωy][νz] = −ΔE A x`).
pub fn link_stiffness(p: &LinkParams, pla_temp_c: Option<f64>) -> [[f64; 6]; 6] {
    let g = &p.geometry;
    let a = g.body_diameter_m / 2.0;
    let i = core::f64::consts::PI * a * a * a * a / 4.0;
    let area = core::f64::consts::PI * a * a;
    let ei = p.mechanics.bending_stiffness_nm2;
    let e = ei / i;
    let gm = e / 3.0;
    let mut k = [[0.0; 6]; 6];
    let diag = [ei, ei, gm * 2.0 * i, gm * area, gm * area, e * area];
    for j in 0..6 {
        k[j][j] = diag[j];
    }
    if let Some(t) = pla_temp_c {
        let de = (crate::mechanics::pla_modulus_pa(&p.pla_stiffness, t)
            - p.pla_stiffness.e_rubbery_pa)
            .max(0.0);
        let ip = crate::mechanics::pla_second_moment_m4(p);
        let ap = core::f64::consts::PI * g.pla_diameter_m * g.pla_diameter_m / 4.0;
        let x = g.pla_offset_m;
        k[0][0] += de * ip;
        k[1][1] += de * (ip + ap * x * x);
        k[2][2] += de / 3.0 * 2.0 * ip;
        k[5][5] += de * ap;
        k[1][5] -= de * ap * x;
        k[5][1] -= de * ap * x;
    }
    k
}

impl Rod {
    /// The link of `p` driven by `actuator`: the TCA at `−tca_offset` on the x axis, so that
    /// bending about +y lengthens it (it is on the convex side).
    pub fn of_link(p: &LinkParams, actuator: ForceAtTemp, pla_temp_c: Option<f64>) -> Self {
        Rod {
            length_m: p.geometry.length_m,
            stiffness: link_stiffness(p, pla_temp_c),
            actuator_offset_m: [-p.geometry.tca_offset_m, 0.0, 0.0],
            actuator: Some(actuator),
            tip_force_n: [0.0; 3],
            tip_moment_nm: [0.0; 3],
        }
    }

    /// The same rod with every load (actuator push, tip force and moment) times `lambda`.
    pub fn scaled(&self, lambda: f64) -> Self {
        let mut r = self.clone();
        if let Some(a) = &mut r.actuator {
            a.push_n *= lambda;
        }
        for j in 0..3 {
            r.tip_force_n[j] *= lambda;
            r.tip_moment_nm[j] *= lambda;
        }
        r
    }

    /// Diagonal of `K`, the residual scale; a stiffness that is not positive is an error.
    fn scale(&self) -> Result<[f64; 6], ReferenceError> {
        for j in 0..6 {
            let k = self.stiffness[j][j];
            if !(k > 0.0 && k.is_finite()) {
                return Err(ReferenceError::NotPositiveDefinite { row: j });
            }
        }
        Ok(core::array::from_fn(|j| self.stiffness[j][j]))
    }

    /// Residual of one segment's balance with the actuator push `force` and an external
    /// body-frame wrench `ext` (moment, force).
    fn balance<S: Scalar>(
        &self,
        xi: &[S; 6],
        force: S,
        ext: [S; 6],
    ) -> Result<[S; 6], ReferenceError> {
        let r = [
            S::of(self.actuator_offset_m[0]),
            S::of(self.actuator_offset_m[1]),
            S::of(self.actuator_offset_m[2]),
        ];
        let w = [xi[0], xi[1], xi[2]];
        let n = [xi[3], xi[4], xi[5]];
        let mut act = [S::of(0.0); 6];
        if self.actuator.is_some() {
            let wr = cross(w, r);
            let v = [n[0] + wr[0], n[1] + wr[1], n[2] + wr[2]];
            let len2 = dot(v, v);
            if !(len2.value() > 1e-18) {
                return Err(ReferenceError::DegenerateActuatorPath);
            }
            let len = len2.sqrt();
            let t = [v[0] / len, v[1] / len, v[2] / len];
            let m = cross(r, t);
            act = [
                force * m[0],
                force * m[1],
                force * m[2],
                force * t[0],
                force * t[1],
                force * t[2],
            ];
        }
        Ok(core::array::from_fn(|j| {
            let mut s = S::of(0.0);
            for c in 0..6 {
                s = s + S::of(self.stiffness[j][c]) * (xi[c] - S::of(REFERENCE_STRAIN[c]));
            }
            s - act[j] - ext[j]
        }))
    }

    /// Actuator length change `δ` over segments of length `h`, m.
    fn extension<S: Scalar>(&self, strains: &[[S; 6]], h: f64) -> S {
        let r = [
            S::of(self.actuator_offset_m[0]),
            S::of(self.actuator_offset_m[1]),
            S::of(self.actuator_offset_m[2]),
        ];
        let mut d = S::of(0.0);
        for xi in strains {
            let wr = cross([xi[0], xi[1], xi[2]], r);
            let v = [xi[3] + wr[0], xi[4] + wr[1], xi[5] + wr[2]];
            d = d + (dot(v, v).sqrt() - S::of(1.0)) * S::of(h);
        }
        d
    }

    fn push<S: Scalar>(&self, delta: S) -> S {
        match &self.actuator {
            Some(a) => S::of(a.push_n) - S::of(a.stiffness_n_per_m) * delta,
            None => S::of(0.0),
        }
    }

    /// Piecewise residual (6N), any scalar type.
    fn piecewise_residual<S: Scalar>(&self, x: &[S]) -> Result<Vec<S>, ReferenceError> {
        let n = x.len() / 6;
        let h = self.length_m / n as f64;
        let strains: Vec<[S; 6]> = (0..n)
            .map(|i| core::array::from_fn(|j| x[6 * i + j]))
            .collect();
        let force = self.push(self.extension(&strains, h));
        // Poses at segment starts and midpoints, and the tip.
        let mut g = Pose::<S>::identity();
        let mut mids = Vec::with_capacity(n);
        for xi in &strains {
            let w = [xi[0], xi[1], xi[2]];
            let nu = [xi[3], xi[4], xi[5]];
            mids.push(g.compose(&exp_map(w, nu, S::of(h / 2.0))));
            g = g.compose(&exp_map(w, nu, S::of(h)));
        }
        let tip = g.p;
        let f = [
            S::of(self.tip_force_n[0]),
            S::of(self.tip_force_n[1]),
            S::of(self.tip_force_n[2]),
        ];
        let m0 = [
            S::of(self.tip_moment_nm[0]),
            S::of(self.tip_moment_nm[1]),
            S::of(self.tip_moment_nm[2]),
        ];
        let mut out = Vec::with_capacity(6 * n);
        for (xi, mid) in strains.iter().zip(&mids) {
            let arm = [tip[0] - mid.p[0], tip[1] - mid.p[1], tip[2] - mid.p[2]];
            let am = cross(arm, f);
            let m = mid.rotate_back([m0[0] + am[0], m0[1] + am[1], m0[2] + am[2]]);
            let fb = mid.rotate_back(f);
            let ext = [m[0], m[1], m[2], fb[0], fb[1], fb[2]];
            out.extend_from_slice(&self.balance(xi, force, ext)?);
        }
        Ok(out)
    }

    /// Constant-strain residual and its analytic Jacobian.
    pub fn constant_residual_jacobian(
        &self,
        xi: &Strain,
    ) -> Result<([f64; 6], [[f64; 6]; 6]), ReferenceError> {
        let delta = self.extension(&[*xi], self.length_m);
        let force = self.push(delta);
        let f = self.balance(xi, force, {
            let m = self.tip_moment_nm;
            [m[0], m[1], m[2], 0.0, 0.0, 0.0]
        })?;
        let mut j = self.stiffness;
        if let Some(a) = &self.actuator {
            let r = self.actuator_offset_m;
            let wr = cross([xi[0], xi[1], xi[2]], r);
            let v = [xi[3] + wr[0], xi[4] + wr[1], xi[5] + wr[2]];
            let len = libm::sqrt(dot(v, v));
            let t = [v[0] / len, v[1] / len, v[2] / len];
            // du/dv for u = F t: F (I − t tᵀ)/|v| + t (dF/dδ · L) tᵀ.
            let dfd = -a.stiffness_n_per_m * self.length_m;
            let mut du = [[0.0; 3]; 3];
            for p in 0..3 {
                for q in 0..3 {
                    let id = if p == q { 1.0 } else { 0.0 };
                    du[p][q] = force * (id - t[p] * t[q]) / len + t[p] * dfd * t[q];
                }
            }
            // dv/dξ = [−[r]×, I].
            let rx = [[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]];
            let mut dv = [[0.0; 6]; 3];
            for p in 0..3 {
                for q in 0..3 {
                    dv[p][q] = -rx[p][q];
                }
                dv[p][3 + p] = 1.0;
            }
            // dW/dξ = [[r]× du; du] dv.
            let mut dudxi = [[0.0; 6]; 3];
            for p in 0..3 {
                for c in 0..6 {
                    dudxi[p][c] = (0..3).map(|q| du[p][q] * dv[q][c]).sum();
                }
            }
            for c in 0..6 {
                for p in 0..3 {
                    let rm: f64 = (0..3).map(|q| rx[p][q] * dudxi[q][c]).sum();
                    j[p][c] -= rm;
                    j[3 + p][c] -= dudxi[p][c];
                }
            }
        }
        Ok((f, j))
    }

    /// Piecewise residual and its exact Jacobian (forward-mode dual numbers, one pass per unknown).
    pub fn piecewise_residual_jacobian(
        &self,
        x: &[f64],
    ) -> Result<(Vec<f64>, DMatrix<f64>), ReferenceError> {
        let n = x.len();
        let f = self.piecewise_residual(x)?;
        let mut jac = DMatrix::zeros(n, n);
        let mut xd: Vec<Dual> = x.iter().map(|&v| Dual::of(v)).collect();
        for c in 0..n {
            xd[c].d = 1.0;
            let r = self.piecewise_residual(&xd)?;
            for (row, v) in r.iter().enumerate() {
                jac[(row, c)] = v.d;
            }
            xd[c].d = 0.0;
        }
        Ok((f, jac))
    }
}

/// Scaled max-norm of a residual, strain units.
fn scaled_norm(f: &[f64], scale: &[f64; 6]) -> f64 {
    f.iter()
        .enumerate()
        .map(|(i, v)| (v / scale[i % 6]).abs())
        .fold(0.0, f64::max)
}

/// Newton's method on `x` for a residual/Jacobian pair; `damped` adds a backtracking line search.
fn newton(
    x0: &[f64],
    scale: &[f64; 6],
    damped: bool,
    mut eval: impl FnMut(&[f64]) -> Result<(Vec<f64>, DMatrix<f64>), ReferenceError>,
) -> Result<(Vec<f64>, usize, f64), ReferenceError> {
    let mut x = x0.to_vec();
    let (mut f, mut j) = eval(&x)?;
    let mut norm = scaled_norm(&f, scale);
    let start = norm.max(1e-300);
    for it in 0..MAX_ITERATIONS {
        if !norm.is_finite() {
            return Err(ReferenceError::NonFinite("Newton residual"));
        }
        if norm < TOLERANCE {
            return Ok((x, it, norm));
        }
        let step = j
            .clone()
            .lu()
            .solve(&DVector::from_column_slice(&f))
            .ok_or(ReferenceError::SingularJacobian { iteration: it })?;
        if step.iter().any(|v| !v.is_finite()) {
            return Err(ReferenceError::SingularJacobian { iteration: it });
        }
        let mut alpha = 1.0;
        loop {
            let trial: Vec<f64> = x
                .iter()
                .zip(step.iter())
                .map(|(a, s)| a - alpha * s)
                .collect();
            match eval(&trial) {
                Ok((tf, tj)) => {
                    let tn = scaled_norm(&tf, scale);
                    if !damped || tn < (1.0 - 1e-4 * alpha) * norm {
                        x = trial;
                        f = tf;
                        j = tj;
                        norm = tn;
                        break;
                    }
                }
                Err(e) if !damped => return Err(e),
                Err(_) => {}
            }
            alpha *= 0.5;
            if alpha < 1.0 / 4096.0 {
                return Err(ReferenceError::NotConverged {
                    iterations: it + 1,
                    residual: norm,
                });
            }
        }
        if !damped && !(norm < 1e8 * start) {
            return Err(ReferenceError::NotConverged {
                iterations: it + 1,
                residual: norm,
            });
        }
    }
    if norm < TOLERANCE {
        return Ok((x, MAX_ITERATIONS, norm));
    }
    Err(ReferenceError::NotConverged {
        iterations: MAX_ITERATIONS,
        residual: norm,
    })
}

/// The constant-strain rod from `guess` (plain Newton, analytic Jacobian).
pub fn solve_constant(rod: &Rod, guess: &Strain, damped: bool) -> Result<Solution, ReferenceError> {
    let scale = rod.scale()?;
    let (x, iterations, residual) = newton(guess, &scale, damped, |x| {
        let xi: Strain = core::array::from_fn(|j| x[j]);
        let (f, j) = rod.constant_residual_jacobian(&xi)?;
        Ok((f.to_vec(), DMatrix::from_fn(6, 6, |r, c| j[r][c])))
    })?;
    Ok(Solution {
        strains: vec![core::array::from_fn(|j| x[j])],
        iterations,
        method: if damped {
            Method::Damped
        } else {
            Method::Newton
        },
        residual,
    })
}

/// The piecewise-constant-strain rod with `guess.len()` segments from `guess`.
pub fn solve_piecewise(
    rod: &Rod,
    guess: &[Strain],
    damped: bool,
) -> Result<Solution, ReferenceError> {
    let scale = rod.scale()?;
    let x0: Vec<f64> = guess.iter().flat_map(|s| s.iter().copied()).collect();
    let (x, iterations, residual) =
        newton(&x0, &scale, damped, |x| rod.piecewise_residual_jacobian(x))?;
    Ok(Solution {
        strains: x
            .chunks(6)
            .map(|c| core::array::from_fn(|j| c[j]))
            .collect(),
        iterations,
        method: if damped {
            Method::Damped
        } else {
            Method::Newton
        },
        residual,
    })
}

/// Checks that a converged equilibrium is stable: every eigenvalue of the scaled tangent
/// stiffness `diag(K)⁻¹ J` must have a positive real part. Newton from a straight guess under a
/// large tip load can converge to a curled-back equilibrium that balances the load exactly but
/// is unstable; this is how it is caught.
pub fn check_stable(rod: &Rod, strains: &[Strain]) -> Result<(), ReferenceError> {
    let scale = rod.scale()?;
    let jac = if strains.len() == 1 && rod.tip_force_n == [0.0; 3] {
        let (_, j) = rod.constant_residual_jacobian(&strains[0])?;
        DMatrix::from_fn(6, 6, |r, c| j[r][c])
    } else {
        let x: Vec<f64> = strains.iter().flat_map(|s| s.iter().copied()).collect();
        rod.piecewise_residual_jacobian(&x)?.1
    };
    let n = jac.nrows();
    let scaled = DMatrix::from_fn(n, n, |r, c| jac[(r, c)] / scale[r % 6]);
    let schur = scaled
        .try_schur(1e-13, 10_000)
        .ok_or(ReferenceError::NonFinite("tangent-stiffness eigenvalues"))?;
    let min = schur
        .complex_eigenvalues()
        .iter()
        .map(|z| z.re)
        .fold(f64::INFINITY, f64::min);
    if min > 0.0 {
        Ok(())
    } else {
        Err(ReferenceError::UnstableEquilibrium {
            min_eigenvalue: min,
        })
    }
}

/// Solves with `segments` segments (1: constant strain with the analytic Jacobian) from `guess`,
/// falling back to damped Newton and then to continuation in the load factor (4, 16, 64 steps).
/// Under a dead tip force every answer is checked with [`check_stable`]. Returns the first error only if every method
/// fails.
pub fn solve_robust(
    rod: &Rod,
    segments: usize,
    guess: &Strain,
) -> Result<Solution, ReferenceError> {
    let seg = segments.max(1);
    let solve = |r: &Rod, g: &[Strain], damped: bool| {
        if seg == 1 && r.tip_force_n == [0.0; 3] {
            solve_constant(r, &g[0], damped)
        } else {
            solve_piecewise(r, g, damped)
        }
    };
    // The static stability test is meaningful for a conservative load: a dead tip force.
    // End moments and the actuator's push turn with the body and are judged by convergence.
    let needs_check = rod.tip_force_n != [0.0; 3];
    let checked = |s: Result<Solution, ReferenceError>| {
        s.and_then(|s| {
            if needs_check {
                check_stable(rod, &s.strains)?;
            }
            Ok(s)
        })
    };
    let guess_all = vec![*guess; seg];
    let first = match checked(solve(rod, &guess_all, false)) {
        Ok(s) => return Ok(s),
        Err(e) => e,
    };
    if let Ok(s) = checked(solve(rod, &guess_all, true)) {
        return Ok(s);
    }
    for steps in [4usize, 16, 64] {
        let mut current = vec![REFERENCE_STRAIN; seg];
        let mut total = 0;
        let mut ok = true;
        for k in 1..=steps {
            match solve(&rod.scaled(k as f64 / steps as f64), &current, true) {
                Ok(s) => {
                    total += s.iterations;
                    current = s.strains;
                }
                Err(_) => {
                    ok = false;
                    break;
                }
            }
        }
        if ok {
            let s = checked(solve(rod, &current, true))?;
            return Ok(Solution {
                strains: s.strains,
                iterations: total + s.iterations,
                method: Method::Continuation(steps),
                residual: s.residual,
            });
        }
    }
    Err(first)
}

/// Position along the rod at `s_m` for the solved strains (segments of equal length), m.
pub fn position_m(strains: &[Strain], length_m: f64, s_m: f64) -> V3<f64> {
    let h = length_m / strains.len() as f64;
    let mut g = Pose::<f64>::identity();
    let mut left = s_m;
    for xi in strains {
        let step = left.min(h);
        g = g.compose(&exp_map([xi[0], xi[1], xi[2]], [xi[3], xi[4], xi[5]], step));
        left -= step;
        if left <= 0.0 {
            break;
        }
    }
    g.p
}

/// Radius of the circle through the base, middle and tip, m — how the paper measured it (three
/// wire markers). Coincident markers (κL a multiple of 2π) are [`ReferenceError::MarkersDegenerate`];
/// collinear ones on a straight rod are [`ReferenceError::Straight`].
pub fn marker_radius_m(strains: &[Strain], length_m: f64) -> Result<f64, ReferenceError> {
    let p0 = [0.0; 3];
    let pm = position_m(strains, length_m, length_m / 2.0);
    let pl = position_m(strains, length_m, length_m);
    let sub = |a: V3<f64>, b: V3<f64>| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let (a, b, c) = (sub(pm, p0), sub(pl, p0), sub(pl, pm));
    let n = |v: V3<f64>| libm::sqrt(dot(v, v));
    let tiny = 1e-9 * length_m;
    if n(a) < tiny || n(b) < tiny || n(c) < tiny {
        return Err(ReferenceError::MarkersDegenerate);
    }
    let area2 = n(cross(a, b));
    if !(area2 > 1e-12 * n(a) * n(b)) {
        let bent = strains
            .iter()
            .any(|x| x[0] != 0.0 || x[1] != 0.0 || x[2] != 0.0);
        return Err(if bent {
            ReferenceError::MarkersDegenerate
        } else {
            ReferenceError::Straight
        });
    }
    Ok(n(a) * n(b) * n(c) / (2.0 * area2))
}

/// Radius of curvature of a constant strain's centreline, `|ν|³ / |ν × (ω × ν)|`, m.
pub fn strain_radius_m(xi: &Strain) -> Result<f64, ReferenceError> {
    let w = [xi[0], xi[1], xi[2]];
    let nu = [xi[3], xi[4], xi[5]];
    let k = cross(nu, cross(w, nu));
    let den = libm::sqrt(dot(k, k));
    if !(den > 0.0) {
        return Err(ReferenceError::Straight);
    }
    let l = libm::sqrt(dot(nu, nu));
    Ok(l * l * l / den)
}

/// Radius, m: from the markers, falling back to the strain of the middle segment when the
/// markers coincide (bending of 2π or more).
pub fn radius_m(strains: &[Strain], length_m: f64) -> Result<f64, ReferenceError> {
    match marker_radius_m(strains, length_m) {
        Err(ReferenceError::MarkersDegenerate) => strain_radius_m(&strains[strains.len() / 2]),
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mechanics;

    fn beam(ei: f64, l: f64) -> Rod {
        let stiff = 1e6 * ei / (l * l);
        let mut k = [[0.0; 6]; 6];
        for (j, v) in [ei, ei, ei, stiff, stiff, stiff].iter().enumerate() {
            k[j][j] = *v;
        }
        Rod {
            length_m: l,
            stiffness: k,
            actuator_offset_m: [0.0; 3],
            actuator: None,
            tip_force_n: [0.0; 3],
            tip_moment_nm: [0.0; 3],
        }
    }

    fn link_rod(temp_c: f64) -> Rod {
        let p = LinkParams::DEFAULT;
        Rod::of_link(
            &p,
            super::super::tca_physics::TcaLaw::Linear(p.mechanics).at(temp_c),
            None,
        )
    }

    #[test]
    fn analytic_jacobian_equals_the_dual_number_one() {
        let mut rod = link_rod(80.0);
        rod.stiffness = link_stiffness(&LinkParams::DEFAULT, Some(64.0));
        let xi = [0.5, 20.0, -0.3, 0.01, -0.02, 1.03];
        let (f, j) = rod.constant_residual_jacobian(&xi).unwrap();
        let (f2, j2) = rod.piecewise_residual_jacobian(&xi).unwrap();
        for r in 0..6 {
            assert!((f[r] - f2[r]).abs() < 1e-12 * (1.0 + f[r].abs()));
            for c in 0..6 {
                let s = j[r][c].abs().max(1e-9);
                assert!(
                    (j[r][c] - j2[(r, c)]).abs() < 1e-9 * s,
                    "J[{r}][{c}] {} vs {}",
                    j[r][c],
                    j2[(r, c)]
                );
            }
        }
    }

    #[test]
    fn planar_link_solution_matches_the_lumped_balance_when_stretch_is_stiff() {
        // With EA and GA made huge the full model reduces to EI κ = r F(r L κ).
        let p = LinkParams::DEFAULT;
        let t = 75.0;
        let mut rod = link_rod(t);
        for j in 3..6 {
            rod.stiffness[j][j] *= 1e6;
        }
        let s = solve_constant(&rod, &REFERENCE_STRAIN, false).unwrap();
        let kappa = s.strains[0][1];
        let lumped = mechanics::curvature_per_m(&p, t);
        assert!(
            (kappa - lumped).abs() < 1e-5 * lumped,
            "{kappa} vs {lumped}"
        );
        assert!(s.iterations <= 5, "{}", s.iterations);
    }

    #[test]
    fn pure_end_moment_gives_an_exact_arc_even_beyond_two_pi() {
        let (ei, l) = (1.5e-5, 0.05);
        for kl in [0.3, 3.0, 7.5, 4.0 * core::f64::consts::PI] {
            let mut rod = beam(ei, l);
            rod.tip_moment_nm = [0.0, ei * kl / l, 0.0];
            for n in [1usize, 3] {
                let s = solve_robust(&rod, n, &REFERENCE_STRAIN)
                    .unwrap_or_else(|e| panic!("κL={kl} n={n}: {e}"));
                for xi in &s.strains {
                    assert!(
                        (xi[1] - kl / l).abs() < 1e-8 * kl / l,
                        "κL={kl} n={n}: {xi:?}"
                    );
                }
                let r = radius_m(&s.strains, l).unwrap();
                assert!((r - l / kl).abs() < 1e-7 * l / kl, "κL={kl}: radius {r}");
            }
        }
    }

    #[test]
    fn coincident_markers_are_reported_and_the_radius_falls_back_to_the_strain() {
        let l = 0.05;
        let xi = [0.0, 2.0 * core::f64::consts::PI / l, 0.0, 0.0, 0.0, 1.0];
        assert_eq!(
            marker_radius_m(&[xi], l),
            Err(ReferenceError::MarkersDegenerate)
        );
        let r = radius_m(&[xi], l).unwrap();
        assert!((r - l / (2.0 * core::f64::consts::PI)).abs() < 1e-12);
        assert_eq!(
            radius_m(&[REFERENCE_STRAIN], l),
            Err(ReferenceError::Straight)
        );
    }

    /// Cantilever under a perpendicular dead tip load: for tip angle φ_L the load is
    /// `PL²/EI = I²` with `I = √2 ∫₀^√sinφ_L dw / cos φ(w)`, `sin φ = sin φ_L − w²`, and the
    /// transverse deflection is `y_L/L = √2 ∫ tan φ dw / I`. Returns (α, y_L/L).
    fn elastica(phi_l: f64) -> (f64, f64) {
        let sl = libm::sin(phi_l);
        let top = libm::sqrt(sl);
        let n = 4000;
        let (mut i1, mut i2) = (0.0, 0.0);
        // Gauss–Legendre 2-point on each of n panels.
        let g = 0.5 / libm::sqrt(3.0);
        for k in 0..n {
            let h = top / n as f64;
            for off in [0.5 - g, 0.5 + g] {
                let w = (k as f64 + off) * h;
                let s = sl - w * w;
                let c = libm::sqrt(1.0 - s * s);
                i1 += 0.5 * h / c;
                i2 += 0.5 * h * s / c;
            }
        }
        let i = libm::sqrt(2.0) * i1;
        (i * i, libm::sqrt(2.0) * i2 / i)
    }

    fn tip_load_rod(alpha: f64) -> Rod {
        let (ei, l) = (1.5e-5, 0.05);
        let mut rod = beam(ei, l);
        rod.tip_force_n = [alpha * ei / (l * l), 0.0, 0.0];
        rod
    }

    #[test]
    fn piecewise_cantilever_converges_to_the_elastica_at_second_order() {
        let phi_l = 1.0; // 57° tip rotation
        let (alpha, y_over_l) = elastica(phi_l);
        let rod = tip_load_rod(alpha);
        let mut errs = Vec::new();
        for n in [2usize, 4, 8] {
            let s = solve_robust(&rod, n, &REFERENCE_STRAIN).unwrap();
            let y = position_m(&s.strains, rod.length_m, rod.length_m)[0] / rod.length_m;
            errs.push((y - y_over_l).abs());
        }
        let p1 = libm::log2(errs[0] / errs[1]);
        let p2 = libm::log2(errs[1] / errs[2]);
        assert!(errs[2] < 2e-3, "{errs:?}");
        assert!(p1 > 1.6 && p2 > 1.6, "orders {p1} {p2} {errs:?}");
    }

    #[test]
    fn small_tip_load_matches_linear_theory() {
        let alpha = 1e-4;
        let rod = tip_load_rod(alpha);
        let s = solve_robust(&rod, 16, &REFERENCE_STRAIN).unwrap();
        let y = position_m(&s.strains, rod.length_m, rod.length_m)[0] / rod.length_m;
        let linear = alpha / 3.0;
        assert!((y - linear).abs() < 2e-3 * linear, "{y} vs {linear}");
    }

    #[test]
    fn all_zero_initial_guess_is_reported_and_robust_solver_recovers() {
        let rod = link_rod(90.0);
        let zero = [0.0; 6];
        assert_eq!(
            solve_constant(&rod, &zero, false),
            Err(ReferenceError::DegenerateActuatorPath)
        );
        let s = solve_robust(&rod, 1, &zero).unwrap();
        assert!(
            matches!(s.method, Method::Continuation(_)),
            "{:?}",
            s.method
        );
        let direct = solve_constant(&rod, &REFERENCE_STRAIN, false).unwrap();
        assert!((s.strains[0][1] - direct.strains[0][1]).abs() < 1e-9);
    }

    #[test]
    fn link_newton_from_straight_converges_fast_and_matches_continuation_in_power() {
        // The link's own problem is nearly linear: plain Newton from the straight rod converges
        // in a few iterations at every power, and continuation reaches the same answer.
        let p = LinkParams::DEFAULT;
        let law = super::super::tca_physics::TcaLaw::Linear(p.mechanics);
        for temp_c in [30.0, 60.0, 90.0, 120.0] {
            let rod = Rod::of_link(&p, law.at(temp_c), None);
            let plain = solve_constant(&rod, &REFERENCE_STRAIN, false).unwrap();
            assert!(
                plain.iterations <= 6,
                "{temp_c} °C: {} iterations",
                plain.iterations
            );
            let mut current = REFERENCE_STRAIN;
            for k in 1..=8 {
                current = solve_constant(&rod.scaled(k as f64 / 8.0), &current, false)
                    .unwrap()
                    .strains[0];
            }
            for j in 0..6 {
                assert!((current[j] - plain.strains[0][j]).abs() < 1e-9 * (1.0 + current[j].abs()));
            }
        }
    }

    #[test]
    fn link_driven_beyond_two_pi_is_solved_and_its_radius_is_consistent() {
        // A push far above the TCA's range curls the link past a full turn (κL ≈ 9 rad): the
        // exponential map has no trouble, and the marker radius equals the strain radius.
        let p = LinkParams::DEFAULT;
        let f = ForceAtTemp {
            push_n: 4.0,
            stiffness_n_per_m: 19.4,
        };
        let rod = Rod::of_link(&p, f, None);
        let s = solve_robust(&rod, 1, &REFERENCE_STRAIN).unwrap();
        let kl = s.strains[0][1] * rod.length_m;
        assert!(kl > 2.0 * core::f64::consts::PI, "κL = {kl}");
        let by_markers = marker_radius_m(&s.strains, rod.length_m).unwrap();
        let by_strain = strain_radius_m(&s.strains[0]).unwrap();
        assert!(
            (by_markers - by_strain).abs() < 1e-9 * by_strain,
            "{by_markers} vs {by_strain}"
        );
    }

    #[test]
    fn zero_stiffness_is_an_error_not_a_nan() {
        let mut rod = beam(1.5e-5, 0.05);
        rod.stiffness[1][1] = 0.0;
        rod.tip_moment_nm = [0.0, 1e-4, 0.0];
        let r = solve_constant(&rod, &REFERENCE_STRAIN, false);
        assert!(
            matches!(r, Err(ReferenceError::NotPositiveDefinite { row: 1 })),
            "{r:?}"
        );
    }

    #[test]
    fn large_tip_load_defeats_plain_newton_and_the_fallbacks_recover() {
        let (alpha, y_over_l) = elastica(1.45); // 83° tip rotation
        let rod = tip_load_rod(alpha);
        let guess = vec![REFERENCE_STRAIN; 8];
        // Plain Newton from straight converges — to a curled-back equilibrium that balances
        // the load but is unstable and far from the elastica. The stability check catches it.
        let plain = solve_piecewise(&rod, &guess, false).unwrap();
        let y_plain = position_m(&plain.strains, rod.length_m, rod.length_m)[0] / rod.length_m;
        assert!((y_plain - y_over_l).abs() > 0.1, "{y_plain} vs {y_over_l}");
        assert!(matches!(
            check_stable(&rod, &plain.strains),
            Err(ReferenceError::UnstableEquilibrium { .. })
        ));
        let s = solve_robust(&rod, 8, &REFERENCE_STRAIN).unwrap();
        assert_ne!(s.method, Method::Newton);
        check_stable(&rod, &s.strains).unwrap();
        let y = position_m(&s.strains, rod.length_m, rod.length_m)[0] / rod.length_m;
        assert!((y - y_over_l).abs() < 2e-2, "{y} vs {y_over_l}");
    }

    #[test]
    fn stiffness_spanning_a_thousandfold_still_converges_to_the_right_answer() {
        // Cold PLA (≈ 1700× the soft link's EI) against soft PLA; both must meet the planar
        // balance with the same K, and the scaled tolerance must be reached.
        let p = LinkParams::DEFAULT;
        for pla_c in [25.0, 90.0] {
            let t = 80.0;
            let f = super::super::tca_physics::TcaLaw::Linear(p.mechanics).at(t);
            let rod = Rod::of_link(&p, f, Some(pla_c));
            let spread = rod.stiffness[1][1] / p.mechanics.bending_stiffness_nm2;
            let s = solve_robust(&rod, 1, &REFERENCE_STRAIN).unwrap();
            assert!(s.residual < TOLERANCE);
            let xi = s.strains[0];
            // Check the balance independently: moment about y and axial force.
            let v = xi[5] + p.geometry.tca_offset_m * xi[1];
            let force = f.force_n((v - 1.0) * p.geometry.length_m);
            let k = &rod.stiffness;
            let m = k[1][1] * xi[1] + k[1][5] * (xi[5] - 1.0);
            assert!(
                (m - p.geometry.tca_offset_m * force).abs() < 1e-9 * (1.0 + m.abs()),
                "PLA {pla_c} °C spread {spread}: {m} vs {}",
                p.geometry.tca_offset_m * force
            );
            if pla_c < 30.0 {
                assert!(spread > 1000.0, "spread {spread}");
            }
        }
    }
}

//! Reference models of the link (host only, feature `reference`): the paper's full model next to
//! the lumped one, to measure what each level of model buys.
//!
//! * [`fv_thermal`]: 2-D finite-volume heat conduction on the cross-section (paper Eq. 1–3),
//!   steady and transient, three materials, convective rim.
//! * [`cosserat`]: the constant-strain Cosserat rod (Eq. 4–9, all six strains, exponential map,
//!   wrench balance with the actuator offset) by Newton with an exact Jacobian, and the
//!   piecewise-constant-strain rod with N segments.
//! * [`se3`]: the exponential map with its series below a threshold; [`scalar`]: the number
//!   types it runs in (f32, f64, dual numbers for exact Jacobians).
//! * [`tca_physics`]: the physics-based TCA force law (fibre untwisting from thermal expansion,
//!   coil as a helical spring) beside the linear law of the lumped model.
//! * [`levels`]: the model levels from lumped to finest, their radius curves, errors and cost,
//!   and the rule that picks the cheapest level meeting a tolerance.
//!
//! Every numerical failure is a [`ReferenceError`]; the solvers that have a fallback say which
//! method produced the answer.

pub mod cosserat;
pub mod fv_thermal;
pub mod levels;
pub mod scalar;
pub mod se3;
pub mod tca_physics;

use core::fmt;

/// A numerical failure of a reference model, with what is needed to understand it.
#[derive(Clone, Debug, PartialEq)]
pub enum ReferenceError {
    /// A grid too coarse to hold the geometry (fewer than 2 rings or 4 sectors, or a heater that
    /// covers no cell).
    BadGrid {
        /// Rings.
        nr: usize,
        /// Sectors.
        nt: usize,
    },
    /// A time step that is not a positive finite number, s.
    BadStep {
        /// The step, s.
        dt_s: f64,
    },
    /// A linear system that is singular or not positive definite (Cholesky pivot at `row`).
    NotPositiveDefinite {
        /// Row of the failing pivot.
        row: usize,
    },
    /// An explicit step above the stability limit `2/λmax`.
    UnstableStep {
        /// Requested step, s.
        dt_s: f64,
        /// Stability limit, s.
        limit_s: f64,
    },
    /// Explicit time stepping blew up (stored heat above the heat put in).
    Diverged {
        /// Step at which it was detected.
        step: usize,
    },
    /// A value that should be finite is not.
    NonFinite(&'static str),
    /// The actuator's path has zero length (e.g. Newton started from the all-zero strain),
    /// so its direction is undefined.
    DegenerateActuatorPath,
    /// Newton's Jacobian is singular.
    SingularJacobian {
        /// Newton iteration.
        iteration: usize,
    },
    /// Newton did not converge.
    NotConverged {
        /// Iterations taken.
        iterations: usize,
        /// Scaled residual at the end (strain units).
        residual: f64,
    },
    /// Newton converged to an equilibrium that is not stable (the scaled tangent stiffness has
    /// an eigenvalue with negative real part): a real but wrong answer for a loaded rod.
    UnstableEquilibrium {
        /// Smallest real part of the eigenvalues of `diag(K)⁻¹ J`.
        min_eigenvalue: f64,
    },
    /// The three markers (base, middle, tip) are coincident or collinear: no circle through them.
    MarkersDegenerate,
    /// Curvature is zero: the radius is infinite.
    Straight,
    /// A model level that does not exist (unknown name or impossible parameters).
    UnknownLevel(String),
}

impl fmt::Display for ReferenceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use ReferenceError::*;
        match self {
            BadGrid { nr, nt } => write!(f, "grid {nr}x{nt} cannot resolve the cross-section"),
            BadStep { dt_s } => write!(f, "time step {dt_s} s is not positive and finite"),
            NotPositiveDefinite { row } => {
                write!(
                    f,
                    "system is singular or not positive definite (pivot {row})"
                )
            }
            UnstableStep { dt_s, limit_s } => write!(
                f,
                "explicit step {dt_s:.4e} s exceeds the stability limit {limit_s:.4e} s"
            ),
            Diverged { step } => write!(f, "explicit stepping diverged at step {step}"),
            NonFinite(what) => write!(f, "non-finite value in {what}"),
            DegenerateActuatorPath => write!(f, "actuator path has zero length"),
            SingularJacobian { iteration } => {
                write!(f, "singular Jacobian at Newton iteration {iteration}")
            }
            NotConverged {
                iterations,
                residual,
            } => write!(
                f,
                "Newton did not converge in {iterations} iterations (residual {residual:.3e})"
            ),
            UnstableEquilibrium { min_eigenvalue } => write!(
                f,
                "converged to an unstable equilibrium (eigenvalue {min_eigenvalue:.3e})"
            ),
            MarkersDegenerate => write!(f, "markers coincide or are collinear"),
            Straight => write!(f, "zero curvature: radius is infinite"),
            UnknownLevel(s) => write!(f, "unknown model level {s}"),
        }
    }
}

impl std::error::Error for ReferenceError {}

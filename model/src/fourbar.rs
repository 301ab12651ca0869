//! The paper's application (Sec. IV): a four-bar linkage whose coupler is the morphing link, and
//! the path of a foot fixed to it, for a locked radius.
//!
//! Frames and units (see `docs/fourbar.md`): SI lengths (m) inside, the ground frame has the crank
//! pivot `O2` at the origin and the rocker pivot `O4` at `(ground_m, 0)`, `y` up; the crank angle
//! is measured from `O2→O4`, counter-clockwise positive, and the crank turns counter-clockwise.
//! The coupler is the locked link: a constant-curvature arc of the link's length `L` from the
//! crank pin `A` to the rocker pin `B`, so its chord is `2R sin(L/2R)` (`L` when straight) and it
//! meets the chord at `L/2R` at each end. It bulges to the right of `A→B`. The foot is the point
//! of the link at arc length `foot_at · L` from `A`, moved `foot_offset_m` along the link's
//! normal on the bulge side. The link is locked while the linkage runs: no rod solver here.
//!
//! Where the method fails, each a [`FourBarError`]: a geometry that cannot assemble over a whole
//! revolution ([`FourBarError::CannotAssemble`], with the crank angles where it cannot), a
//! revolution that passes a toggle, where the coupler and the rocker are collinear and the
//! position solution is singular ([`FourBarError::Toggle`], judged by [`MIN_SIN_TRANSMISSION`]),
//! and a sweep whose next position lies nearer the other assembly mode than its own
//! ([`FourBarError::BranchFlip`]: the branch could not be followed at that resolution).

use crate::params::LinkParams;
use core::fmt;
use libm::{cos, sin, sqrt};

/// The default geometry's ground link (pivot to pivot), m. With the crank 15 mm, the rocker
/// 40 mm and the coupler's chord 45.3–50 mm over the reachable radii and the straight link, it
/// is a crank-rocker: the crank is the shortest link and `s + l = 65 mm ≤ p + q ≥ 85.3 mm`, so
/// every reachable radius leaves 20 mm of Grashof margin (tested).
pub const DEFAULT_GROUND_M: f64 = 0.050;
/// The default crank, m: the shortest link, so it turns fully (a 30 mm stroke for a small motor).
pub const DEFAULT_CRANK_M: f64 = 0.015;
/// The default rocker, m: keeps the transmission angle within 44–99° over the reachable radii
/// (the usual design rule asks for 40–140°), far from either toggle.
pub const DEFAULT_ROCKER_M: f64 = 0.040;
/// Where the default foot sits along the link, as a fraction of its length from the crank pin:
/// the middle, where the bend moves it most (by the sagitta `R(1 − cos(L/2R))`).
pub const DEFAULT_FOOT_AT: f64 = 0.5;
/// The default foot's offset from the link along its normal (bulge side), m: on the link itself.
pub const DEFAULT_FOOT_OFFSET_M: f64 = 0.0;
/// Points per revolution of a foot path: one per degree of crank.
pub const DEFAULT_STEPS: usize = 360;

/// Smallest `sin` of the transmission angle (between the coupler and the rocker) a revolution may
/// reach. At a toggle it is zero and the two assembly modes meet; near it the pin `B` moves by
/// about `δ / sin μ` for a length error `δ`, so below 1e-3 a micrometre of error in a link moves
/// the joint by a millimetre and the computed path says nothing about the real linkage.
pub const MIN_SIN_TRANSMISSION: f64 = 1e-3;

/// The assembly mode: on which side of the directed line from the crank pin `A` to the rocker
/// pivot `O4` the rocker pin `B` lies. The other side is the other mode of the same linkage.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Branch {
    /// `B` right of `A→O4` (below the ground line while the crank is near it): the legs hang.
    Right,
    /// `B` left of `A→O4`.
    Left,
}

impl Branch {
    fn sign(self) -> f64 {
        match self {
            Branch::Right => -1.0,
            Branch::Left => 1.0,
        }
    }
}

/// The rigid links, the foot and the assembly mode (the `[fourbar]` section of `link.toml`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FourBarGeometry {
    /// Ground link, crank pivot `O2` to rocker pivot `O4`, m.
    pub ground_m: f64,
    /// Crank, `O2` to the crank pin `A`, m.
    pub crank_m: f64,
    /// Rocker, `O4` to the rocker pin `B`, m.
    pub rocker_m: f64,
    /// Foot position along the morphing link from `A`, fraction of its length (0..=1).
    pub foot_at: f64,
    /// Foot offset from the link along its normal towards the bulge side, m.
    pub foot_offset_m: f64,
    /// Assembly mode, kept over the whole revolution.
    pub branch: Branch,
}

impl FourBarGeometry {
    /// The documented default: a crank-rocker for every reachable radius and the straight link.
    pub const DEFAULT: FourBarGeometry = FourBarGeometry {
        ground_m: DEFAULT_GROUND_M,
        crank_m: DEFAULT_CRANK_M,
        rocker_m: DEFAULT_ROCKER_M,
        foot_at: DEFAULT_FOOT_AT,
        foot_offset_m: DEFAULT_FOOT_OFFSET_M,
        branch: Branch::Right,
    };
}

impl Default for FourBarGeometry {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why a four-bar has no foot path, with what is needed to understand it.
#[derive(Clone, Debug, PartialEq)]
pub enum FourBarError {
    /// A radius that is not positive, or not finite where a finite one is needed.
    BadRadius {
        /// The radius, mm.
        radius_mm: f64,
    },
    /// The pins cannot be joined at some crank angles: the distance `A–O4` leaves the range
    /// `|rocker − chord|..rocker + chord` there.
    CannotAssemble {
        /// The coupler's chord, mm.
        chord_mm: f64,
        /// First and last crank angle that cannot assemble, degrees (counter-clockwise).
        crank_deg: (f64, f64),
    },
    /// The revolution passes within [`MIN_SIN_TRANSMISSION`] of a toggle (coupler and rocker
    /// collinear): the position solution is singular there and the branch undecidable.
    Toggle {
        /// The coupler's chord, mm.
        chord_mm: f64,
        /// Crank angle of the worst position, degrees.
        crank_deg: f64,
        /// `sin` of the transmission angle there.
        sin_transmission: f64,
    },
    /// Between two steps of the sweep the position moved nearer the other assembly mode than
    /// its own: the sweep is too coarse to follow the branch near a toggle.
    BranchFlip {
        /// Crank angle of the step, degrees.
        crank_deg: f64,
        /// Steps per revolution.
        steps: usize,
    },
    /// Fewer than 3 steps per revolution.
    TooFewSteps {
        /// The steps asked for.
        steps: usize,
    },
}

impl fmt::Display for FourBarError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FourBarError::BadRadius { radius_mm } => {
                write!(f, "the radius must be a positive number of mm, got {radius_mm}")
            }
            FourBarError::CannotAssemble { chord_mm, crank_deg: (lo, hi) } => write!(
                f,
                "the four-bar cannot assemble over a full revolution: with a {chord_mm:.2} mm chord the \
                 rocker and the morphing link cannot meet for crank angles {lo:.1}..{hi:.1} deg; \
                 change fourbar.ground_m, crank_m or rocker_m (see docs/fourbar.md)"
            ),
            FourBarError::Toggle { chord_mm, crank_deg, sin_transmission } => write!(
                f,
                "the four-bar passes a toggle at crank {crank_deg:.1} deg with a {chord_mm:.2} mm chord \
                 (sin of the transmission angle {sin_transmission:.1e} < {MIN_SIN_TRANSMISSION:.0e}): \
                 the position is singular there and the branch undecidable; change the fourbar \
                 lengths (see docs/fourbar.md)"
            ),
            FourBarError::BranchFlip { crank_deg, steps } => write!(
                f,
                "the sweep of {steps} steps lost its assembly mode at crank {crank_deg:.1} deg (the next \
                 position is nearer the other mode); use more steps or a geometry farther from a toggle"
            ),
            FourBarError::TooFewSteps { steps } => {
                write!(f, "a revolution needs at least 3 steps, got {steps}")
            }
        }
    }
}

impl std::error::Error for FourBarError {}

/// `sin(z)/z`, 1 at 0.
fn sinc(z: f64) -> f64 {
    if z.abs() < 1e-4 {
        1.0 - z * z / 6.0
    } else {
        sin(z) / z
    }
}

/// Curvature of a radius in mm, 1/m: `None` is the straight link.
pub fn curvature_per_m(radius_mm: Option<f64>) -> Result<f64, FourBarError> {
    match radius_mm {
        None => Ok(0.0),
        Some(r) if r > 0.0 && r.is_finite() => Ok(1e3 / r),
        Some(r) if r == f64::INFINITY => Ok(0.0),
        Some(r) => Err(FourBarError::BadRadius { radius_mm: r }),
    }
}

/// Chord of an arc of length `length_m` and curvature `kappa_per_m`, m: `2R sin(L/2R)`, `L` when
/// straight.
pub fn chord_m(length_m: f64, kappa_per_m: f64) -> f64 {
    length_m * sinc(kappa_per_m * length_m / 2.0)
}

/// Angle between the arc's end tangent and its chord, rad: `L/2R` (zero when straight). At the
/// crank pin the tangent turns towards the bulge side, at the rocker pin away from it.
pub fn end_angle_rad(length_m: f64, kappa_per_m: f64) -> f64 {
    kappa_per_m * length_m / 2.0
}

/// A point on the arc at arc length `s_m` from its start, and its unit normal towards the bulge,
/// in the chord frame (x along the chord from the start, y towards the bulge), m.
pub fn arc_point(length_m: f64, kappa_per_m: f64, s_m: f64) -> ([f64; 2], [f64; 2]) {
    let k = kappa_per_m;
    let t = k * (s_m - length_m / 2.0);
    let x = chord_m(length_m, k) / 2.0 + (s_m - length_m / 2.0) * sinc(t);
    // R (cos t − cos φ) written without the cancellation: 2R sin(ks/2) sin(k(L−s)/2).
    let y =
        k * s_m * (length_m - s_m) / 2.0 * sinc(k * s_m / 2.0) * sinc(k * (length_m - s_m) / 2.0);
    ([x, y], [sin(t), cos(t)])
}

/// The linkage with the morphing link locked at one curvature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FourBar {
    /// The rigid links, foot and branch.
    pub geometry: FourBarGeometry,
    /// The morphing link's length, m.
    pub length_m: f64,
    /// Its locked curvature, 1/m (0: straight).
    pub kappa_per_m: f64,
}

/// The linkage at one crank angle, ground frame, m.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Crank angle, degrees.
    pub crank_deg: f64,
    /// Crank pin `A`.
    pub a: [f64; 2],
    /// Rocker pin `B`.
    pub b: [f64; 2],
    /// The foot.
    pub foot: [f64; 2],
    /// `sin` of the transmission angle (coupler chord to rocker), positive.
    pub sin_transmission: f64,
}

/// One foot path sample in mm, as `morph-model fourbar --json` prints it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathPoint {
    /// Crank angle, degrees.
    pub crank_deg: f64,
    /// Foot x, mm.
    pub foot_x_mm: f64,
    /// Foot y, mm.
    pub foot_y_mm: f64,
}

/// A foot path property the inverse can ask for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Property {
    /// The path's lowest y, mm.
    Lowest,
    /// Its horizontal extent, mm.
    Stride,
    /// Its vertical extent, mm.
    Height,
}

impl Property {
    /// Every property, in the order the CLI lists them.
    pub const ALL: [Property; 3] = [Property::Lowest, Property::Stride, Property::Height];

    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Property::Lowest => "lowest_mm",
            Property::Stride => "stride_mm",
            Property::Height => "height_mm",
        }
    }

    /// The property named `name`.
    pub fn parse(name: &str) -> Option<Property> {
        Property::ALL.into_iter().find(|p| p.name() == name)
    }
}

/// Extremes of a foot path, mm, refined between samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathStats {
    /// Smallest x.
    pub min_x_mm: f64,
    /// Largest x.
    pub max_x_mm: f64,
    /// Smallest y (the lowest point).
    pub min_y_mm: f64,
    /// Largest y.
    pub max_y_mm: f64,
    /// Crank angle of the lowest point, degrees.
    pub lowest_crank_deg: f64,
    /// Smallest `sin` of the transmission angle over the revolution.
    pub min_sin_transmission: f64,
}

impl PathStats {
    /// The value of `prop`, mm.
    pub fn get(&self, prop: Property) -> f64 {
        match prop {
            Property::Lowest => self.min_y_mm,
            Property::Stride => self.max_x_mm - self.min_x_mm,
            Property::Height => self.max_y_mm - self.min_y_mm,
        }
    }
}

/// One closed-form position: the crank pin, the rocker pin on this branch and on the other,
/// `sin` of the transmission angle.
struct Solved {
    a: [f64; 2],
    b: [f64; 2],
    other_b: [f64; 2],
    sin_mu: f64,
}

fn dist(p: [f64; 2], q: [f64; 2]) -> f64 {
    sqrt((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]))
}

impl FourBar {
    /// The linkage of `geometry` with a link of `length_m` locked at `radius_mm` (`None`:
    /// straight), checked over a whole revolution: it must assemble everywhere and stay
    /// [`MIN_SIN_TRANSMISSION`] away from a toggle.
    pub fn new(
        geometry: FourBarGeometry,
        length_m: f64,
        radius_mm: Option<f64>,
    ) -> Result<FourBar, FourBarError> {
        let fb = FourBar {
            geometry,
            length_m,
            kappa_per_m: curvature_per_m(radius_mm)?,
        };
        fb.check_revolution()?;
        Ok(fb)
    }

    /// The coupler's chord, m.
    pub fn chord_m(&self) -> f64 {
        chord_m(self.length_m, self.kappa_per_m)
    }

    /// Assembly and toggle over the whole revolution, in closed form. The distance `f = |A O4|`
    /// runs over `|ground − crank|..ground + crank` (at 0° and 180°); the pins join where
    /// `|rocker − chord| ≤ f ≤ rocker + chord`, and the transmission angle's cosine
    /// `(rocker² + chord² − f²) / (2 rocker chord)` is monotone in `f`, so its worst value is
    /// at one of those two crank angles.
    fn check_revolution(&self) -> Result<(), FourBarError> {
        let g = &self.geometry;
        let (d, a, b, c) = (g.ground_m, g.crank_m, g.rocker_m, self.chord_m());
        let chord_mm = c * 1e3;
        let f_lo_ok = (b - c).abs();
        let f_hi_ok = b + c;
        // Crank angle at which |A O4| = f: f² = a² + d² − 2ad cos θ.
        let angle_of = |f: f64| {
            let cth = ((a * a + d * d - f * f) / (2.0 * a * d)).clamp(-1.0, 1.0);
            libm::acos(cth).to_degrees()
        };
        if d + a > f_hi_ok {
            let th = angle_of(f_hi_ok);
            return Err(FourBarError::CannotAssemble {
                chord_mm,
                crank_deg: (th, 360.0 - th),
            });
        }
        if (d - a).abs() < f_lo_ok {
            let th = angle_of(f_lo_ok);
            return Err(FourBarError::CannotAssemble {
                chord_mm,
                crank_deg: (-th, th),
            });
        }
        for (crank_deg, f) in [(0.0, (d - a).abs()), (180.0, d + a)] {
            let cos_mu = (b * b + c * c - f * f) / (2.0 * b * c);
            let s = sqrt((1.0 - cos_mu * cos_mu).max(0.0));
            if s < MIN_SIN_TRANSMISSION {
                return Err(FourBarError::Toggle {
                    chord_mm,
                    crank_deg,
                    sin_transmission: s,
                });
            }
        }
        Ok(())
    }

    /// The crank pin, both positions of the rocker pin at crank angle `theta_rad` (this branch,
    /// then the other) and `sin` of the transmission angle. `None` if the pins cannot join
    /// (only for a linkage not built by [`FourBar::new`]).
    fn solve(&self, theta_rad: f64) -> Option<Solved> {
        let g = &self.geometry;
        let (a, b, c) = (g.crank_m, g.rocker_m, self.chord_m());
        let pa = [a * cos(theta_rad), a * sin(theta_rad)];
        let e = [g.ground_m - pa[0], -pa[1]];
        let f = sqrt(e[0] * e[0] + e[1] * e[1]);
        let cos_al = (c * c + f * f - b * b) / (2.0 * c * f);
        let disc = 1.0 - cos_al * cos_al;
        if !(disc >= 0.0) || !(f > 0.0) {
            return None;
        }
        let sin_al = sqrt(disc);
        let u = [e[0] / f, e[1] / f];
        let at = |s: f64| {
            let (ca, sa) = (cos_al, s * sin_al);
            [
                pa[0] + c * (ca * u[0] - sa * u[1]),
                pa[1] + c * (sa * u[0] + ca * u[1]),
            ]
        };
        let sign = g.branch.sign();
        // The triangle A B O4: sin μ = f sin α / rocker (law of sines).
        let sin_mu = f * sin_al / b;
        Some(Solved {
            a: pa,
            b: at(sign),
            other_b: at(-sign),
            sin_mu,
        })
    }

    /// The foot, ground frame, m, for the crank and rocker pins `a`, `b`.
    fn foot(&self, a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
        let g = &self.geometry;
        let c = dist(a, b);
        let u = [(b[0] - a[0]) / c, (b[1] - a[1]) / c];
        let n = [u[1], -u[0]]; // right of A→B: the bulge side
        let (p, nrm) = arc_point(self.length_m, self.kappa_per_m, g.foot_at * self.length_m);
        let (x, y) = (
            p[0] + g.foot_offset_m * nrm[0],
            p[1] + g.foot_offset_m * nrm[1],
        );
        [a[0] + x * u[0] + y * n[0], a[1] + x * u[1] + y * n[1]]
    }

    /// Points of the locked link from `A` to `B` (for drawing), ground frame, m.
    pub fn link_points(&self, pose: &Pose, n: usize) -> Vec<[f64; 2]> {
        let (a, b) = (pose.a, pose.b);
        let c = dist(a, b);
        let u = [(b[0] - a[0]) / c, (b[1] - a[1]) / c];
        let nv = [u[1], -u[0]];
        (0..=n)
            .map(|i| {
                let s = self.length_m * i as f64 / n as f64;
                let (p, _) = arc_point(self.length_m, self.kappa_per_m, s);
                [
                    a[0] + p[0] * u[0] + p[1] * nv[0],
                    a[1] + p[0] * u[1] + p[1] * nv[1],
                ]
            })
            .collect()
    }

    /// The linkage at `crank_deg` on its branch.
    pub fn pose(&self, crank_deg: f64) -> Result<Pose, FourBarError> {
        let Solved { a, b, sin_mu, .. } =
            self.solve(crank_deg.to_radians())
                .ok_or(FourBarError::CannotAssemble {
                    chord_mm: self.chord_m() * 1e3,
                    crank_deg: (crank_deg, crank_deg),
                })?;
        if sin_mu < MIN_SIN_TRANSMISSION {
            return Err(FourBarError::Toggle {
                chord_mm: self.chord_m() * 1e3,
                crank_deg,
                sin_transmission: sin_mu,
            });
        }
        Ok(Pose {
            crank_deg,
            a,
            b,
            foot: self.foot(a, b),
            sin_transmission: sin_mu,
        })
    }

    /// One revolution in `steps` equal crank steps from 0°, following the branch: each rocker
    /// pin must lie nearer the previous one than the other mode's does, else
    /// [`FourBarError::BranchFlip`].
    pub fn sweep(&self, steps: usize) -> Result<Vec<Pose>, FourBarError> {
        if steps < 3 {
            return Err(FourBarError::TooFewSteps { steps });
        }
        let mut poses: Vec<Pose> = Vec::with_capacity(steps);
        let mut prev: Option<[f64; 2]> = None;
        for i in 0..=steps {
            let crank_deg = 360.0 * i as f64 / steps as f64;
            let pose = self.pose(crank_deg)?;
            let other = self
                .solve(crank_deg.to_radians())
                .expect("pose solved it")
                .other_b;
            if let Some(pb) = prev {
                if dist(other, pb) < dist(pose.b, pb) {
                    return Err(FourBarError::BranchFlip { crank_deg, steps });
                }
            }
            prev = Some(pose.b);
            if i < steps {
                poses.push(pose);
            }
        }
        Ok(poses)
    }

    /// The foot path over one revolution of `steps` points, mm.
    pub fn foot_path(&self, steps: usize) -> Result<Vec<PathPoint>, FourBarError> {
        Ok(self
            .sweep(steps)?
            .iter()
            .map(|p| PathPoint {
                crank_deg: p.crank_deg,
                foot_x_mm: p.foot[0] * 1e3,
                foot_y_mm: p.foot[1] * 1e3,
            })
            .collect())
    }

    /// The foot path's extremes, each refined by golden-section search in the crank angle
    /// around the best of [`DEFAULT_STEPS`] samples (so they vary smoothly with the radius).
    pub fn stats(&self) -> Result<PathStats, FourBarError> {
        let poses = self.sweep(DEFAULT_STEPS)?;
        let step = 360.0 / DEFAULT_STEPS as f64;
        let coord = |deg: f64, k: usize, sign: f64| -> f64 {
            let Solved { a, b, .. } = self.solve(deg.to_radians()).expect("checked revolution");
            sign * self.foot(a, b)[k]
        };
        // Smallest of sign·coord k: the best sample, then golden section over its neighbours.
        let extreme = |k: usize, sign: f64| -> (f64, f64) {
            let best = poses
                .iter()
                .min_by(|p, q| (sign * p.foot[k]).total_cmp(&(sign * q.foot[k])))
                .expect("at least 3 poses");
            let deg = golden_min(
                |t| coord(t, k, sign),
                best.crank_deg - step,
                best.crank_deg + step,
            );
            (sign * coord(deg, k, sign) * 1e3, deg.rem_euclid(360.0))
        };
        let (min_x_mm, _) = extreme(0, 1.0);
        let (max_x_mm, _) = extreme(0, -1.0);
        let (min_y_mm, lowest_crank_deg) = extreme(1, 1.0);
        let (max_y_mm, _) = extreme(1, -1.0);
        let min_sin_transmission = poses
            .iter()
            .map(|p| p.sin_transmission)
            .fold(f64::INFINITY, f64::min);
        Ok(PathStats {
            min_x_mm,
            max_x_mm,
            min_y_mm,
            max_y_mm,
            lowest_crank_deg,
            min_sin_transmission,
        })
    }
}

/// Minimum of a unimodal `f` on `[lo, hi]` by golden-section search, to 1e-9 of the interval.
fn golden_min(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
    const INV_PHI: f64 = 0.618_033_988_749_894_9;
    let tol = 1e-9 * (hi - lo).abs().max(1e-300);
    let mut x1 = hi - INV_PHI * (hi - lo);
    let mut x2 = lo + INV_PHI * (hi - lo);
    let (mut f1, mut f2) = (f(x1), f(x2));
    while (hi - lo).abs() > tol {
        if f1 <= f2 {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - INV_PHI * (hi - lo);
            f1 = f(x1);
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + INV_PHI * (hi - lo);
            f2 = f(x2);
        }
    }
    (lo + hi) / 2.0
}

/// Grashof's condition for four lengths: shortest + longest ≤ the other two. Returns the margin
/// `p + q − (s + l)`, m (negative: no link turns fully relative to another).
pub fn grashof_margin_m(lengths: [f64; 4]) -> f64 {
    let mut l = lengths;
    l.sort_by(f64::total_cmp);
    l[1] + l[2] - (l[0] + l[3])
}

/// Whether the linkage is a crank-rocker: Grashof with the crank the strictly shortest link.
pub fn is_crank_rocker(g: &FourBarGeometry, chord_m: f64) -> bool {
    let others = [g.ground_m, g.rocker_m, chord_m];
    grashof_margin_m([g.ground_m, g.crank_m, g.rocker_m, chord_m]) > 0.0
        && others.iter().all(|&x| g.crank_m < x)
}

/// The radii the link reaches, mm: `(min, max)`, the firmware table's ends (`RANGE`).
pub fn reachable_radii_mm(p: &LinkParams) -> (f64, f64) {
    let n = p.table_entries;
    (
        crate::table::entry(p, n - 1).radius_mm,
        crate::table::entry(p, 0).radius_mm,
    )
}

/// The inverse's answer.
#[derive(Clone, Debug, PartialEq)]
pub enum Inverse {
    /// Every reachable radius that gives the value (to 1e-6 mm of radius), ascending, with
    /// the value it gives.
    Found(Vec<(f64, f64)>),
    /// None does: the range of the property over the reachable radii, and the nearest radius
    /// with its value.
    Unreachable {
        /// Smallest and largest value over the reachable radii, mm.
        span_mm: (f64, f64),
        /// The radius that comes nearest, mm, and its value.
        nearest: (f64, f64),
    },
}

/// Radius scan points of the inverse over the reachable range: between two of them the property
/// is taken to cross a value at most once.
pub const INVERSE_SCAN: usize = 64;

/// The radii within `range_mm` at which `geometry`'s foot path has `prop = want_mm`: a scan of
/// [`INVERSE_SCAN`] radii, each turn of the property between scan points found by golden
/// section (a value between the scan's best and the true extremum is reached too), bisection
/// of every sign change, and, if there is none, the end of the span nearest the wanted value.
pub fn inverse(
    geometry: FourBarGeometry,
    length_m: f64,
    range_mm: (f64, f64),
    prop: Property,
    want_mm: f64,
) -> Result<Inverse, FourBarError> {
    let value = |r: f64| -> Result<f64, FourBarError> {
        Ok(FourBar::new(geometry, length_m, Some(r))?
            .stats()?
            .get(prop))
    };
    let (lo, hi) = range_mm;
    // (radius, value) in ascending radius: the scan, then the turns refined between.
    let mut pts = Vec::with_capacity(INVERSE_SCAN + 8);
    for i in 0..=INVERSE_SCAN {
        let r = lo + (hi - lo) * i as f64 / INVERSE_SCAN as f64;
        pts.push((r, value(r)?));
    }
    let mut turns = Vec::new();
    for w in pts.windows(3) {
        let (rise_in, rise_out) = (w[1].1 - w[0].1, w[2].1 - w[1].1);
        if rise_in * rise_out < 0.0 {
            // A maximum (rising in) or a minimum: the golden section minimises.
            let sign = if rise_in > 0.0 { -1.0 } else { 1.0 };
            let f = |r: f64| value(r).map_or(f64::INFINITY, |v| sign * v);
            let r = golden_min(f, w[0].0, w[2].0);
            turns.push((r, value(r)?));
        }
    }
    pts.extend(turns);
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Only the signs of the differences are used: they stay right for any finite want.
    let diff = |v: f64| v - want_mm;
    let mut found = Vec::new();
    for (k, w) in pts.windows(2).enumerate() {
        let ((mut a, va), (mut b, vb)) = (w[0], w[1]);
        let (mut fa, fb) = (diff(va), diff(vb));
        if fa == 0.0 {
            found.push((a, va));
            continue;
        }
        let last = k + 2 == pts.len();
        if fa * fb > 0.0 || (fb == 0.0 && !last) {
            continue; // no crossing, or it is the next interval's left end
        }
        while b - a > 1e-6 {
            let m = 0.5 * (a + b);
            let fm = diff(value(m)?);
            if (fm < 0.0) == (fa < 0.0) {
                a = m;
                fa = fm;
            } else {
                b = m;
            }
        }
        let r = 0.5 * (a + b);
        found.push((r, value(r)?));
    }
    if !found.is_empty() {
        return Ok(Inverse::Found(found));
    }
    let span_mm = pts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &(_, v)| {
            (a.min(v), b.max(v))
        });
    // With no crossing the wanted value lies outside the span: its nearer end is nearest.
    let above = want_mm > span_mm.1;
    let nearest = pts
        .iter()
        .copied()
        .min_by(|a, b| match above {
            true => b.1.total_cmp(&a.1),
            false => a.1.total_cmp(&b.1),
        })
        .expect("scan points");
    Ok(Inverse::Unreachable { span_mm, nearest })
}

#[cfg(test)]
mod tests {
    use super::*;

    const L: f64 = 0.05;

    fn default_bar(radius_mm: Option<f64>) -> FourBar {
        FourBar::new(FourBarGeometry::DEFAULT, L, radius_mm).unwrap()
    }

    fn reachable() -> (f64, f64) {
        reachable_radii_mm(&LinkParams::DEFAULT)
    }

    /// Radii across the reachable range, and the straight link.
    fn every_radius() -> Vec<Option<f64>> {
        let (lo, hi) = reachable();
        let mut v: Vec<Option<f64>> = (0..=40)
            .map(|i| Some(lo + (hi - lo) * i as f64 / 40.0))
            .collect();
        v.push(None);
        v
    }

    #[test]
    fn chord_is_2r_sin_l_over_2r_and_tends_to_l() {
        for r_mm in [20.0, 32.72, 40.0, 46.46, 1e3] {
            let r = r_mm * 1e-3;
            let want = 2.0 * r * (L / (2.0 * r)).sin();
            let got = chord_m(L, 1.0 / r);
            assert!((got - want).abs() < 1e-15, "{r_mm}: {got} vs {want}");
        }
        assert_eq!(chord_m(L, 0.0), L);
        // The limit: L − chord ≈ L³/(24 R²), to its next term.
        for r in [1.0, 10.0, 1e3, 1e6] {
            let gap = L - chord_m(L, 1.0 / r);
            let want = L * L * L / (24.0 * r * r);
            assert!(
                (gap - want).abs() <= 1e-2 * want + 1e-17,
                "{r}: {gap} vs {want}"
            );
        }
        assert!((end_angle_rad(L, 1.0 / 0.04) - 0.625).abs() < 1e-15);
    }

    #[test]
    fn arc_points_lie_on_the_circle_and_end_on_the_chord() {
        let (r, k) = (0.035, 1.0 / 0.035);
        let c = chord_m(L, k);
        let ([x0, y0], _) = arc_point(L, k, 0.0);
        let ([x1, y1], _) = arc_point(L, k, L);
        assert!(x0.abs() < 1e-16 && y0.abs() < 1e-16);
        assert!((x1 - c).abs() < 1e-16 && y1.abs() < 1e-16);
        // Centre at (c/2, −R cos φ) in the chord frame.
        let cy = -r * (L / (2.0 * r)).cos();
        for i in 0..=10 {
            let s = L * i as f64 / 10.0;
            let ([x, y], n) = arc_point(L, k, s);
            let rr = ((x - c / 2.0).powi(2) + (y - cy).powi(2)).sqrt();
            assert!((rr - r).abs() < 1e-15, "{s}: {rr}");
            assert!(
                ((x - c / 2.0) / r - n[0]).abs() < 1e-12 && ((y - cy) / r - n[1]).abs() < 1e-12
            );
        }
        let ([_, sag], _) = arc_point(L, k, L / 2.0);
        assert!((sag - r * (1.0 - (L / (2.0 * r)).cos())).abs() < 1e-16);
    }

    #[test]
    fn loop_closes_to_round_off_at_every_point() {
        let g = FourBarGeometry::DEFAULT;
        for r in every_radius() {
            let fb = default_bar(r);
            let c = fb.chord_m();
            for p in fb.sweep(DEFAULT_STEPS).unwrap() {
                let th = p.crank_deg.to_radians();
                assert!((dist(p.a, [g.crank_m * th.cos(), g.crank_m * th.sin()])) < 1e-17);
                assert!((dist(p.a, p.b) - c).abs() < 1e-16, "{r:?} {}", p.crank_deg);
                assert!((dist(p.b, [g.ground_m, 0.0]) - g.rocker_m).abs() < 1e-16);
                // The foot is the link's midpoint: equidistant from both pins.
                assert!((dist(p.foot, p.a) - dist(p.foot, p.b)).abs() < 1e-16);
            }
        }
    }

    /// An independent rigid four-bar: the rocker angle from Freudenstein's equation, the
    /// coupler point in the coupler's own frame.
    fn rigid_foot(g: &FourBarGeometry, coupler: f64, theta: f64) -> [f64; 2] {
        let (a, b, c, d) = (g.crank_m, g.rocker_m, coupler, g.ground_m);
        let (k1, k2, k3) = (
            d / a,
            d / b,
            (a * a - c * c + b * b + d * d) / (2.0 * a * b),
        );
        let aa = theta.cos() - k1 - k2 * theta.cos() + k3;
        let bb = -2.0 * theta.sin();
        let cc = k1 - (k2 + 1.0) * theta.cos() + k3;
        let disc = (bb * bb - 4.0 * aa * cc).sqrt();
        // Both roots; the right branch has B right of A→O4.
        let pa = [a * theta.cos(), a * theta.sin()];
        let pick = [1.0, -1.0]
            .into_iter()
            .map(|s| {
                let t4 = 2.0 * ((-bb + s * disc) / (2.0 * aa)).atan();
                [d + b * t4.cos(), b * t4.sin()]
            })
            .find(|pb| {
                let cross = (d - pa[0]) * (pb[1] - pa[1]) - (-pa[1]) * (pb[0] - pa[0]);
                cross < 0.0
            })
            .unwrap();
        [(pa[0] + pick[0]) / 2.0, (pa[1] + pick[1]) / 2.0]
    }

    #[test]
    fn a_straight_link_is_a_rigid_link_of_the_same_length() {
        let g = FourBarGeometry::DEFAULT;
        let fb = default_bar(None);
        assert_eq!(fb.chord_m(), L);
        for p in fb.sweep(DEFAULT_STEPS).unwrap() {
            let want = rigid_foot(&g, L, p.crank_deg.to_radians());
            assert!(
                dist(p.foot, want) < 1e-15,
                "{}: {:?} vs {want:?}",
                p.crank_deg,
                p.foot
            );
        }
        // An infinite radius is the straight link.
        assert_eq!(default_bar(Some(f64::INFINITY)), fb);
    }

    #[test]
    fn the_default_is_a_crank_rocker_over_the_whole_reachable_range() {
        let g = FourBarGeometry::DEFAULT;
        let (lo, hi) = reachable();
        assert!(lo > 30.0 && hi < 50.0, "reachable {lo}..{hi}");
        for r in every_radius() {
            let c = chord_m(L, curvature_per_m(r).unwrap());
            let margin = grashof_margin_m([g.ground_m, g.crank_m, g.rocker_m, c]);
            assert!(margin > 0.02 - 1e-12, "{r:?}: Grashof margin {margin}");
            assert!(is_crank_rocker(&g, c), "{r:?}");
            let s = default_bar(r).stats().unwrap();
            // Transmission angle kept within 40..140 deg.
            assert!(s.min_sin_transmission > 40f64.to_radians().sin(), "{r:?}");
        }
    }

    #[test]
    fn rocker_limit_positions_are_regular_for_a_crank_drive() {
        // Crank and coupler collinear (A on the line O2–B): the rocker reverses, the position
        // stays regular. Find the crank angle where |O2 B| = crank + chord and check the pose.
        let fb = default_bar(Some(38.0));
        let c = fb.chord_m();
        let poses = fb.sweep(3600).unwrap();
        let p = poses
            .iter()
            .min_by(|p, q| {
                let e = |p: &Pose| (dist(p.b, [0.0, 0.0]) - (DEFAULT_CRANK_M + c)).abs();
                e(p).total_cmp(&e(q))
            })
            .unwrap();
        assert!((dist(p.b, [0.0, 0.0]) - (DEFAULT_CRANK_M + c)).abs() < 1e-7);
        assert!(p.sin_transmission > 0.5);
    }

    #[test]
    fn a_geometry_that_cannot_assemble_is_refused_with_the_crank_angles() {
        // The rocker so short that at 180 deg the pins cannot meet (d + a = 65 mm > b + c).
        let g = FourBarGeometry {
            rocker_m: 0.016,
            ..FourBarGeometry::DEFAULT
        };
        let e = FourBar::new(g, L, Some(38.0)).unwrap_err();
        let FourBarError::CannotAssemble {
            crank_deg: (lo, hi),
            ..
        } = e
        else {
            panic!("{e:?}")
        };
        assert!(
            lo > 90.0 && lo < 180.0 && (lo + hi - 360.0).abs() < 1e-9,
            "{lo}..{hi}"
        );
        assert!(
            e.to_string()
                .contains("cannot assemble over a full revolution"),
            "{e}"
        );
    }

    #[test]
    fn a_radius_can_be_what_makes_the_linkage_fail_to_assemble() {
        // Rocker 18 mm: the straight link (b + c = 68 mm > d + a = 65 mm) turns fully, but a
        // chord under 47 mm cannot reach at 180 deg, and the tightest reachable radius gives 45.27.
        let g = FourBarGeometry {
            rocker_m: 0.018,
            ..FourBarGeometry::DEFAULT
        };
        FourBar::new(g, L, None)
            .unwrap()
            .sweep(DEFAULT_STEPS)
            .unwrap();
        let (lo, _) = reachable();
        let e = FourBar::new(g, L, Some(lo)).unwrap_err();
        assert!(matches!(e, FourBarError::CannotAssemble { .. }), "{e:?}");
        assert!(e.to_string().contains("45.27 mm chord"), "{e}");
        // Right at the toggle (b + c = d + a) it is singular, not merely unassemblable.
        let g = FourBarGeometry {
            rocker_m: 0.015,
            ..FourBarGeometry::DEFAULT
        };
        assert!(matches!(
            FourBar::new(g, L, None),
            Err(FourBarError::Toggle { .. })
        ));
    }

    /// A straight-link linkage `delta` metres short of its toggle at 180 deg.
    fn near_toggle(delta: f64) -> FourBarGeometry {
        FourBarGeometry {
            ground_m: 0.055,
            rocker_m: 0.020 + delta,
            ..FourBarGeometry::DEFAULT
        }
    }

    #[test]
    fn near_toggle_is_refused_at_the_documented_tolerance() {
        // Ground 55 mm, rocker 20 mm + δ, straight link: b + c − (d + a) = δ, so the toggle is at
        // 180 deg only, where sin μ ≈ sqrt(2 δ (b + c) / (b c)).
        let sin_at = |delta: f64| {
            let g = near_toggle(delta);
            (g, FourBar::new(g, L, None))
        };
        let (_, just_inside) = sin_at(1e-9);
        match just_inside {
            Err(FourBarError::Toggle {
                crank_deg,
                sin_transmission,
                ..
            }) => {
                assert_eq!(crank_deg, 180.0);
                assert!(sin_transmission < MIN_SIN_TRANSMISSION);
            }
            other => panic!("{other:?}"),
        }
        let (g, ok) = sin_at(1e-6);
        let fb = ok.unwrap();
        let s = fb.stats().unwrap();
        assert!(s.min_sin_transmission > MIN_SIN_TRANSMISSION && s.min_sin_transmission < 0.05);
        assert!(g.rocker_m > 0.020);
        // A pose asked for at the toggle of a linkage built around the check is refused too.
        let raw = FourBar {
            geometry: near_toggle(0.0),
            length_m: L,
            kappa_per_m: 0.0,
        };
        assert!(matches!(raw.pose(180.0), Err(FourBarError::Toggle { .. })));
    }

    #[test]
    fn a_coarse_sweep_near_a_toggle_loses_its_branch_and_says_so() {
        let g = near_toggle(1e-6);
        let fb = FourBar::new(g, L, None).unwrap();
        // Fine steps follow the branch through the near-toggle at 180 deg…
        fb.sweep(3600).unwrap();
        // …a coarse step that lands on both sides of it cannot tell the modes apart.
        let e = (3..40)
            .find_map(|n| fb.sweep(n).err())
            .expect("some coarse sweep flips");
        assert!(matches!(e, FourBarError::BranchFlip { .. }), "{e:?}");
        assert!(e.to_string().contains("lost its assembly mode"));
        // The default is far from any toggle: even 3 steps keep the branch.
        default_bar(Some(38.0)).sweep(3).unwrap();
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(matches!(
            FourBar::new(FourBarGeometry::DEFAULT, L, Some(-3.0)),
            Err(FourBarError::BadRadius { .. })
        ));
        assert!(matches!(
            FourBar::new(FourBarGeometry::DEFAULT, L, Some(f64::NAN)),
            Err(FourBarError::BadRadius { .. })
        ));
        assert!(matches!(
            default_bar(Some(38.0)).sweep(2),
            Err(FourBarError::TooFewSteps { steps: 2 })
        ));
    }

    #[test]
    fn the_bend_changes_the_path() {
        let straight = default_bar(None).stats().unwrap();
        let (lo, _) = reachable();
        let bent = default_bar(Some(lo)).stats().unwrap();
        assert!(
            (straight.min_y_mm - bent.min_y_mm).abs() > 1.0,
            "{straight:?} {bent:?}"
        );
    }

    #[test]
    fn stats_refine_the_samples() {
        let fb = default_bar(Some(40.0));
        let path = fb.foot_path(DEFAULT_STEPS).unwrap();
        let s = fb.stats().unwrap();
        let low = path
            .iter()
            .map(|p| p.foot_y_mm)
            .fold(f64::INFINITY, f64::min);
        assert!(
            s.min_y_mm <= low && low - s.min_y_mm < 1e-2,
            "{} {low}",
            s.min_y_mm
        );
        let fine = fb.foot_path(36_000).unwrap();
        let low_fine = fine
            .iter()
            .map(|p| p.foot_y_mm)
            .fold(f64::INFINITY, f64::min);
        assert!((s.min_y_mm - low_fine).abs() < 1e-6);
    }

    #[test]
    fn the_inverse_round_trips() {
        let g = FourBarGeometry::DEFAULT;
        let range = reachable();
        for prop in Property::ALL {
            for r in [33.5, 39.0, 45.0] {
                let want = default_bar(Some(r)).stats().unwrap().get(prop);
                let Inverse::Found(sols) = inverse(g, L, range, prop, want).unwrap() else {
                    panic!("{prop:?} at {r}")
                };
                assert!(
                    sols.iter()
                        .any(|&(s, v)| (s - r).abs() < 1e-5 && (v - want).abs() < 1e-6),
                    "{prop:?} {r}: {sols:?}"
                );
            }
        }
    }

    #[test]
    fn a_non_monotonic_property_gives_every_solution() {
        // A foot 30 mm off the link, three quarters along it: its lowest point first falls then
        // rises with the radius (−9.80 mm at the tightest radius, −9.36 mm at the turn, −9.57 mm
        // at the loosest), so −9.45 mm has two radii.
        let g = FourBarGeometry {
            foot_at: 0.75,
            foot_offset_m: -0.03,
            ..FourBarGeometry::DEFAULT
        };
        let Inverse::Found(sols) = inverse(g, L, reachable(), Property::Lowest, -9.45).unwrap()
        else {
            panic!()
        };
        assert_eq!(sols.len(), 2, "{sols:?}");
        for (r, v) in sols {
            assert!((v + 9.45).abs() < 1e-6, "{r} {v}");
            let back = FourBar::new(g, L, Some(r))
                .unwrap()
                .stats()
                .unwrap()
                .get(Property::Lowest);
            assert!((back + 9.45).abs() < 1e-6);
        }
    }

    #[test]
    fn the_inverse_says_how_close_it_can_get() {
        let g = FourBarGeometry::DEFAULT;
        let range = reachable();
        let Inverse::Unreachable { span_mm, nearest } =
            inverse(g, L, range, Property::Stride, 1.0).unwrap()
        else {
            panic!()
        };
        assert!(
            span_mm.0 > 1.0 && nearest.1 - span_mm.0 < 1e-6,
            "{span_mm:?} {nearest:?}"
        );
        assert!(nearest.0 >= range.0 && nearest.0 <= range.1);
    }

    #[test]
    fn the_inverse_reaches_a_value_between_the_scans_best_and_the_true_turn() {
        // A foot whose lowest point turns inside the range: its true maximum lies between two
        // scan points, above both.
        let g = FourBarGeometry {
            foot_at: 0.75,
            foot_offset_m: -0.03,
            ..FourBarGeometry::DEFAULT
        };
        let range = reachable();
        let at = |r: f64| {
            let s = FourBar::new(g, L, Some(r)).unwrap().stats().unwrap();
            s.get(Property::Lowest)
        };
        let dense_max = (0..=4000)
            .map(|i| at(range.0 + (range.1 - range.0) * i as f64 / 4000.0))
            .fold(f64::NEG_INFINITY, f64::max);
        let scan_max = (0..=INVERSE_SCAN)
            .map(|i| at(range.0 + (range.1 - range.0) * i as f64 / INVERSE_SCAN as f64))
            .fold(f64::NEG_INFINITY, f64::max);
        assert!(dense_max > scan_max + 1e-4, "{dense_max} {scan_max}");
        let want = 0.5 * (dense_max + scan_max);
        let Inverse::Found(sols) = inverse(g, L, range, Property::Lowest, want).unwrap() else {
            panic!("{want} is reachable")
        };
        assert_eq!(sols.len(), 2, "{sols:?}");
        for (_, v) in sols {
            assert!((v - want).abs() < 1e-6, "{v} {want}");
        }
        // Just over the true maximum: unreachable, with that maximum as the span's top.
        let Inverse::Unreachable { span_mm, nearest } =
            inverse(g, L, range, Property::Lowest, dense_max + 1e-3).unwrap()
        else {
            panic!()
        };
        // The refined turn is at least the dense scan's best, and near it.
        assert!(
            span_mm.1 >= dense_max - 1e-9 && span_mm.1 < dense_max + 1e-3,
            "{span_mm:?} {dense_max}"
        );
        assert_eq!(nearest.1, span_mm.1);
    }

    #[test]
    fn the_inverse_of_a_value_far_out_of_reach_names_the_span_and_its_nearest_end() {
        let g = FourBarGeometry::DEFAULT;
        let range = reachable();
        let span = |want: f64| match inverse(g, L, range, Property::Height, want).unwrap() {
            Inverse::Unreachable { span_mm, nearest } => (span_mm, nearest),
            Inverse::Found(s) => panic!("{want}: {s:?}"),
        };
        let (near, _) = span(1e3);
        for want in [1e20, -1e20, f64::MAX] {
            let (span_mm, nearest) = span(want);
            // The span is the property's, whatever was wanted.
            assert!((span_mm.0 - near.0).abs() < 1e-9 && (span_mm.1 - near.1).abs() < 1e-9);
            assert!(span_mm.1 > span_mm.0, "{span_mm:?}");
            let end = if want > 0.0 { span_mm.1 } else { span_mm.0 };
            assert!(
                (nearest.1 - end).abs() < 1e-6,
                "{want}: {nearest:?} {span_mm:?}"
            );
        }
    }
}

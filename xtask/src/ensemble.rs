//! The links the ensemble tasks run on (`strategies`, `calibration`, `warm`, `limits`,
//! `stored-heat`, `gait`), built in one place so "hifi draw 15" or "lumped nominal air" is the
//! same link, with the same board noise and the same name, in every task and every table; and
//! the options those tasks share ([`Common`]).

use indicatif::{ProgressBar, ProgressStyle};
use morphlink::bench::Noise;
use morphlink_plant::hifi::{Grid, Hifi, HifiSpec};
use morphlink_plant::{Lumped, Medium, Plant};
use morphlink_sim::ensemble::Mismatch;
use morphlink_sim::Rig;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// Seed of every ensemble's draws (each CSV records every drawn mismatch, so any run can be
/// replayed; the charts in docs/ were made with it).
pub const DEFAULT_SEED: u64 = 20_261_122;
/// High-fidelity links drawn by default: 40 links × 5 radii × 4 strategies = 800 morphs on the
/// reduced-order grid (about 0.1 s a morph, 0.5 s to build a link), a few minutes on two cores.
pub const DEFAULT_HIFI_DRAWS: u64 = 40;
/// Worker threads by default: the machines the docs' figures were measured on have two cores.
pub const DEFAULT_THREADS: usize = 2;

/// The options every ensemble task takes. Each task names its own default number of links.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct Common {
    /// Seed of the drawn links.
    #[arg(long, default_value_t = DEFAULT_SEED)]
    pub seed: u64,
    /// Worker threads.
    #[arg(long, default_value_t = DEFAULT_THREADS)]
    pub threads: usize,
}

/// A link's physics, owned and cloned for every run.
#[derive(Clone)]
// Cloned once a run and matched at once: boxing the lumped link too would buy nothing.
#[allow(clippy::large_enum_variant)]
pub enum Body {
    /// The lumped plant: the controller's own equations, other parameters.
    Lumped(Lumped),
    /// The high-fidelity plant: the one that shares the least with the controller.
    Hifi(Box<Hifi>),
}

/// How a link was made, for grouping results.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// The lumped plant with no mismatch (in water or still air).
    LumpedNominal,
    /// The hifi plant's nominal link (in water or still air).
    HifiNominal,
    /// A drawn lumped link.
    LumpedDraws,
    /// A drawn hifi link.
    HifiDraws,
}

impl Family {
    /// The family's name in tables.
    pub fn as_str(self) -> &'static str {
        match self {
            Family::LumpedNominal => "lumped nominal",
            Family::HifiNominal => "hifi nominal",
            Family::LumpedDraws => "lumped draws",
            Family::HifiDraws => "hifi draws",
        }
    }
}

/// One link of an ensemble: its physics, its board's thermistor noise and what it is.
#[derive(Clone)]
pub struct Link {
    /// Its name in tables, for example `hifi draw 15 air` or `lumped nominal water`.
    pub name: String,
    /// How it was made.
    pub family: Family,
    /// Its draw number (0 for a nominal link).
    pub draw: u64,
    /// True if it sits in still air (the controller's model assumes water).
    pub air: bool,
    /// A lumped link's mismatch (`None` for a hifi link: its spec is its body's).
    pub mismatch: Option<Mismatch>,
    /// Its board's thermistor noise.
    pub noise: Noise,
    /// Its physics.
    pub body: Body,
}

impl Link {
    /// The temperature of its medium, °C (the surroundings it was made in).
    pub fn ambient_c(&self) -> f64 {
        match &self.body {
            Body::Lumped(l) => l.spec().params.surroundings.ambient_c,
            Body::Hifi(h) => h.spec().ambient_c,
        }
    }
}

/// The medium's name in a link's name.
fn medium_name(air: bool) -> &'static str {
    if air {
        "air"
    } else {
        "water"
    }
}

impl Link {
    /// The lumped link with no mismatch, in water or still air, its thermistors' time constant
    /// `sensor_tau_s` (the nominal 3 s unless a task tries others).
    pub fn lumped_nominal(air: bool, sensor_tau_s: f64) -> Link {
        let mismatch = Mismatch {
            air,
            sensor_tau_s,
            ..Mismatch::NONE
        };
        let setup = mismatch.plant();
        let bead = if sensor_tau_s == Mismatch::NONE.sensor_tau_s {
            String::new()
        } else {
            format!(" bead {sensor_tau_s} s")
        };
        Link {
            name: format!("lumped nominal {}{bead}", medium_name(air)),
            family: Family::LumpedNominal,
            draw: 0,
            air,
            mismatch: Some(mismatch),
            noise: setup.noise(),
            body: Body::Lumped(setup.lumped()),
        }
    }

    /// The hifi plant's nominal link on the reduced-order grid, in water or still air, with the
    /// nominal board noise.
    pub fn hifi_nominal(air: bool) -> Result<Link, String> {
        let mut spec = HifiSpec::nominal(morphlink::link::LINK, Grid::Reduced)
            .map_err(|e| format!("hifi nominal: {e}"))?;
        if air {
            spec.medium = Medium::Air;
        }
        let plant = Hifi::new(spec).map_err(|e| format!("hifi nominal: {e}"))?;
        Ok(Link {
            name: format!("hifi nominal {}", medium_name(air)),
            family: Family::HifiNominal,
            draw: 0,
            air,
            mismatch: None,
            noise: Noise::NOMINAL,
            body: Body::Hifi(Box::new(plant)),
        })
    }

    /// The nominal link (lumped, or hifi where `hifi`) in the stillest air the calibration's
    /// convection setting is rated for (`convection_w_m2k`'s least, 10 W/(m² K): half the
    /// model's still air, under the ensemble's draws): where a still-air expectation is
    /// furthest from water's.
    pub fn nominal_stillest_air(hifi: bool) -> Result<Link, String> {
        let h_w_m2k = f64::from(morphlink::link::CONVECTION_RANGE_W_M2K.0);
        let h_scale = h_w_m2k / morphlink_model::params::H_AIR_W_M2K;
        let name = format!(
            "{} nominal air {h_w_m2k} W/m2K",
            if hifi { "hifi" } else { "lumped" }
        );
        let mut link = if hifi {
            Link::hifi_nominal(true)?
        } else {
            Link::lumped_nominal(true, Mismatch::NONE.sensor_tau_s)
        };
        match &mut link.body {
            Body::Lumped(_) => {
                let mismatch = Mismatch {
                    air: true,
                    h_scale,
                    ..Mismatch::NONE
                };
                link.body = Body::Lumped(mismatch.plant().lumped());
                link.mismatch = Some(mismatch);
            }
            Body::Hifi(p) => {
                let mut spec = *p.spec();
                spec.h_scale = h_scale;
                **p = Hifi::new(spec).map_err(|e| format!("{name}: {e}"))?;
            }
        }
        link.name = name;
        Ok(link)
    }

    /// Lumped link number `draw` of the ensemble with seed `seed`.
    pub fn lumped_draw(seed: u64, draw: u64) -> Link {
        let mismatch = Mismatch::draw(seed, draw);
        let setup = mismatch.plant();
        Link {
            name: format!("lumped draw {draw} {}", medium_name(mismatch.air)),
            family: Family::LumpedDraws,
            draw,
            air: mismatch.air,
            mismatch: Some(mismatch),
            noise: setup.noise(),
            body: Body::Lumped(setup.lumped()),
        }
    }

    /// High-fidelity link number `draw` of the ensemble with seed `seed`, in its drawn medium
    /// (`morphlink_sim::ensemble::hifi_draw`: the one definition the tests share).
    pub fn hifi_draw(seed: u64, draw: u64) -> Result<Link, String> {
        let (spec, noise) = morphlink_sim::ensemble::hifi_draw(seed, draw)
            .map_err(|e| format!("hifi draw {draw}: {e}"))?;
        Self::hifi_from(spec, noise, draw)
    }

    fn hifi_from(spec: HifiSpec, noise: Noise, draw: u64) -> Result<Link, String> {
        let air = spec.medium == Medium::Air;
        let plant = Hifi::new(spec).map_err(|e| format!("hifi draw {draw}: {e}"))?;
        Ok(Link {
            name: format!("hifi draw {draw} {}", medium_name(air)),
            family: Family::HifiDraws,
            draw,
            air,
            mismatch: None,
            noise,
            body: Body::Hifi(Box::new(plant)),
        })
    }

    /// High-fidelity draw `draw` moved into still air (its convection scale kept), or `None` if
    /// it was drawn in air.
    pub fn hifi_draw_in_air(seed: u64, draw: u64) -> Result<Option<Link>, String> {
        let (mut spec, noise) = morphlink_sim::ensemble::hifi_draw(seed, draw)
            .map_err(|e| format!("hifi draw {draw}: {e}"))?;
        if spec.medium == Medium::Air {
            return Ok(None);
        }
        spec.medium = Medium::Air;
        Self::hifi_from(spec, noise, draw).map(Some)
    }

    /// True if the link is a hifi one.
    pub fn is_hifi(&self) -> bool {
        matches!(self.body, Body::Hifi(_))
    }

    /// A fresh copy of the link's plant.
    pub fn plant(&self) -> Box<dyn Plant> {
        match &self.body {
            Body::Lumped(p) => Box::new(p.clone()),
            Body::Hifi(p) => Box::new((**p).clone()),
        }
    }

    /// A fresh rig on a copy of the link, with its board noise, not yet booted.
    pub fn rig(&self) -> Rig<Box<dyn Plant>> {
        Rig::with_plant(self.plant(), self.noise)
    }
}

/// Percentile `p` (0–100) of sorted values, nearest rank (NaN of none): the strategy and
/// calibration tables'.
pub fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((p / 100.0) * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

/// Quantile `q` (0–1) of `v`, which it sorts, at the rounded rank `(len − 1) · q` (NaN of
/// none): the self-sense and warm tables'.
pub fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(((v.len() as f64 - 1.0) * q).round() as usize)
        .copied()
        .unwrap_or(f64::NAN)
}

/// Runs `f` on every item of `items` on `threads` workers, with a progress bar named `what`.
pub fn parallel<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    what: &str,
    f: impl Fn(&T) -> R + Sync,
) -> Result<Vec<R>, String> {
    let bar = ProgressBar::new(items.len() as u64);
    bar.set_style(
        ProgressStyle::with_template(&format!(
            "{{bar:40}} {{pos}}/{{len}} {what}, {{elapsed}} elapsed, ~{{eta}} left"
        ))
        .map_err(|e| e.to_string())?,
    );
    // Drawn from the start, not only once the first item is done (a hifi link takes seconds);
    // on stderr, and only on a terminal (indicatif hides a bar whose stderr is not one).
    bar.enable_steady_tick(std::time::Duration::from_millis(250));
    let next = AtomicUsize::new(0);
    let out = Mutex::new(Vec::with_capacity(items.len()));
    std::thread::scope(|scope| {
        for _ in 0..threads.max(1) {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(item) = items.get(i) else {
                    break;
                };
                let r = f(item);
                out.lock().unwrap().push((i, r));
                bar.inc(1);
            });
        }
    });
    bar.finish();
    let mut out = out.into_inner().unwrap();
    out.sort_by_key(|(i, _)| *i);
    Ok(out.into_iter().map(|(_, r)| r).collect())
}

#[cfg(test)]
mod tests {
    #[test]
    fn percentile_is_nearest_rank_and_quantile_the_rounded_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(percentile(&v, 50.0), 50.0);
        assert_eq!(percentile(&v, 95.0), 95.0);
        assert_eq!(percentile(&[3.0], 95.0), 3.0);
        assert!(percentile(&[], 50.0).is_nan());
        let mut w: Vec<f64> = (1..=11).rev().map(f64::from).collect();
        assert_eq!(quantile(&mut w, 0.5), 6.0);
        assert_eq!(quantile(&mut w, 0.95), 11.0);
        assert!(quantile(&mut [], 0.5).is_nan());
    }

    use super::*;

    #[test]
    fn a_draw_is_the_same_link_in_every_task() {
        let a = Link::lumped_draw(DEFAULT_SEED, 7);
        let b = Link::lumped_draw(DEFAULT_SEED, 7);
        assert_eq!(a.mismatch, b.mismatch);
        assert_eq!(a.name, b.name);
        assert_ne!(a.mismatch, Link::lumped_draw(DEFAULT_SEED, 8).mismatch);
    }

    #[test]
    fn names_say_the_plant_the_draw_and_the_medium() {
        assert_eq!(
            Link::lumped_nominal(true, Mismatch::NONE.sensor_tau_s).name,
            "lumped nominal air"
        );
        assert_eq!(
            Link::lumped_nominal(false, 6.0).name,
            "lumped nominal water bead 6 s"
        );
        let d = Link::lumped_draw(DEFAULT_SEED, 3);
        assert!(d.name.starts_with("lumped draw 3 "), "{}", d.name);
    }
}

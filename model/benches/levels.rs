//! Cost of each model level: the lumped curve, the finite-volume thermal matrix per grid, the
//! constant-strain and piecewise Cosserat solves, and transient stepping.
//! `cargo bench -p morphlink-model --features reference --bench levels`
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use morphlink_model::reference::cosserat::{self, Rod, REFERENCE_STRAIN};
use morphlink_model::reference::fv_thermal::{CrossSection, Stepping};
use morphlink_model::reference::levels::{radius_curve_mm, Level, POWERS_W};
use morphlink_model::reference::tca_physics::TcaLaw;
use morphlink_model::LinkParams;

fn lumped(c: &mut Criterion) {
    let p = LinkParams::DEFAULT;
    c.bench_function("lumped curve (15 powers)", |b| {
        b.iter(|| radius_curve_mm(black_box(&p), &Level::LUMPED, &POWERS_W).unwrap())
    });
}

/// `cargo bench` passes `--bench`; `cargo test --all-targets` runs each benchmark once in a
/// debug build, where the fine grids would take minutes, so they are measured only under bench.
fn full_run() -> bool {
    std::env::args().any(|a| a == "--bench")
}

fn thermal(c: &mut Criterion) {
    let p = LinkParams::DEFAULT;
    let mut g = c.benchmark_group("fv thermal matrix");
    g.sample_size(10);
    let grids: &[usize] = if full_run() {
        &[8, 16, 32, 64, 96]
    } else {
        &[8]
    };
    for &rings in grids {
        g.bench_function(format!("{rings} rings"), |b| {
            b.iter(|| {
                CrossSection::of_link(black_box(&p), rings)
                    .unwrap()
                    .resistance_matrix()
                    .unwrap()
            })
        });
    }
    g.finish();
    let rings = if full_run() { 16 } else { 6 };
    let mut g = c.benchmark_group(format!("fv transient {rings} rings, 10 s"));
    g.sample_size(10);
    let x = CrossSection::of_link(&p, rings).unwrap();
    let limit = x.explicit_limit_s();
    let n_exp = (10.0 / (0.9 * limit)).ceil() as usize;
    g.bench_function(format!("explicit, {n_exp} steps at 0.9 x limit"), |b| {
        b.iter(|| {
            x.transient(1.0, 1.5, 10.0 / n_exp as f64, n_exp, Stepping::Explicit)
                .unwrap()
        })
    });
    g.bench_function("implicit, 100 steps of 0.1 s", |b| {
        b.iter(|| x.transient(1.0, 1.5, 0.1, 100, Stepping::Implicit).unwrap())
    });
    g.finish();
}

fn mechanics(c: &mut Criterion) {
    let p = LinkParams::DEFAULT;
    let rod = Rod::of_link(&p, TcaLaw::Linear(p.mechanics).at(80.0), None);
    c.bench_function("cosserat constant strain, one power", |b| {
        b.iter(|| cosserat::solve_robust(black_box(&rod), 1, &REFERENCE_STRAIN).unwrap())
    });
    let mut g = c.benchmark_group("cosserat piecewise, one power");
    g.sample_size(20);
    for n in [2usize, 8, 32] {
        g.bench_function(format!("N = {n}"), |b| {
            b.iter(|| cosserat::solve_robust(black_box(&rod), n, &REFERENCE_STRAIN).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, lumped, thermal, mechanics);
criterion_main!(benches);

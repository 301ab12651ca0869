//! Cost of one controller tick and of a whole simulated morph.
//!
//! `cargo bench --bench step`; results are written into docs/performance.md by hand with the
//! date and the machine.
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use morphlink::controller::TICK_MS;
use morphlink_sim::{LinkSetup, Rig};

/// A rig in the bend phase of a morph to 38 mm.
fn rig_in_bend() -> Rig {
    let mut rig = Rig::new(LinkSetup::NOMINAL);
    rig.handle_line("MORPH 38", &mut |_| {});
    while rig.ctrl.phase() != morphlink::vocab::Phase::Bend {
        rig.tick();
    }
    rig
}

fn controller_step(c: &mut Criterion) {
    let mut rig = rig_in_bend();
    let inputs = rig.inputs(rig.now_ms());
    let mut now = rig.now_ms();
    c.bench_function("controller step (bend phase)", |b| {
        b.iter(|| {
            now += TICK_MS;
            let mut i = inputs;
            i.sample_ms = now;
            black_box(rig.ctrl.step(now, black_box(&i)))
        })
    });
}

fn sim_tick(c: &mut Criterion) {
    let mut rig = rig_in_bend();
    c.bench_function("rig tick (controller + simulated link, 100 ms)", |b| {
        b.iter(|| black_box(rig.tick()))
    });
}

fn whole_morph(c: &mut Criterion) {
    c.bench_function("whole simulated morph to 38 mm", |b| {
        b.iter(|| {
            let mut rig = Rig::new(LinkSetup::NOMINAL);
            rig.handle_line("MORPH 38", &mut |_| {});
            while rig.ctrl.busy() {
                rig.tick();
            }
            black_box(rig.radius_mm())
        })
    });
}

criterion_group!(benches, controller_step, sim_tick, whole_morph);
criterion_main!(benches);

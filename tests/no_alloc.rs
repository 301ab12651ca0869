//! The controller and the simulated link allocate nothing: a whole morph runs under a counting
//! allocator with zero allocations. Only the test's own thread is counted: the test harness
//! allocates on its main thread while the test runs, which says nothing about the core.
use morphlink_sim::{LinkSetup, Rig};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// True on the thread whose allocations are counted (const-initialised: no allocation).
    static COUNTED: Cell<bool> = const { Cell::new(false) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTED.try_with(Cell::get).unwrap_or(false) {
            ALLOCS.fetch_add(1, Ordering::SeqCst);
        }
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn a_whole_morph_allocates_nothing() {
    let mut rig = Rig::new(LinkSetup::NOMINAL);
    let mut replies = 0usize;
    let mut events = 0usize;
    COUNTED.with(|c| c.set(true));
    let before = ALLOCS.load(Ordering::SeqCst);
    rig.handle_line("MORPH 38", &mut |_| replies += 1);
    let mut ticks = 0;
    while rig.ctrl.busy() {
        rig.tick();
        rig.drain_events(&mut |_| events += 1);
        ticks += 1;
    }
    rig.handle_line("STATUS", &mut |_| replies += 1);
    let after = ALLOCS.load(Ordering::SeqCst);
    // The counter sees this thread's allocations: one more is counted.
    drop(std::hint::black_box(Vec::<u8>::with_capacity(8)));
    let probe = ALLOCS.load(Ordering::SeqCst);
    COUNTED.with(|c| c.set(false));
    assert_eq!(probe - after, 1, "the counting allocator counts");
    assert_eq!(after - before, 0, "allocations during {ticks} ticks");
    assert_eq!(replies, 2);
    assert_eq!(events, 5, "four phases and done");
    assert!(ticks > 100);
}

//! The controller and the simulated link allocate nothing: a whole morph runs under a counting
//! allocator with zero allocations.
use morphlink_sim::{LinkSetup, Rig};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::SeqCst);
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
    assert_eq!(after - before, 0, "allocations during {ticks} ticks");
    assert_eq!(replies, 2);
    assert_eq!(events, 5, "four phases and done");
    assert!(ticks > 100);
}

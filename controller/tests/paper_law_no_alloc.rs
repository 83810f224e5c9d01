//! The paper's law steps without touching the heap: a counting global allocator sees no allocation
//! across many steps (contact, free air, an event).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use controller::{ForceLaw, ImpedanceLaw, ImpedanceParams, Reference};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// The workspace denies `unsafe`; a global allocator cannot be written without it, so this test opts in.
#[allow(unsafe_code)]
// SAFETY: forwards every call unchanged to the system allocator.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: the caller upholds `GlobalAlloc::alloc`'s contract, which we pass on.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above, for `dealloc`.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn paper_and_fixed_laws_step_without_allocating() {
    let mut paper = ImpedanceLaw::paper();
    let mut fixed =
        ImpedanceLaw::new(ImpedanceParams::PAPER, Reference::Fixed { x_r: 0.0101 }).unwrap();
    paper.start(0.0091);
    fixed.start(0.0091);
    let mut x = 0.0091;
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    for k in 0..10_000 {
        let k_c = if k < 5_000 { 70_000.0 } else { 40_000.0 };
        let f = (k_c * (x - 0.01f64)).max(0.0);
        x = paper.step(x, f, 1e-3).x_cmd;
        std::hint::black_box(fixed.step(x, f, 1e-3));
    }
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    assert_eq!(after - before, 0, "the step allocated");
    assert!(x.is_finite());
}

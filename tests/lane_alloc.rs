//! Steady state allocates nothing: after the first frame, measuring the lane and running the
//! whole pipeline (lane + control) makes no heap allocation at all. Counted with a global
//! allocator wrapper, so this test binary holds only this test.

use rccar::config::Config;
use rccar::pipeline::Pipeline;
use rccar::timing::{NoTimer, StageTimes};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
}
#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn no_allocation_per_frame() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let frames: Vec<_> = (0..32)
        .map(|i| {
            image::open(root.join(format!("tests/data/lane_sample/frame_{i:03}.png")))
                .unwrap()
                .to_rgb8()
        })
        .collect();
    let cfg = Config::default();
    let mut det = cfg.lane_detector().unwrap();
    let mut pipe = Pipeline::new(&cfg).unwrap();
    let mut t = StageTimes::default();
    det.measure(&frames[0], &mut NoTimer, &mut t);
    pipe.step(&frames[0], 1.0 / 30.0, &mut NoTimer);
    let before = ALLOCS.load(Ordering::SeqCst);
    for f in &frames {
        det.measure(f, &mut NoTimer, &mut t);
        pipe.step(f, 1.0 / 30.0, &mut NoTimer);
    }
    let n = ALLOCS.load(Ordering::SeqCst) - before;
    assert_eq!(n, 0, "{n} allocations over {} frames", frames.len());
}

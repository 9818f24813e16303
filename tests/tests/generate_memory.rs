//! Dataset generation streams: the peak heap of a run does not grow with the
//! sample count once it exceeds one block (an in-memory generator's peak
//! grows in proportion). Measured with a counting global allocator, so this
//! file holds a single test and nothing else allocates meanwhile.

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use tendril::dataset::generate::BLOCK;
use tendril::jobs::dataset::{generate, GenerateRequest};

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: defers to the system allocator; only adds bookkeeping.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let live = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(live, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Peak heap above the starting level while generating `samples` rows.
fn peak_bytes(dir: &Path, samples: usize) -> usize {
    let robot = tendril_tests::robot("seed-4t.toml");
    let req = GenerateRequest {
        samples,
        // Coarse integration: this test is about memory, not accuracy.
        steps: 4,
        ..GenerateRequest::new(&robot, &dir.join(format!("d{samples}.csv")))
    };
    let before = LIVE.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    let side = generate(&req, false, &AtomicBool::new(false)).expect("generation runs");
    assert_eq!(side.count + side.dropped, samples);
    PEAK.load(Ordering::Relaxed) - before
}

#[test]
fn peak_heap_does_not_grow_with_the_sample_count() {
    let dir = tempfile::tempdir().unwrap();
    let one_block = peak_bytes(dir.path(), BLOCK);
    let three_blocks = peak_bytes(dir.path(), 3 * BLOCK);
    // In memory, three blocks would hold three times the rows; streamed, only
    // the 5-byte-per-row split mask grows.
    assert!(
        (three_blocks as f64) < 1.25 * one_block as f64,
        "peak heap {one_block} B for {BLOCK} samples, {three_blocks} B for {}",
        3 * BLOCK
    );
    eprintln!(
        "peak heap: {one_block} B for {BLOCK} samples, {three_blocks} B for {}",
        3 * BLOCK
    );
}

//! Exact JPDA's edge budget bounds the memory of one step (issue 53): the
//! budget is checked inside the loop that stores the edges, so a step whose
//! layer would multiply out to millions of edges gives up before storing
//! more than the budget. The peak is measured by a counting allocator of
//! this test binary (per thread, so parallel tests do not mix).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use algo::jpda::{ClusterProblem, ExactLimit, exact_marginals};

struct Counting;

thread_local! {
    static HELD: Cell<usize> = const { Cell::new(0) };
    static PEAK: Cell<usize> = const { Cell::new(0) };
}

// SAFETY: every call is forwarded to the system allocator unchanged; the
// thread-local counters are `const`-initialised `Cell`s, which never
// allocate.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = HELD.try_with(|h| {
            h.set(h.get() + layout.size());
            let _ = PEAK.try_with(|p| p.set(p.get().max(h.get())));
        });
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        let _ = HELD.try_with(|h| h.set(h.get().saturating_sub(layout.size())));
        // SAFETY: `ptr` came from `alloc` with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Bytes allocated at the peak of `f`, above what was held before it.
fn peak_of<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = HELD.with(Cell::get);
    PEAK.with(|p| p.set(base));
    let out = f();
    (out, PEAK.with(Cell::get) - base)
}

/// Four tracks that all gate the same 64 measurements, every weight 1.
///
/// Every measurement stays live until the last track, so the layer after s
/// tracks holds one node per used set of at most s measurements, Σ_{i≤s}
/// C(64, i), and step s + 1 has Σ_{i≤s} C(64, i)·(65 − i) edges (a miss,
/// or one of the 64 − i measurements still free):
/// step 1: 65; step 2: 65 + 64·64 = 4,161; step 3: 65 + 4,096 + 2,016·63 =
/// 131,169; step 4: 131,169 + 41,664·62 = 2,714,337; in all 2,849,732.
fn four_tracks_on_64_measurements() -> ClusterProblem {
    let gate: Vec<(usize, f64)> = (0..64).map(|j| (j, 1.0)).collect();
    ClusterProblem {
        measurements: 64,
        gates: vec![gate; 4],
        miss: vec![1.0; 4],
        count_factor: None,
    }
}

const ALL_EDGES: u64 = 2_849_732;

#[test]
fn the_budget_admits_exactly_its_number_of_edges() {
    let p = four_tracks_on_64_measurements();
    let m = exact_marginals(&p, ALL_EDGES).expect("exactly within the budget");
    assert_eq!(m.hypotheses, ALL_EDGES);
    assert_eq!(
        exact_marginals(&p, ALL_EDGES - 1),
        Err(ExactLimit::Hypotheses)
    );
}

#[test]
fn a_step_over_the_budget_stops_before_allocating_its_edges() {
    let p = four_tracks_on_64_measurements();
    // Steps 1–3 hold 135,395 edges: the budget lets them through and stops
    // step 4, which alone would store 2,714,337 edges of 12 bytes (32 MB,
    // more with the vector's doubling).
    let budget = 200_000u64;
    let (result, peak) = peak_of(|| exact_marginals(&p, budget));
    assert_eq!(result, Err(ExactLimit::Hypotheses));
    // What the budget allows: 200,000 edges of 12 bytes, the 43,745 nodes
    // of layer 3 (a 32-byte key, an 8-byte weight, a hash-map slot), the
    // vectors' doubling: well under 100 bytes per edge of the budget
    // (measured: 10.8 MB; 81.5 MB when the budget was checked between
    // steps).
    let bound = 100 * budget as usize;
    assert!(
        peak < bound,
        "peak {peak} bytes, over {bound}: the budget did not bound the step"
    );
}

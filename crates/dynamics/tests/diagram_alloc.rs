//! A diagram evaluates inside the allocation-free step loop (issue 12, "Performance"): the
//! number of heap allocations of a whole playback does not depend on the number of steps, for
//! the unit with SEXS and STAB3 as diagrams as for the built-in unit. (Initialisation allocates;
//! halving the step doubles the steps and must not add a single allocation.)

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::PathBuf;

use itaipu_dynamics::event::Event;
use itaipu_dynamics::integrate::Method;
use itaipu_dynamics::simulate::{simulate_pq, PreparedEvent, SimOptions};
use itaipu_dynamics::unit_file::read_unit;

struct Counting;

thread_local! {
    /// Allocations made by this thread: the playback runs on the test's thread, and the test
    /// harness's own threads (output capture, the timer) allocate when they like, which made a
    /// process-wide count flaky on a loaded machine.
    static ALLOCS: Cell<usize> = const { Cell::new(0) };
}

fn count_one() {
    // `try_with`: the thread-local may already be gone while a thread exits.
    let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        count_one();
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        count_one();
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static A: Counting = Counting;

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data")
        .join(rel)
}

#[test]
fn allocations_of_a_playback_do_not_grow_with_the_number_of_steps() {
    let ev = Event::from_toml_file(&data("itaipu/event.toml")).unwrap();
    let prepared = PreparedEvent::new(&ev);
    for file in ["itaipu/unit.toml", "diagrams/unit_itaipu_diagrams.toml"] {
        let mut unit = read_unit(&data(file)).unwrap();
        let mut count = |h: f64| {
            let opts = SimOptions {
                method: Method::Rk4 { h },
            };
            // One run first: anything allocated once per unit (caches) is not counted.
            simulate_pq(&mut unit, &prepared, &opts).unwrap();
            let before = ALLOCS.with(Cell::get);
            let (p, _) = simulate_pq(&mut unit, &prepared, &opts).unwrap();
            assert!(p.iter().all(|x| x.is_finite()));
            ALLOCS.with(Cell::get) - before
        };
        let (coarse, fine) = (count(2e-3), count(1e-3));
        println!("{file}: {coarse} allocations at 2 ms, {fine} at 1 ms");
        assert_eq!(
            coarse, fine,
            "{file}: the step loop allocates ({coarse} allocations at 2 ms, {fine} at 1 ms)"
        );
    }
}

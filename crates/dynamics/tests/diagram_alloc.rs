//! A diagram evaluates inside the allocation-free step loop (issue 12, "Performance"): the
//! number of heap allocations of a whole playback does not depend on the number of steps, for
//! the unit with SEXS and STAB3 as diagrams as for the built-in unit. (Initialisation allocates;
//! halving the step doubles the steps and must not add a single allocation.)

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use itaipu_dynamics::event::Event;
use itaipu_dynamics::integrate::Method;
use itaipu_dynamics::simulate::{simulate_pq, PreparedEvent, SimOptions};
use itaipu_dynamics::unit_file::read_unit;

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
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
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
            let before = ALLOCS.load(Ordering::Relaxed);
            let (p, _) = simulate_pq(&mut unit, &prepared, &opts).unwrap();
            assert!(p.iter().all(|x| x.is_finite()));
            ALLOCS.load(Ordering::Relaxed) - before
        };
        let (coarse, fine) = (count(2e-3), count(1e-3));
        println!("{file}: {coarse} allocations at 2 ms, {fine} at 1 ms");
        assert_eq!(
            coarse, fine,
            "{file}: the step loop allocates ({coarse} allocations at 2 ms, {fine} at 1 ms)"
        );
    }
}

//! The hot threads of the running pipeline (ingest, estimator, RSI loop)
//! allocate nothing after warm-up: the real daemon threads against the mock
//! KR C4 and the simulated tracker on loopback, every allocation counted
//! by a global allocator on the threads marked hot.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use topspin_core::calib::Calibration;
use topspin_daemon::runtime::THREAD_START_HOOK;
use topspin_sim::demo::{DemoConfig, run};

struct Counting;

static COUNTING: AtomicBool = AtomicBool::new(false);
static HOT_ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    static HOT: Cell<bool> = const { Cell::new(false) };
}

fn count() {
    if COUNTING.load(Ordering::Relaxed) && HOT.try_with(|h| h.get()).unwrap_or(false) {
        HOT_ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: forwards to the system allocator unchanged; only counts.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn mark_hot(role: &'static str) {
    if matches!(role, "ingest" | "estimator" | "rsi") {
        HOT.with(|h| h.set(true));
    }
}

#[test]
fn hot_threads_allocate_nothing_after_warm_up() {
    THREAD_START_HOOK.set(mark_hot).unwrap();
    // Count from the second ball on (launches every 1.5 s from 0.5 s).
    let timer = std::thread::spawn(|| {
        std::thread::sleep(std::time::Duration::from_millis(2500));
        COUNTING.store(true, Ordering::SeqCst);
    });
    let cfg = DemoConfig { balls: 5, ..DemoConfig::default() };
    let report = run(&cfg, &Calibration::default_cell()).unwrap();
    COUNTING.store(false, Ordering::SeqCst);
    timer.join().unwrap();
    assert!(report.rsi_cycles > 1500, "{} RSI cycles", report.rsi_cycles);
    assert!(report.latency_us.obs_to_plan.n > 100, "only {} plans", report.latency_us.obs_to_plan.n);
    assert_eq!(HOT_ALLOCATIONS.load(Ordering::SeqCst), 0, "allocations on the hot threads");
}

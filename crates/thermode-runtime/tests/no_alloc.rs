//! The control loop does not allocate per tick: a counting global allocator counts the allocations made on the
//! loop's thread (marked by the engine factory, which runs there) while it ticks five render pipelines on the
//! simulated display with a recorder feed attached, through several statistics refreshes. Commands are not per-tick
//! work and are left out.
#![allow(unsafe_code)] // a counting global allocator needs `unsafe impl GlobalAlloc`

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::sync_channel;
use std::sync::Arc;
use std::time::{Duration, Instant};

use thermode_device::{DefaultFinger, DeviceConfig, SimulatedDisplay};
use thermode_pipeline::{ControllerKind, PipelineConfig};
use thermode_platform::ManualClock;
use thermode_runtime::engine::pipeline_engines;
use thermode_runtime::{EngineFactory, LoopConfig, LoopHandle, TickRecord};

thread_local! {
    static ON_LOOP_THREAD: Cell<bool> = const { Cell::new(false) };
}

static LOOP_ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

struct Counting;

// SAFETY: every call is forwarded unchanged to the system allocator; the counter only observes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if ON_LOOP_THREAD.with(Cell::get) {
            LOOP_ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if ON_LOOP_THREAD.with(Cell::get) {
            LOOP_ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

const PERIOD_S: f64 = 0.01;

#[test]
fn steady_ticks_allocate_nothing_on_the_loop_thread() {
    let pipelines = pipeline_engines(PipelineConfig::new(DeviceConfig::default(), ControllerKind::Model));
    let marking: EngineFactory = Box::new(move |count| {
        ON_LOOP_THREAD.with(|flag| flag.set(true));
        pipelines(count)
    });
    let display = SimulatedDisplay::<DefaultFinger>::fingertips(&DeviceConfig::default(), 5, 3).expect("display");
    let (feed, records) = sync_channel::<TickRecord>(1 << 14);
    let clock = Arc::new(ManualClock::new());
    let handle = LoopHandle::spawn(
        LoopConfig::default(),
        Box::new(display),
        marking,
        clock.clone(),
        vec![feed],
        Arc::default(),
    )
    .expect("loop");
    let run_to = |k: u64| {
        clock.set(k as f64 * PERIOD_S);
        let want = k as f64 * PERIOD_S;
        let start = Instant::now();
        while handle.snapshot().time_s < want {
            assert!(start.elapsed() < Duration::from_secs(10), "tick {k} did not run");
            std::thread::sleep(Duration::from_micros(200));
        }
    };
    assert!(
        (0..2000).any(|_| {
            std::thread::sleep(Duration::from_millis(5));
            handle.snapshot().stats.ticks >= 1
        }),
        "first tick"
    );
    for k in 1..=150 {
        run_to(k); // warm-up: first statistics refresh, lazily sized buffers
    }
    let before = LOOP_ALLOCATIONS.load(Ordering::Relaxed);
    assert!(
        before > 0,
        "the counter must see the loop thread (building the pipelines allocates)"
    );
    for k in 151..=450 {
        run_to(k); // three more seconds: three statistics refreshes, 300 records
    }
    let during = LOOP_ALLOCATIONS.load(Ordering::Relaxed) - before;
    let received = records.try_iter().count();
    assert!(received >= 450, "records received: {received}");
    assert_eq!(during, 0, "allocations on the loop thread during 300 steady ticks");
}

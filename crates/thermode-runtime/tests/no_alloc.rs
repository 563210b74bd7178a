//! The control loop does not allocate per tick: a counting global allocator counts the allocations made on the
//! loop's thread (marked by the engine factory, which runs there) while it ticks five render pipelines on the
//! simulated display with a recorder feed attached, through several statistics refreshes; and while a stimulus
//! program runs on every channel through its segments. Commands are not per-tick work and are left out. Each test
//! counts its own loop thread (a mark of its own), so the tests may run in parallel.
#![allow(unsafe_code)] // a counting global allocator needs `unsafe impl GlobalAlloc`

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::Arc;
use std::time::{Duration, Instant};

use thermode_device::{DefaultFinger, DeviceConfig, SimulatedDisplay};
use thermode_pipeline::{ControllerKind, PipelineConfig};
use thermode_platform::ManualClock;
use thermode_runtime::engine::pipeline_engines;
use thermode_runtime::program::{Program, Segment};
use thermode_runtime::{Command, EngineFactory, LoopConfig, LoopHandle, Owner, TickRecord};

thread_local! {
    /// Which test's loop thread this is (0: none).
    static ON_LOOP_THREAD: Cell<usize> = const { Cell::new(0) };
}

/// Allocations per marked loop thread (index: the mark).
static LOOP_ALLOCATIONS: [AtomicU64; 3] = [const { AtomicU64::new(0) }; 3];

/// Counts one allocation of the calling thread, if it is a marked loop thread.
fn count_allocation() {
    let mark = ON_LOOP_THREAD.with(Cell::get);
    if mark > 0 {
        LOOP_ALLOCATIONS[mark].fetch_add(1, Ordering::Relaxed);
    }
}

struct Counting;

// SAFETY: every call is forwarded unchanged to the system allocator; the counter only observes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count_allocation();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count_allocation();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

const PERIOD_S: f64 = 0.01;

/// A loop of five render pipelines on the simulated display, on a manual clock, its thread marked `mark`; its
/// recorder feed's receiving end; and a function running it to tick `k`.
fn marked_loop(mark: usize) -> (LoopHandle, Receiver<TickRecord>, Arc<ManualClock>) {
    let pipelines = pipeline_engines(PipelineConfig::new(DeviceConfig::default(), ControllerKind::Model));
    let marking: EngineFactory = Box::new(move |count| {
        ON_LOOP_THREAD.with(|flag| flag.set(mark));
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
    assert!(
        (0..2000).any(|_| {
            std::thread::sleep(Duration::from_millis(5));
            handle.snapshot().stats.ticks >= 1
        }),
        "first tick"
    );
    (handle, records, clock)
}

/// Runs the loop of `handle` on `clock` to tick `k` (every tick of `PERIOD_S`).
fn run_to(handle: &LoopHandle, clock: &ManualClock, k: u64) {
    clock.set(k as f64 * PERIOD_S);
    let want = k as f64 * PERIOD_S;
    let start = Instant::now();
    while handle.snapshot().time_s < want {
        assert!(start.elapsed() < Duration::from_secs(10), "tick {k} did not run");
        std::thread::sleep(Duration::from_micros(200));
    }
}

#[test]
fn steady_ticks_allocate_nothing_on_the_loop_thread() {
    let (handle, records, clock) = marked_loop(1);
    let run_to = |k: u64| run_to(&handle, &clock, k);
    let allocations = || LOOP_ALLOCATIONS[1].load(Ordering::Relaxed);
    for k in 1..=150 {
        run_to(k); // warm-up: first statistics refresh, lazily sized buffers
    }
    let before = allocations();
    assert!(
        before > 0,
        "the counter must see the loop thread (building the pipelines allocates)"
    );
    for k in 151..=450 {
        run_to(k); // three more seconds: three statistics refreshes, 300 records
    }
    let during = allocations() - before;
    let received = records.try_iter().count();
    assert!(received >= 450, "records received: {received}");
    assert_eq!(during, 0, "allocations on the loop thread during 300 steady ticks");
}

#[test]
fn a_running_program_allocates_nothing_per_tick() {
    let (handle, _records, clock) = marked_loop(2);
    let run_to = |k: u64| run_to(&handle, &clock, k);
    let allocations = || LOOP_ALLOCATIONS[2].load(Ordering::Relaxed);
    for k in 1..=50 {
        run_to(k);
    }
    // On every channel: a ramp until a response (none comes: it runs to its end), a hold, a step, a long hold.
    let limits = handle.stimulus_limits();
    let segments = vec![
        Segment::Ramp {
            to_c: 31.0,
            rate_c_per_s: 4.0,
            until_response: true,
        },
        Segment::Hold {
            hold_s: 0.3,
            until_response: false,
        },
        Segment::Step { to_c: 33.0 },
        Segment::Hold {
            hold_s: 60.0,
            until_response: false,
        },
    ];
    let programs = (0..5)
        .map(|channel| {
            (
                channel,
                Program::new(channel, segments.clone(), &limits).expect("program"),
            )
        })
        .collect();
    let answer = handle
        .commands()
        .request(Command::Program {
            programs,
            owner: Owner::Script,
        })
        .expect("queued");
    run_to(51);
    answer.blocking_recv().expect("answered").expect("the program runs");
    run_to(55); // the command's tick is behind us
    let before = allocations();
    for k in 56..=250 {
        run_to(k); // the ramp's end, the hold, the step, into the long hold: every kind of segment change
    }
    let during = allocations() - before;
    let segments: Vec<Option<usize>> = handle.snapshot().channels.iter().map(|c| c.program.segment).collect();
    assert_eq!(segments, vec![Some(3); 5], "every channel reached its last segment");
    assert_eq!(
        during, 0,
        "allocations on the loop thread during 195 ticks of a program"
    );
}

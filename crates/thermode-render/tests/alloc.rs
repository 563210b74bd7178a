//! The pipeline's tick never allocates: a counting global allocator (per thread) sees no allocation during
//! thousands of ticks of every renderer and controller, in air, in contact, after a material change, in direct mode,
//! on a refused time step and under a latched fault. (The plant, which is not part of the tick, is stepped outside
//! the counted region.)
#![allow(unsafe_code)] // a counting global allocator needs `unsafe impl GlobalAlloc`

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use common::{material, spec, Loop};
use thermode_device::Device;
use thermode_pipeline::{ControllerKind, RendererKind, ShippedDisplay, Stimulus};

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

/// `n` ticks, counting the allocations inside `ChannelPipeline::tick` only.
fn counted_ticks(lp: &mut Loop, n: usize, dt_s: f64) -> usize {
    let mut count = 0;
    for _ in 0..n {
        let reading = lp.plant.read(0).unwrap_or_else(|e| panic!("{e}"));
        let now_s = lp.now_s();
        let before = allocations();
        let (drive, telemetry) = lp.pipeline.tick(now_s, dt_s, &reading);
        count += allocations() - before;
        std::hint::black_box(telemetry);
        lp.plant.apply(0, &drive).unwrap_or_else(|e| panic!("{e}"));
        for _ in 0..lp.substeps {
            lp.plant.advance(lp.dt_s / lp.substeps as f64);
        }
        lp.ticks += 1;
    }
    count
}

#[test]
fn a_tick_never_allocates() {
    // The counter itself counts.
    let before = allocations();
    std::hint::black_box(vec![0u8; 16]);
    assert_eq!(allocations(), before + 1, "the counting allocator missed an allocation");
    let gains = ShippedDisplay::Default.gains().unwrap_or_else(|e| panic!("{e}"));
    for controller in [ControllerKind::Pid(gains), ControllerKind::Model] {
        for renderer in [RendererKind::Fv, RendererKind::Kron] {
            let mut s = spec(ShippedDisplay::Default, controller, "aluminium");
            s.pipeline.renderer = renderer;
            let mut lp = Loop::new(&s);
            let dt_s = lp.dt_s;
            let what = format!("{} {renderer:?}", controller.name());
            assert_eq!(counted_ticks(&mut lp, 300, dt_s), 0, "{what}: in air");
            let touch = |name: &str| Stimulus::Touch {
                material: material(name),
                object_c: 23.0,
            };
            lp.pipeline
                .set_stimulus(touch("aluminium"))
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(counted_ticks(&mut lp, 1000, dt_s), 0, "{what}: touching aluminium");
            lp.pipeline
                .set_stimulus(touch("wood"))
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(counted_ticks(&mut lp, 500, dt_s), 0, "{what}: after the change to wood");
            let direct = Stimulus::Direct {
                temp_c: 38.0,
                rate_c_per_s: 5.0,
            };
            lp.pipeline.set_stimulus(direct).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(counted_ticks(&mut lp, 500, dt_s), 0, "{what}: direct");
            assert_eq!(counted_ticks(&mut lp, 5, f64::NAN), 0, "{what}: refused time step");
            assert!(
                lp.pipeline.envelope().fault().is_some(),
                "{what}: the NaN step latched nothing"
            );
            assert_eq!(counted_ticks(&mut lp, 200, dt_s), 0, "{what}: under a latched fault");
        }
    }
}

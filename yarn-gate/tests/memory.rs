//! A fabric over the memory cap is refused by every backend's `load`, with
//! `OutOfMemory` naming both figures, and the fabric loaded before stays
//! loaded. Its own test binary, since the cap (`limit_memory`) holds for
//! the whole process.

use yarn_backend_cpu::{Rayon, Reference, Serial};
use yarn_backend_wgpu::{Mode, Wgpu, testing};
use yarn_model::{Backend, BackendError, Params};
use yarn_topology::{Chart, Fabric, Geometry, TopologyError, limit_memory};

fn fabric(w: usize, h: usize) -> Fabric {
    Fabric::from_chart(&Chart::stockinette(w, h).expect("a valid size"), &Geometry::default()).expect("a valid chart")
}

/// Load a 2x2 patch, cap the memory at 64 KiB, and try a 32x32 one.
fn refuses_past_the_cap(mut backend: impl Backend, small: &Fabric, large: &Fabric) {
    let name = backend.name();
    backend.load(small, &Params::default()).expect("the small patch loads");
    backend.advance(10).expect("and runs");
    let before = backend.state().expect("and reads back");
    limit_memory(Some(64 << 10));
    let refused = backend.load(large, &Params::default());
    limit_memory(None);
    match refused {
        Err(BackendError::Topology(TopologyError::OutOfMemory { what, needed, available })) => {
            assert_eq!(available, 64 << 10, "{name}");
            assert!(needed > available, "{name}: {needed} bytes");
            assert!(what.contains("arrays"), "{name}: {what}");
        }
        other => panic!("{name}: expected OutOfMemory, got {other:?}"),
    }
    assert_eq!(backend.state().expect("still loaded"), before, "{name}: the refused load lost the fabric before it");
    backend.advance(10).expect("the fabric before runs on");
}

#[test]
fn every_backend_refuses_a_fabric_over_the_memory_cap_and_keeps_the_last() {
    // Built before the cap: the fabric's own check would refuse it first.
    let (small, large) = (fabric(2, 2), fabric(32, 32));
    refuses_past_the_cap(Serial::<f32>::new(), &small, &large);
    refuses_past_the_cap(Serial::<f64>::new(), &small, &large);
    refuses_past_the_cap(Rayon::with_threads(2).expect("a pool of 2"), &small, &large);
    refuses_past_the_cap(Reference::<f32>::new(), &small, &large);
    if let Some(gpu) = testing::shared_gpu() {
        refuses_past_the_cap(Wgpu::with_gpu(gpu, Mode::Gather), &small, &large);
    }
}

//! Criterion benches of the hot paths, so a regression shows up as a diff:
//! the force accumulation and substep of `Serial`, the `Rayon` substep, and
//! the element-by-element `Reference` accumulation they are checked
//! against, on the 16x16 gate patch and a 64x64 patch.

#![allow(missing_docs, reason = "criterion's macros generate undocumented items")]

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use yarn_backend_cpu::{Rayon, Serial};
use yarn_model::{Backend, Model, Params, State, step};
use yarn_topology::{Chart, Fabric, Geometry};

fn patch(side: usize) -> Fabric {
    Fabric::from_chart(&Chart::stockinette(side, side).expect("valid size"), &Geometry::default()).expect("valid chart")
}

fn passes(c: &mut Criterion) {
    let mut group = c.benchmark_group("hot paths");
    for side in [16, 64] {
        let fabric = patch(side);
        group.throughput(Throughput::Elements(fabric.node_count() as u64));

        let model = Model::<f32>::new(&fabric, &Params::default()).expect("valid params");
        let state = State::<f32>::at_rest(&fabric);
        let mut forces = Vec::new();
        group.bench_function(BenchmarkId::new("reference-f32 accumulate_forces", side), |b| {
            b.iter(|| step::accumulate_forces(&model, &state.positions, &mut forces));
        });

        let mut serial = Serial::<f32>::new();
        serial.load(&fabric, &Params::default()).expect("load");
        group.bench_function(BenchmarkId::new("serial-f32 forces", side), |b| {
            b.iter(|| serial.compute_forces(&mut forces).expect("forces"));
        });
        group.bench_function(BenchmarkId::new("serial-f32 substep", side), |b| {
            b.iter(|| serial.advance(1).expect("advance"));
        });

        let mut rayon = Rayon::new();
        rayon.load(&fabric, &Params::default()).expect("load");
        group
            .bench_function(BenchmarkId::new("rayon substep", side), |b| b.iter(|| rayon.advance(1).expect("advance")));
    }
    group.finish();
}

criterion_group!(benches, passes);
criterion_main!(benches);

//! IK per pose, all solutions, on the chain shapes that matter: table-table, head-head,
//! nutating (non-orthogonal) and the 3-rotary/2-linear machine. `cargo bench --bench ik`.

use criterion::{Criterion, criterion_group, criterion_main};
use kinepost::kinematics::{IkOptions, Joints, Pose, Setup, Solutions, Vec3, fk, ik_into};
use kinepost::machines::Library;
use std::hint::black_box;

fn poses(m: &kinepost::kinematics::Machine, setup: &Setup, n: usize) -> Vec<Pose> {
    // Deterministic spread of joints within travel, mapped to poses by FK.
    let mut s: u64 = 0x9E3779B97F4A7C15;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            let mut j = Joints::default();
            for i in 0..3 {
                if let Some(l) = &m.linears[i] {
                    j.linear[i] = l.min + (l.max - l.min) * next();
                }
            }
            for (i, r) in m.rotaries.iter().enumerate() {
                let (lo, hi) = r.limits.unwrap_or((-std::f64::consts::PI, std::f64::consts::PI));
                j.rotary[i] = lo + (hi - lo) * next();
            }
            fk(m, &j, setup)
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let lib = Library::load_dir(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/machines"))).unwrap();
    let mut g = c.benchmark_group("ik_per_pose");
    for id in [
        "spinner-u5-620",
        "fryer-5x-45",
        "dmu-nutating-45",
        "dmg-dmc75v",
        "htm50200-horizontal",
        "propeller-3r2l",
    ] {
        let m = lib.get(id).unwrap().machine.clone();
        let setup = Setup::new(m.default_tool_length, Vec3::zeros());
        let ps = poses(&m, &setup, 1024);
        let opt = IkOptions::default();
        let mut i = 0;
        let mut out = Solutions::new();
        g.bench_function(id, |b| {
            b.iter(|| {
                i = (i + 1) & 1023;
                let _ = ik_into(&m, black_box(&ps[i]), &setup, &opt, &mut out);
                black_box(out.len())
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

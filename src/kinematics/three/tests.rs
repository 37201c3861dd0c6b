//! The resultant against the scan it replaces, on random 3-rotary machines no one designed and on
//! the shipped one: every root the scan finds, the resultant finds, and the pose's own joints are
//! always among the roots.

use super::{Residual, Trig, contract, contract_outer, resultant_roots, scan};
use crate::kinematics::model::Shape;
use crate::kinematics::model::controlled_point_cs;
use crate::kinematics::subproblem::{Cs, FreeAngle};
use crate::kinematics::{Joints, Linear, Machine, MachineSpec, Mount, Rotary, Setup, Units, Vec3, fk, wrap};

/// A whole turn, in radians.
const TURN: (f64, f64) = (-std::f64::consts::PI, std::f64::consts::PI);

/// xorshift: deterministic, so a failure names its case.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
    fn unit(&mut self) -> Vec3 {
        loop {
            let v = Vec3::new(self.range(-1.0, 1.0), self.range(-1.0, 1.0), self.range(-1.0, 1.0));
            if (0.1..1.0).contains(&v.norm()) {
                return v.normalize();
            }
        }
    }
}

fn random_machine(rng: &mut Rng) -> Option<Machine> {
    let missing = (rng.next() * 3.0) as usize;
    let lin = || {
        Some(Linear {
            min: -2000.0,
            max: 2000.0,
            max_feed: None,
            max_accel: None,
        })
    };
    let mut linears = [lin(), lin(), lin()];
    linears[missing] = None;
    let tables = (rng.next() * 4.0) as usize; // 0..=3 of the rotaries turn the table
    let rotaries = (0..3)
        .map(|i| Rotary {
            name: ['A', 'B', 'C'][i],
            mount: if i < tables { Mount::Table } else { Mount::Head },
            axis: rng.unit(),
            pivot: Vec3::new(rng.range(-300.0, 300.0), rng.range(-300.0, 300.0), rng.range(-300.0, 300.0)),
            limits: None,
            max_feed: None,
            max_accel: None,
            angle_error: None,
        })
        .collect();
    Machine::new(MachineSpec {
        id: "random".into(),
        name: "random".into(),
        units: Units::Mm,
        controller: "fanuc".into(),
        description: String::new(),
        linears,
        rotaries,
        default_tool_length: 100.0,
    })
    .ok()
}

/// The chain of `machines/propeller-3r2l.toml` (kinematics reads no files).
fn propeller() -> Machine {
    let lin = |lim: f64| {
        Some(Linear {
            min: -lim,
            max: lim,
            max_feed: None,
            max_accel: None,
        })
    };
    let rot = |name, mount, axis: [f64; 3], pivot: [f64; 3]| Rotary {
        name,
        mount,
        axis: axis.into(),
        pivot: pivot.into(),
        limits: None,
        max_feed: None,
        max_accel: None,
        angle_error: None,
    };
    Machine::new(MachineSpec {
        id: "propeller-3r2l".into(),
        name: "propeller".into(),
        units: Units::Mm,
        controller: "fanuc".into(),
        description: String::new(),
        linears: [None, lin(1500.0), lin(800.0)],
        rotaries: vec![
            rot('C', Mount::Table, [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]),
            rot('A', Mount::Head, [0.0, 1.0, 0.0], [60.0, 0.0, 350.0]),
            rot('B', Mount::Head, [1.0, 0.0, 0.0], [0.0, 0.0, 150.0]),
        ],
        default_tool_length: 100.0,
    })
    .unwrap()
}

/// (scan's roots, resultant's roots or None, the outer angle of the joints that made the pose,
/// the scan's roots where the inner pair cannot reach the orientation).
fn both(m: &Machine, j: &Joints, setup: &Setup) -> (Vec<(f64, i8)>, Option<Vec<(f64, i8)>>, f64, usize) {
    let Shape::Three { s0, pair, missing, form } = &m.chain.shape else {
        panic!("not a 3-rotary chain")
    };
    let pose = fk(m, j, setup);
    let u = pose.axis;
    let p_w = pose.tip + setup.work_offset;
    let r = Residual {
        m,
        s0,
        pair,
        missing: *missing,
        u: &u,
        terms: form.at(&p_w, setup.tool_length),
        free: FreeAngle(0.0),
    };
    let scale = 1.0 + p_w.norm() + setup.tool_length.abs();
    let mut old = scan::roots(&r, scale).map(|v| v.to_vec()).unwrap_or_default();
    let n = old.len();
    old.retain(|&(a, _)| pair.meet(&r.inner(a)).reach >= -1e-14);
    let new = resultant_roots(&r, scale).map(|v| v.iter().map(|&(a, _, sg)| (a, sg)).collect());
    let bogus = n - old.len();
    (old, new, j.rotary[m.chain.seq[0]], bogus)
}

fn has(roots: &[(f64, i8)], a: f64, sg: Option<i8>) -> bool {
    roots
        .iter()
        .any(|&(b, s)| wrap(a - b).abs() < 1e-6 && sg.is_none_or(|sg| s == sg))
}

/// Counts of (cases, resultant answered, roots the scan found, found by both, resultant only,
/// the scan's roots that are none); the rotaries drawn from `travel` (radians).
fn compare(m: &Machine, rng: &mut Rng, cases: usize, travel: [(f64, f64); 3], tally: &mut [usize; 6]) {
    for _ in 0..cases {
        let mut j = Joints::default();
        for i in 0..3 {
            if m.linears[i].is_some() {
                j.linear[i] = rng.range(-800.0, 800.0);
            }
        }
        for (a, &(lo, hi)) in j.rotary.iter_mut().zip(&travel) {
            *a = rng.range(lo, hi);
        }
        check(m, &j, tally);
    }
}

/// The pose of joints `j`: the resultant finds its own outer angle and every root the scan
/// finds, and every solution reproduces it; counted into `tally` as [`compare`] says.
fn check(m: &Machine, j: &Joints, tally: &mut [usize; 6]) {
    let setup = Setup::new(m.default_tool_length, Vec3::zeros());
    let (old, new, outer, bogus) = both(m, j, &setup);
    tally[0] += 1;
    tally[5] += bogus;
    let Some(new) = new else { return };
    tally[1] += 1;
    assert!(
        has(&new, outer, None),
        "{}: the pose's own outer angle {outer} is not among {new:?} (scan: {old:?}), joints {j:?}",
        m.id
    );
    for &(a, sg) in &old {
        tally[2] += 1;
        assert!(
            has(&new, a, Some(sg)),
            "{}: the scan's root ({a}, {sg}) is missing from {new:?}, joints {j:?}, machine {:?}",
            m.id,
            m.rotaries
        );
        tally[3] += 1;
    }
    tally[4] += new.iter().filter(|&&(a, sg)| !has(&old, a, Some(sg))).count();
    // Every solution the solver returns reproduces the pose.
    let pose = fk(m, j, &setup);
    let scale = 1.0 + pose.tip.norm() + setup.tool_length;
    for s in crate::kinematics::ik(m, &pose, &setup, &crate::kinematics::IkOptions::default()).unwrap() {
        let p = fk(m, &s.joints, &setup);
        let (dp, da) = ((p.tip - pose.tip).norm(), (p.axis - pose.axis).norm());
        assert!(
            dp <= 1e-12 * scale && da <= 1e-12,
            "{}: {s:?} misses the pose by {dp}, {da}; joints {j:?}, linears {:?}, rotaries {:?}",
            m.id,
            m.linears.each_ref().map(|l| l.is_some()),
            m.rotaries
        );
    }
}

#[test]
fn the_resultant_finds_every_root_the_scan_finds() {
    // KINEPOST_SOAK_SEED=n draws other machines and poses.
    let seed = std::env::var("KINEPOST_SOAK_SEED").ok().and_then(|v| v.parse::<u64>().ok());
    let mut rng = Rng(0x2545F4914F6CDD1D ^ seed.unwrap_or(0).wrapping_mul(0x9E3779B97F4A7C15));
    let mut tally = [0usize; 6];
    // KINEPOST_SOAK=k runs k times as many (a soak, not CI's share).
    let k: usize = std::env::var("KINEPOST_SOAK").ok().and_then(|v| v.parse().ok()).unwrap_or(1);
    let mut machines = 0;
    while machines < 60 * k {
        let Some(m) = random_machine(&mut rng) else { continue };
        if !matches!(m.chain.shape, Shape::Three { .. }) {
            continue;
        }
        machines += 1;
        compare(&m, &mut rng, 25, [TURN; 3], &mut tally);
    }
    let d = f64::to_radians;
    compare(&propeller(), &mut rng, 500 * k, [TURN; 3], &mut tally);
    // Within the profile's travel; and with B within 3° of ±90°, where the tool lies along A (the
    // inner axis) for some C, and close roots gather (the cases that found two gaps).
    compare(&propeller(), &mut rng, 500 * k, [TURN, (d(-120.0), d(120.0)), (d(-100.0), d(100.0))], &mut tally);
    compare(&propeller(), &mut rng, 250 * k, [TURN, (d(-120.0), d(120.0)), (d(87.0), d(93.0))], &mut tally);
    compare(&propeller(), &mut rng, 250 * k, [TURN, (d(-120.0), d(120.0)), (d(-93.0), d(-87.0))], &mut tally);
    eprintln!(
        "cases {}, resultant answered {}, scan roots {}, also found {}, resultant only {}, scan's roots in an unreachable gap {}",
        tally[0], tally[1], tally[2], tally[3], tally[4], tally[5]
    );
    assert!(tally[1] * 10 >= tally[0] * 9, "the scan answered too often: {tally:?}");
}

#[test]
fn two_roots_on_one_branch_microradians_apart_are_both_found() {
    // Poses the profile's own travel gave (1 in 100 000 each): B near −90°, two roots of f₋
    // 3e-5 and 1.2e-5 rad apart, where the product's rounding could not tell them apart.
    let m = propeller();
    let mut tally = [0usize; 6];
    for (linear, rotary) in [
        ([0.0, -728.0634614002945, -335.9523285179989], [-2.6760457067572943, -1.9567300858593424, -1.5606983370650898]),
        ([0.0, -826.190101812559, -250.0622762929595], [0.002308303649497301, -2.0935446392706036, -1.5419024073980092]),
    ] {
        check(&m, &Joints { linear, rotary }, &mut tally);
    }
    // Both answered by the resultant, and no root of its own beyond the scan's.
    assert_eq!((tally[1], tally[4]), (2, 0), "{tally:?}");
}

#[test]
fn the_form_is_the_chain_turned() {
    // The missing coordinate from the form against the chain turned rotary by rotary, on random
    // machines, tips, tool lengths and rotations (and (cos, sin) off the circle, where the samples
    // read it): the same polynomial, so equal to rounding.
    let mut rng = Rng(0x5DEECE66D);
    let mut machines = 0;
    while machines < 200 {
        let Some(m) = random_machine(&mut rng) else { continue };
        let Shape::Three { missing, form, .. } = &m.chain.shape else { continue };
        machines += 1;
        for _ in 0..50 {
            let p_w = Vec3::new(rng.range(-900.0, 900.0), rng.range(-900.0, 900.0), rng.range(-900.0, 900.0));
            let tool_length = rng.range(0.0, 300.0);
            let cs: [Cs; 3] = std::array::from_fn(|_| Cs { c: rng.range(-1.5, 1.5), s: rng.range(-1.5, 1.5) });
            let mut by_chain_order = [Cs::ZERO; 3];
            for (k, &ri) in m.chain.seq.iter().enumerate() {
                by_chain_order[ri] = cs[k];
            }
            let want = controlled_point_cs(&m.chain.links, &by_chain_order, &p_w, tool_length)[*missing];
            let got = contract(&contract_outer(&form.at(&p_w, tool_length), cs[0]), cs[1], cs[2]);
            let scale = 1.0 + p_w.norm() + tool_length + m.rotaries.iter().map(|r| r.pivot.norm()).sum::<f64>();
            assert!((got - want).abs() <= 1e-13 * scale, "{got} against {want}, machine {m:?}");
        }
    }
}

#[test]
fn a_rotation_off_the_circle_is_polished() {
    // Soak seed 17: the inner pair's (cos, sin) 1.7e-12 off the circle put the tip 4.4e-10 away
    // through a lever of 260 mm, where the missing coordinate and the axis were at rounding.
    let head = |name, axis: [f64; 3], pivot: [f64; 3]| Rotary {
        name,
        mount: Mount::Head,
        axis: Vec3::from(axis),
        pivot: Vec3::from(pivot),
        limits: None,
        max_feed: None,
        max_accel: None,
        angle_error: None,
    };
    let lin = Some(Linear {
        min: -2000.0,
        max: 2000.0,
        max_feed: None,
        max_accel: None,
    });
    let m = Machine::new(MachineSpec {
        id: "seed-17".into(),
        name: "seed-17".into(),
        units: Units::Mm,
        controller: "fanuc".into(),
        description: String::new(),
        linears: [lin.clone(), None, lin],
        rotaries: vec![
            head('A', [0.2554644587564226, -0.6566409438265203, -0.7096200259314169], [299.92002826691146, 87.48773624826077, -219.4857314414133]),
            head('B', [-0.31020079837826, 0.4282318516914217, -0.8487596514222542], [241.12522729401007, 47.61215407084177, -3.633760260418967]),
            head('C', [0.004674002257104746, -0.01987769116748522, -0.9997914938109599], [-151.4475043986951, 216.5611121022729, 252.9963481590321]),
        ],
        default_tool_length: 100.0,
    })
    .unwrap();
    let j = Joints {
        linear: [-351.69716550028767, 0.0, -182.29887670577637],
        rotary: [0.6560245150561692, -1.9937585222941123, 0.12434827673062587],
    };
    check(&m, &j, &mut [0; 6]);
}

#[test]
fn the_isolation_brackets_every_root_and_drops_no_interval_that_holds_one() {
    // g(x) = s ∏ sin((x − rᵢ)/2) over 16 roots in 8 pairs, 1e-6 to 1 rad apart: a trigonometric
    // polynomial of degree 8 whose roots are known, with dips between close roots that the ends
    // of an interval do not show.
    use std::f64::consts::{PI, TAU};
    let mut rng = Rng(0x5EED_1507);
    let mut tally = [0usize; 3];
    for case in 0..3000 {
        let mut roots = [0.0; 16];
        for pair in roots.chunks_mut(2) {
            let a = rng.range(-PI, PI);
            pair[0] = a;
            pair[1] = wrap(a + 10f64.powf(rng.range(-6.0, 0.0)));
        }
        let s = 10f64.powf(rng.range(-3.0, 3.0));
        let poly = Trig::interpolate(|z: Cs| {
            let x = z.angle();
            Some(s * roots.iter().map(|r| (0.5 * (x - r)).sin()).product::<f64>())
        })
        .unwrap();
        // More than 32 roots or unsure stretches: the caller scans f instead.
        let Some(iso) = poly.isolate() else {
            tally[2] += 1;
            continue;
        };
        // A root is found to within the rounding of g over its slope there.
        let near = |x: f64, d: f64, r: f64| wrap(x - r).abs() <= 1e-13 + 16.0 * poly.noise / d.abs();
        let inside = |r: f64, (lo, hi): (f64, f64)| {
            let r = if r < lo { r + TAU } else { r };
            r >= lo - 1e-12 && r <= hi + 1e-12
        };
        for &(x, z, d, lo, hi) in &iso.roots {
            assert!(roots.iter().any(|&r| near(x, d, r)), "case {case}: a root at {x} that g does not have: {roots:?}");
            // Proven monotone there: the bracket holds one root, however close its neighbour (to
            // the rounding of g over its slope at either end).
            let tol = 16.0 * poly.noise / d.abs();
            let held = |e: f64| roots.iter().filter(|&&r| inside(r, (lo - e, hi + e))).count();
            assert!(held(tol) >= 1 && held(-tol) <= 1, "case {case}: ({lo}, {hi}) holds {} roots: {roots:?}", held(0.0));
            assert!((z.c - x.cos()).abs() < 1e-13 && (z.s - x.sin()).abs() < 1e-13, "case {case}: its (cos, sin) is not its angle's");
            assert!(inside(x, (lo, hi)), "case {case}: {x} outside its interval ({lo}, {hi})");
        }
        for &r in &roots {
            let found = iso.roots.iter().any(|&(x, _, d, ..)| near(x, d, r));
            let unsure = iso.unsure.iter().any(|&i| inside(r, i));
            assert!(found || unsure, "case {case}: the root {r} was dropped: {roots:?}");
            tally[usize::from(!found)] += 1;
        }
    }
    // Most roots are bracketed alone; the closest pairs are left to the scan of f as unsure, and
    // so, rarely, is the whole circle.
    assert!(tally[0] > 5 * tally[1] && tally[2] < 30, "{tally:?}");
}


#![allow(clippy::needless_range_loop)]
//! Kinematics against the machine model: FK/IK round trips on every shipped profile (property
//! tests), the seed papers' closed forms, singular, unreachable and angle-error cases.

use crate::common;

use common::machine;

use kinepost::kinematics::{self, IkOptions, Joints, Machine, Pose, Setup, Vec3, angle_between, fk, ik};
use proptest::prelude::*;
use std::f64::consts::{PI, TAU};

const IDS: [&str; 11] = [
    "spinner-u5-620",
    "mikron-ucp710",
    "fryer-5x-45",
    "dmg-dmc75v",
    "htm50200-horizontal",
    "dmu-nutating-45",
    "propeller-3r2l",
    "haas-umc750",
    "vmc-4axis-a",
    "vmc-3axis",
    "linuxcnc-xyzbc-trt",
];

#[test]
fn the_library_ships_every_seed_machine() {
    for id in IDS {
        assert!(common::library().get(id).is_ok(), "{id} missing");
    }
    assert_eq!(common::library().len(), IDS.len());
}

/// Joints drawn uniformly within travel (unbounded rotaries over ±2 turns, to exercise windings)
/// from unit-interval samples.
fn joints_from(m: &Machine, t: &[f64; 6]) -> Joints {
    let mut j = Joints::default();
    for i in 0..3 {
        if let Some(l) = &m.linears[i] {
            j.linear[i] = l.min + (l.max - l.min) * t[i];
        }
    }
    for (i, r) in m.rotaries.iter().enumerate() {
        let (lo, hi) = r.limits.unwrap_or((-2.0 * TAU, 2.0 * TAU));
        j.rotary[i] = lo + (hi - lo) * t[3 + i];
    }
    j
}

fn setup_from(m: &Machine, t: &[f64; 4]) -> Setup {
    let scale = m.units.factor_to(kinematics::Units::Mm).recip();
    Setup::new(
        m.default_tool_length * (0.5 + t[0]),
        Vec3::new(t[1] - 0.5, t[2] - 0.5, t[3] - 0.5) * 200.0 * scale,
    )
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

fn same_joints(m: &Machine, a: &Joints, b: &Joints, tol_len: f64, tol_ang: f64) -> bool {
    (0..3).all(|i| m.linears[i].is_none() || (a.linear[i] - b.linear[i]).abs() <= tol_len)
        && (0..m.rotaries.len())
            .all(|i| wrap(m.rotaries[i].actual(a.rotary[i]) - m.rotaries[i].actual(b.rotary[i])).abs() <= tol_ang)
}

/// Smallest singular value of the FK Jacobian (tip and axis against the machine's joints, with
/// lengths scaled by a typical 100 mm so both halves weigh alike) by central differences.
fn sigma_min(m: &Machine, j: &Joints, setup: &Setup) -> f64 {
    let unit = 100.0 * m.units.factor_to(kinematics::Units::Mm).recip();
    let mut cols: Vec<(bool, usize)> = (0..3).filter(|&i| m.linears[i].is_some()).map(|i| (true, i)).collect();
    cols.extend((0..m.rotaries.len()).map(|i| (false, i)));
    let pose_vec = |j: &Joints| {
        let p = fk(m, j, setup);
        nalgebra::DVector::from_vec(vec![
            p.tip.x / unit,
            p.tip.y / unit,
            p.tip.z / unit,
            p.axis.x,
            p.axis.y,
            p.axis.z,
        ])
    };
    let mut jac = nalgebra::DMatrix::<f64>::zeros(6, cols.len());
    for (c, &(lin, i)) in cols.iter().enumerate() {
        let h = if lin { 1e-5 * unit } else { 1e-5 };
        let (mut a, mut b) = (*j, *j);
        if lin {
            a.linear[i] += h;
            b.linear[i] -= h;
        } else {
            a.rotary[i] += h;
            b.rotary[i] -= h;
        }
        let d = (pose_vec(&a) - pose_vec(&b)) / (2.0 * h / if lin { unit } else { 1.0 });
        jac.set_column(c, &d);
    }
    jac.singular_values()
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min)
        .max(1e-300)
}

fn pose_error(a: &Pose, b: &Pose) -> (f64, f64) {
    ((a.tip - b.tip).norm(), angle_between(&a.axis, &b.axis))
}

/// Tip tolerance: 1e-9 in profile units scaled by the size of the numbers involved.
fn tol_len(m: &Machine, p: &Pose, s: &Setup) -> f64 {
    let pivots: f64 = m.rotaries.iter().map(|r| r.pivot.norm()).sum();
    1e-9 * (1.0 + (p.tip.norm() + s.work_offset.norm() + s.tool_length.abs() + pivots) / 1000.0)
}

fn round_trip(id: &str, t: [f64; 6], s: [f64; 4]) -> Result<(), TestCaseError> {
    let m = machine(id);
    let setup = setup_from(&m, &s);
    let j = joints_from(&m, &t);
    let pose = fk(&m, &j, &setup);
    // A tilted plane's frame: a rotation whose Z is the tool axis.
    let f = kinepost::kinematics::machine_frame(&m, &j.rotary);
    prop_assert!((f.transpose() * f - nalgebra::Matrix3::identity()).norm() < 1e-12 && (f.determinant() - 1.0).abs() < 1e-12);
    prop_assert!((f.column(2) - pose.axis).norm() < 1e-12, "{id}: {f} vs {:?}", pose.axis);
    let mut sols = ik(&m, &pose, &setup, &IkOptions::default()).map_err(|e| TestCaseError::fail(format!("{id}: {e}")))?;
    // At a singular pose the free angle is the caller's: ask with the one we started from.
    if let Some(free) = sols.iter().find_map(|s| s.singular) {
        let opt = IkOptions {
            free_angle: m.rotaries[free].actual(j.rotary[free]),
            ..Default::default()
        };
        sols = ik(&m, &pose, &setup, &opt).map_err(|e| TestCaseError::fail(format!("{id}: {e}")))?;
    }
    let tl = tol_len(&m, &pose, &setup);
    prop_assert!(!sols.is_empty());
    for s in &sols {
        let back = fk(&m, &s.joints, &setup);
        let (dp, da) = pose_error(&back, &pose);
        prop_assert!(dp <= tl && da <= 1e-9, "{id}: solution {s:?} misses pose by {dp} / {da} rad");
    }
    // Joints are only as determined as the pose makes them: near a singular pose, or at a double
    // root of the 3-rotary chain, the Jacobian from joints to pose loses rank and the pose's own
    // rounding (1e-16 relative) moves the joints by ~rounding / σ_min. Require 1e-9 beyond that.
    let sigma = sigma_min(&m, &j, &setup);
    let tol_ang = 1e-9 + 1e-12 / sigma;
    let lever = 1.0 + pose.tip.norm() + setup.tool_length + m.rotaries.iter().map(|r| r.pivot.norm()).sum::<f64>();
    prop_assert!(
        sols.iter()
            .any(|s| same_joints(&m, &s.joints, &j, 1e-7 + lever * tol_ang, tol_ang)),
        "{id}: {j:?} not among {sols:#?}"
    );
    Ok(())
}

/// Random axis (uniform on the sphere) and tip; every solution IK returns must reproduce it.
fn random_pose(id: &str, t: [f64; 3], dir: [f64; 2], s: [f64; 4]) -> Result<(), TestCaseError> {
    let m = machine(id);
    let setup = setup_from(&m, &s);
    let z = 2.0 * dir[0] - 1.0;
    let phi = TAU * dir[1];
    let r = (1.0 - z * z).sqrt();
    let axis = Vec3::new(r * phi.cos(), r * phi.sin(), z);
    let scale = m.units.factor_to(kinematics::Units::Mm).recip();
    let tip = Vec3::new(t[0] - 0.5, t[1] - 0.5, t[2] - 0.5) * 300.0 * scale;
    let pose = Pose { tip, axis };
    match ik(&m, &pose, &setup, &IkOptions::default()) {
        Ok(sols) => {
            // An orientation within the (documented) tolerance of the reachable set is projected
            // onto it; an exactly reachable one is reproduced to 1e-9 (the round trip checks).
            let tol_ang = IkOptions::default().orientation_tolerance + 1e-12;
            for s in &sols {
                let (dp, da) = pose_error(&fk(&m, &s.joints, &setup), &pose);
                prop_assert!(
                    dp <= tol_len(&m, &pose, &setup) && da <= tol_ang,
                    "{id}: {s:?} misses by {dp} / {da}"
                );
            }
        }
        Err(kinematics::Error::Unreachable { miss }) => {
            prop_assert!(miss > 1e-7, "{id}: unreachable with miss {miss}");
            // A claimed miss must be real: no joint setting gets closer. Sample the rotaries.
            let n: usize = 24;
            let nrot = m.rotaries.len().min(2);
            let mut best = f64::INFINITY;
            for k in 0..n.pow(nrot as u32) {
                let mut j = Joints::default();
                for i in 0..nrot {
                    j.rotary[i] = -PI + TAU * ((k / n.pow(i as u32)) % n) as f64 / n as f64;
                }
                best = best.min(angle_between(&fk(&m, &j, &setup).axis, &axis));
            }
            prop_assert!(best >= miss - 1e-6, "{id}: claimed miss {miss} but a sample reaches {best}");
        }
        Err(kinematics::Error::NoSolution { .. }) => prop_assert!(m.rotaries.len() == 3),
        Err(e) => return Err(TestCaseError::fail(format!("{id}: {e}"))),
    }
    Ok(())
}

/// Coordinates up to `MAX_COORD` (scaled by 10^-e): IK returns (it once spun forever in an SVD fed
/// with overflowed numbers), and what it returns is finite.
fn extreme(id: &str, t: [f64; 3], d: [f64; 3], s: [f64; 4], e: i32) -> Result<(), TestCaseError> {
    let m = machine(id);
    let big = kinematics::MAX_COORD / 10f64.powi(e);
    let pose = Pose {
        tip: Vec3::new(t[0], t[1], t[2]) * big,
        axis: Vec3::new(d[0], d[1], d[2] + 1e-3),
    };
    let setup = Setup::new(s[0].abs() * big, Vec3::new(s[1], s[2], s[3]) * big);
    if let Ok(sols) = ik(&m, &pose, &setup, &IkOptions::default()) {
        for sol in sols.iter() {
            prop_assert!(
                sol.joints
                    .linear
                    .iter()
                    .chain(sol.joints.rotary.iter())
                    .all(|v| v.is_finite()),
                "{id}: non-finite solution {sol:?}"
            );
        }
    }
    Ok(())
}

/// `KINEPOST_PROPTEST_SCALE=50` runs fifty times the cases (for soak runs, not CI).
fn cases(n: u32) -> u32 {
    n * std::env::var("KINEPOST_PROPTEST_SCALE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1)
}

macro_rules! profile_props {
    ($($name:ident => $id:literal),* $(,)?) => {
        mod props { use super::*;
        $(
            mod $name { use super::*;
                proptest! {
                    #![proptest_config(ProptestConfig::with_cases(cases(if $id == "propeller-3r2l" { 96 } else { 400 })))]
                    #[test]
                    fn joints_fk_ik_contains_joints(t in prop::array::uniform6(0.0f64..1.0), s in prop::array::uniform4(0.0f64..1.0)) {
                        round_trip($id, t, s)?;
                    }
                    #[test]
                    fn extreme_inputs_return_finite_solutions_or_errors(t in prop::array::uniform3(-1.0f64..1.0), d in prop::array::uniform3(-1.0f64..1.0), s in prop::array::uniform4(-1.0f64..1.0), e in 0i32..10) {
                        extreme($id, t, d, s, e)?;
                    }
                    #[test]
                    fn pose_ik_fk_reproduces_pose(t in prop::array::uniform3(0.0f64..1.0), d in prop::array::uniform2(0.0f64..1.0), s in prop::array::uniform4(0.0f64..1.0)) {
                        random_pose($id, t, d, s)?;
                    }
                }
            }
        )*
        }
    };
}

profile_props! {
    spinner => "spinner-u5-620",
    mikron => "mikron-ucp710",
    fryer => "fryer-5x-45",
    dmg => "dmg-dmc75v",
    htm => "htm50200-horizontal",
    nutating => "dmu-nutating-45",
    propeller => "propeller-3r2l",
    haas => "haas-umc750",
    vmc4 => "vmc-4axis-a",
    vmc3 => "vmc-3axis",
    linuxcnc_trt => "linuxcnc-xyzbc-trt",
}

fn words(m: &Machine, lin: [f64; 3], rot: &[(char, f64)]) -> Joints {
    let mut j = Joints {
        linear: lin,
        ..Default::default()
    };
    for &(n, deg) in rot {
        j.rotary[m.rotary_index(n).unwrap()] = deg.to_radians();
    }
    j
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

/// Spinner U5-620 paper, equations (10)–(15), d = 100.
#[test]
fn spinner_fk_equals_paper_equations_10_to_15() {
    let m = machine("spinner-u5-620");
    let d = 100.0;
    for &(x, y, z, b, c) in &[
        (10.0, 20.0, 30.0, 30.0, 45.0),
        (-120.0, 75.0, -40.0, -95.0, 200.0),
        (0.0, 0.0, 0.0, 110.0, -17.0),
    ] {
        let pose = fk(
            &m,
            &words(&m, [x, y, z], &[('B', b), ('C', c)]),
            &Setup::new(100.0, Vec3::zeros()),
        );
        let (sb, cb, sc, cc) = (
            b.to_radians().sin(),
            b.to_radians().cos(),
            c.to_radians().sin(),
            c.to_radians().cos(),
        );
        let want_axis = [sb * cc, sb * sc, cb];
        let want_tip = [
            x * cb * cc - y * sc + z * sb * cc - d * sb * cc,
            x * cb * sc + y * cc + z * sb * sc - d * sb * sc,
            -x * sb + z * cb - d * cb + d,
        ];
        for k in 0..3 {
            assert!(
                close(pose.axis[k], want_axis[k], 1e-12),
                "axis {k}: {} vs {}",
                pose.axis[k],
                want_axis[k]
            );
            assert!(
                close(pose.tip[k], want_tip[k], 1e-9),
                "tip {k}: {} vs {}",
                pose.tip[k],
                want_tip[k]
            );
        }
        // And the paper's IK (18)–(22) on the positive-B branch agrees with one of ours.
        let sols = ik(&m, &pose, &Setup::new(100.0, Vec3::zeros()), &IkOptions::default()).unwrap();
        assert!(
            sols.iter()
                .any(|s| close(s.joints.linear[0], x, 1e-9) && close(wrap(s.joints.rotary[1] - c.to_radians()), 0.0, 1e-12))
        );
    }
}

/// Fryer 5X-45 thesis, equations (15)–(17) with the calibrated t and J. The thesis' X, Y are the
/// C-axis point: the model's controlled point differs by J + t in x and y. (16) is read with Qy.
#[test]
fn fryer_fk_equals_thesis_equations_15_to_17() {
    let m = machine("fryer-5x-45");
    let (t, j) = ([0.002, 0.001, 0.0], [0.0, 0.0005, 0.0]);
    for &(x, y, z, a, c) in &[
        (1.2, -0.7, -3.1, 25.0, -70.0),
        (-10.0, 4.0, -12.0, -140.0, 200.0),
        (0.0, 0.0, 0.0, 90.0, 0.0),
    ] {
        for tool in [3.0, 1.5] {
            let lt = 5.0 + tool; // L_t = LHO + LLO: pivot distance plus tool length
            let pose = fk(
                &m,
                &words(&m, [x, y, z], &[('A', a), ('C', c)]),
                &Setup::new(tool, Vec3::zeros()),
            );
            let (sa, ca, sc, cc) = (
                a.to_radians().sin(),
                a.to_radians().cos(),
                c.to_radians().sin(),
                c.to_radians().cos(),
            );
            let q = pose.tip;
            let br = j[1] + t[1] * ca - sa * (t[2] - lt);
            let x_th = q.x - cc * (t[0] + j[0]) + sc * br;
            let y_th = q.y - sc * (t[0] + j[0]) - cc * br;
            let z_th = q.z + j[2] - t[1] * sa - ca * (t[2] - lt) - lt;
            assert!(close(x, x_th + j[0] + t[0], 1e-12), "X {x} vs {}", x_th + j[0] + t[0]);
            assert!(close(y, y_th + j[1] + t[1], 1e-12), "Y {y} vs {}", y_th + j[1] + t[1]);
            assert!(close(z, z_th, 1e-12), "Z {z} vs {z_th}");
            // Tool axis K = Rz(C) Rx(A) z, equations (13)–(14).
            assert!((pose.axis - Vec3::new(sa * sc, -sa * cc, ca)).norm() < 1e-12);
        }
    }
}

/// DMG B/C paper, equations (7) and (9) with m = 0 and the S_z the paper omits in P_z;
/// L there is the pivot-to-tip length, 150 + tool length.
#[test]
fn dmg_fk_equals_paper_equations_7_and_9() {
    let m = machine("dmg-dmc75v");
    for &(sx, sy, sz, b, c) in &[
        (12.0, -40.0, 5.0, -60.0, 130.0),
        (-200.0, 100.0, -100.0, 10.0, -300.0),
        (0.0, 0.0, 0.0, -110.0, 0.0),
    ] {
        for tool in [100.0, 37.5] {
            let l = 150.0 + tool;
            let pose = fk(
                &m,
                &words(&m, [sx, sy, sz], &[('B', b), ('C', c)]),
                &Setup::new(tool, Vec3::zeros()),
            );
            let (sb, cb, sc, cc) = (
                b.to_radians().sin(),
                b.to_radians().cos(),
                c.to_radians().sin(),
                c.to_radians().cos(),
            );
            let u = Vec3::new(cc * sb, -sc * sb, cb);
            let p = Vec3::new(
                -cc * sb * l + cc * sx + sc * sy,
                sc * sb * l - sc * sx + cc * sy,
                sz - cb * l + l,
            );
            assert!((pose.axis - u).norm() < 1e-12);
            assert!((pose.tip - p).norm() < 1e-9, "{:?} vs {:?}", pose.tip, p);
        }
    }
}

/// The real NX post's angles for the Haas UMC-750: B = ∓acos(k), C = atan2(j, i) (+180° on the
/// negative-B branch), i.e. both of our branches.
#[test]
fn haas_branches_are_the_nx_posts_formulas() {
    let m = machine("haas-umc750");
    let u = Vec3::new(0.3, -0.4, 0.866).normalize();
    let sols = ik(
        &m,
        &Pose {
            tip: Vec3::new(1.0, 2.0, 0.5),
            axis: u,
        },
        &Setup::new(3.0, Vec3::zeros()),
        &IkOptions::default(),
    )
    .unwrap();
    assert_eq!(sols.len(), 2);
    let b = u.z.acos();
    let c = u.y.atan2(u.x);
    let pos = sols.iter().find(|s| s.joints.rotary[0] > 0.0).unwrap();
    let neg = sols.iter().find(|s| s.joints.rotary[0] < 0.0).unwrap();
    assert!(close(pos.joints.rotary[0], b, 1e-12) && close(wrap(pos.joints.rotary[1] - c), 0.0, 1e-12));
    assert!(close(neg.joints.rotary[0], -b, 1e-12) && close(wrap(neg.joints.rotary[1] - c - PI), 0.0, 1e-12));
    assert_ne!(pos.branch, neg.branch);
}

#[test]
fn vertical_tool_on_a_bc_table_is_singular_with_the_free_angle_chosen_by_the_caller() {
    let m = machine("spinner-u5-620");
    let setup = Setup::new(100.0, Vec3::zeros());
    let pose = Pose {
        tip: Vec3::new(50.0, -20.0, 10.0),
        axis: Vec3::z(),
    };
    for free in [0.0, 1.0, -2.5, 7.0] {
        let sols = ik(
            &m,
            &pose,
            &setup,
            &IkOptions {
                free_angle: free,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(sols.len(), 1, "one family at the singularity");
        let s = sols[0];
        assert_eq!(s.singular, Some(m.rotary_index('C').unwrap()));
        assert!(
            close(s.joints.rotary[1], free, 0.0),
            "free angle kept as given, windings included"
        );
        assert!(close(s.joints.rotary[0], 0.0, 1e-12));
        let (dp, da) = pose_error(&fk(&m, &s.joints, &setup), &pose);
        assert!(dp < 1e-9 && da < 1e-12);
    }
    // Just off the singularity: exact, not singular, and still reproducing the pose.
    let pose = Pose {
        tip: Vec3::new(50.0, -20.0, 10.0),
        axis: Vec3::new(1e-7, 0.0, 1.0).normalize(),
    };
    let sols = ik(&m, &pose, &setup, &IkOptions::default()).unwrap();
    assert_eq!(sols.len(), 2);
    for s in &sols {
        assert!(s.singular.is_none());
        let (dp, da) = pose_error(&fk(&m, &s.joints, &setup), &pose);
        assert!(dp < 1e-9 && da < 1e-12);
    }
}

#[test]
fn head_head_singularity_frees_the_c_head() {
    let m = machine("fryer-5x-45");
    let setup = Setup::new(3.0, Vec3::zeros());
    let pose = Pose {
        tip: Vec3::new(1.0, 1.0, -2.0),
        axis: Vec3::z(),
    };
    let sols = ik(
        &m,
        &pose,
        &setup,
        &IkOptions {
            free_angle: 0.7,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(sols[0].singular, Some(m.rotary_index('C').unwrap()));
    // The calibration offsets make the tip depend on C even here: the linears follow C.
    let (dp, _) = pose_error(&fk(&m, &sols[0].joints, &setup), &pose);
    assert!(dp < 1e-9);
}

#[test]
fn unreachable_orientations_report_their_angular_miss() {
    let setup = Setup::new(100.0, Vec3::zeros());
    // 3-axis: the miss is the tilt.
    let m = machine("vmc-3axis");
    let tilted = Vec3::new(0.0, 3f64.to_radians().sin(), 3f64.to_radians().cos());
    match ik(
        &m,
        &Pose {
            tip: Vec3::zeros(),
            axis: tilted,
        },
        &setup,
        &IkOptions::default(),
    ) {
        Err(kinematics::Error::Unreachable { miss }) => assert!(close(miss.to_degrees(), 3.0, 1e-9)),
        other => panic!("{other:?}"),
    }
    // 4-axis A table: tilting about y is out of reach, about x is fine.
    let m = machine("vmc-4axis-a");
    let about_y = Vec3::new(10f64.to_radians().sin(), 0.0, 10f64.to_radians().cos());
    match ik(
        &m,
        &Pose {
            tip: Vec3::zeros(),
            axis: about_y,
        },
        &setup,
        &IkOptions::default(),
    ) {
        Err(kinematics::Error::Unreachable { miss }) => assert!(close(miss.to_degrees(), 10.0, 1e-9)),
        other => panic!("{other:?}"),
    }
    // The table turns the part, so W sees the tool turn the other way: axis (0, sin A, cos A).
    let about_x = Vec3::new(0.0, 25f64.to_radians().sin(), 25f64.to_radians().cos());
    let s = ik(
        &m,
        &Pose {
            tip: Vec3::new(5.0, 6.0, 7.0),
            axis: about_x,
        },
        &setup,
        &IkOptions::default(),
    )
    .unwrap();
    assert_eq!(s.len(), 1);
    assert!(close(s[0].joints.rotary[0].to_degrees(), 25.0, 1e-9));
    // Nutating 45°: nothing beyond 90° from +z, however the tip lies.
    let m = machine("dmu-nutating-45");
    let low = Vec3::new(0.0, 100f64.to_radians().sin(), 100f64.to_radians().cos());
    match ik(
        &m,
        &Pose {
            tip: Vec3::zeros(),
            axis: low,
        },
        &setup,
        &IkOptions::default(),
    ) {
        Err(kinematics::Error::Unreachable { miss }) => assert!(close(miss.to_degrees(), 10.0, 1e-9), "{}", miss.to_degrees()),
        other => panic!("{other:?}"),
    }
    // Rounding of i, j, k in a CL file (1e-8) is within the default tolerance.
    let m = machine("vmc-4axis-a");
    let nearly = Vec3::new(1e-8, -(25f64.to_radians().sin()), 25f64.to_radians().cos());
    assert!(
        ik(
            &m,
            &Pose {
                tip: Vec3::zeros(),
                axis: nearly
            },
            &setup,
            &IkOptions::default()
        )
        .is_ok()
    );
}

#[test]
fn nutating_machine_needs_no_special_case() {
    let m = machine("dmu-nutating-45");
    let setup = Setup::new(100.0, Vec3::zeros());
    // Every orientation within 90° of +z is reachable, on the B in [0, 180] branch.
    for tilt in [1.0f64, 30.0, 60.0, 89.0] {
        for az in [0.0f64, 77.0, 200.0] {
            let (t, a) = (tilt.to_radians(), az.to_radians());
            let u = Vec3::new(t.sin() * a.cos(), t.sin() * a.sin(), t.cos());
            let sols = ik(
                &m,
                &Pose {
                    tip: Vec3::new(10.0, 0.0, 5.0),
                    axis: u,
                },
                &setup,
                &IkOptions::default(),
            )
            .unwrap();
            assert!(
                sols.iter().any(|s| kinematics::reachable_within_limits(&m, s)),
                "tilt {tilt} az {az}: {sols:?}"
            );
        }
    }
}

#[test]
fn angle_error_is_inverted_to_1e_9_degrees_and_flagged_outside_its_range() {
    let m = machine("htm50200-horizontal");
    let b = &m.rotaries[m.rotary_index('B').unwrap()];
    let e = b.angle_error.as_ref().unwrap();
    for wanted in [-10.0f64, 0.0, 0.5, 12.0, 25.0, 39.9, 40.0, 55.0, 89.0] {
        let w = b.word(wanted.to_radians());
        let got = b.actual(w).to_degrees();
        assert!(
            (got - wanted).abs() < 1e-9,
            "wanted {wanted}, word {} stands at {got}",
            w.to_degrees()
        );
        assert_eq!(e.in_range(w), (0.0..=40.0).contains(&w.to_degrees()), "{}", w.to_degrees());
    }
    // The paper's polynomial as printed reaches −3.85° at 40°.
    assert!(close(e.delta(40f64.to_radians()).to_degrees(), -3.8472, 1e-9));
    // IK commands the word, so that FK (which applies Δ) lands on the pose.
    let setup = Setup::new(100.0, Vec3::new(-1000.0, -2000.0, -1500.0));
    let j = words(&m, [100.0, -1500.0, -1000.0], &[('A', 120.0), ('B', 20.0)]);
    let pose = fk(&m, &j, &setup);
    let sols = ik(&m, &pose, &setup, &IkOptions::default()).unwrap();
    let s = sols
        .iter()
        .find(|s| close(s.joints.rotary[1], j.rotary[1], 1e-11))
        .expect("word recovered to 1e-9°");
    assert!(close(s.joints.rotary[1].to_degrees(), 20.0, 1e-9));
    assert!(
        !close(s.actual[1].to_degrees(), 20.0, 1e-3),
        "the axis stands elsewhere than the word says"
    );
}

#[test]
fn three_rotary_machine_returns_every_root() {
    let m = machine("propeller-3r2l");
    let setup = Setup::new(100.0, Vec3::zeros());
    let j = words(&m, [0.0, 120.0, -80.0], &[('C', 33.0), ('A', 20.0), ('B', -35.0)]);
    let pose = fk(&m, &j, &setup);
    let sols = ik(&m, &pose, &setup, &IkOptions::default()).unwrap();
    assert!(sols.len() >= 2, "{sols:#?}");
    let mut roots: Vec<u8> = sols.iter().map(|s| s.root).collect();
    roots.dedup();
    assert_eq!(roots.len(), sols.len(), "roots numbered distinctly");
    for s in &sols {
        assert_eq!(s.joints.linear[0], 0.0, "no X on this machine");
        let (dp, da) = pose_error(&fk(&m, &s.joints, &setup), &pose);
        assert!(dp < 1e-9 && da < 1e-12, "{s:?}: {dp} {da}");
    }
    assert!(sols.iter().any(|s| same_joints(&m, &s.joints, &j, 1e-8, 1e-10)));
}

/// Found by the property test: B near 90° puts the inner pair near its singularity, where the
/// inner angles swing fast with the outer one and a coarse scan stepped over the roots.
#[test]
fn three_rotary_roots_near_the_inner_singularity() {
    let m = machine("propeller-3r2l");
    let setup = Setup::new(100.0, Vec3::zeros());
    // The second case is a double root: the residual touches zero at C = 0 without a sign change.
    for j in [
        Joints {
            linear: [0.0, 1494.5865265154284, -800.0],
            rotary: [-12.566370614359172, -2.0943951023931953, 1.5609030877733467],
        },
        Joints {
            linear: [0.0, -1500.0, -800.0],
            rotary: [-12.566370614359172, -1.3635363847359723, 1.581375998732448],
        },
    ] {
        let pose = fk(&m, &j, &setup);
        let sols = ik(&m, &pose, &setup, &IkOptions::default()).unwrap();
        assert!(sols.iter().any(|s| same_joints(&m, &s.joints, &j, 1e-3, 1e-6)), "{sols:#?}");
        for s in &sols {
            let (dp, da) = pose_error(&fk(&m, &s.joints, &setup), &pose);
            assert!(dp < 1e-9 && da < 1e-12);
        }
    }
}

#[test]
fn invalid_poses_are_errors_not_panics() {
    let m = machine("spinner-u5-620");
    let setup = Setup::new(100.0, Vec3::zeros());
    for pose in [
        Pose {
            tip: Vec3::zeros(),
            axis: Vec3::zeros(),
        },
        Pose {
            tip: Vec3::new(f64::NAN, 0.0, 0.0),
            axis: Vec3::z(),
        },
        Pose {
            tip: Vec3::zeros(),
            axis: Vec3::new(f64::INFINITY, 0.0, 1.0),
        },
        Pose {
            tip: Vec3::new(0.0, -2.0 * kinematics::MAX_COORD, 0.0),
            axis: Vec3::z(),
        },
    ] {
        assert!(matches!(
            ik(&m, &pose, &setup, &IkOptions::default()),
            Err(kinematics::Error::InvalidPose { .. })
        ));
    }
    // Schemathesis found this one: a work offset of -f64::MAX overflowed to inf inside the
    // solver and nalgebra's SVD never returned, hanging a server thread.
    let p3 = machine("propeller-3r2l");
    let r = ik(
        &p3,
        &Pose {
            tip: Vec3::new(-6.307825680014814e16, 3.16e-77, -1.25e-221),
            axis: Vec3::new(-0.0005293209536042197, -1.5, -9.29e-262),
        },
        &Setup::new(100.0, Vec3::new(-f64::MAX, -3.2e-172, -4.758281671465856e140)),
        &IkOptions::default(),
    );
    assert!(matches!(r, Err(kinematics::Error::InvalidPose { .. })), "{r:?}");
    // An unnormalised axis is taken as its direction.
    let s = ik(
        &m,
        &Pose {
            tip: Vec3::zeros(),
            axis: Vec3::new(0.0, 0.0, 5.0),
        },
        &setup,
        &IkOptions::default(),
    )
    .unwrap();
    assert_eq!(s.len(), 1);
}

#[test]
fn windings_list_every_word_within_travel() {
    let m = machine("dmg-dmc75v");
    let c = &m.rotaries[m.rotary_index('C').unwrap()];
    let w: Vec<f64> = c.windings(100f64.to_radians(), 0.0).iter().map(|x| x.to_degrees()).collect();
    assert_eq!(w.len(), 2);
    assert!(close(w[0], -260.0, 1e-9) && close(w[1], 100.0, 1e-9));
    let spinner = machine("spinner-u5-620");
    let c = &spinner.rotaries[1];
    let w = c.windings(10f64.to_radians(), 3000f64.to_radians());
    assert!(close(w[0].to_degrees(), 2890.0, 1e-9), "unbounded: nearest the previous word");
}

/// The soak runs' hardest cases, kept: double roots next to the inner singularity (B ≈ ±90°).
#[test]
fn three_rotary_soak_cases() {
    let m = machine("propeller-3r2l");
    let setup = Setup::new(100.0, Vec3::zeros());
    for j in [
        Joints {
            linear: [0.0, 1270.9302023140149, -800.0],
            rotary: [11.913042045504117, 0.876310950038873, 1.5295823528871455],
        },
        Joints {
            linear: [0.0, 856.1574313522556, -800.0],
            rotary: [-4.071382192896053, -1.8676155485726427, -1.5710697047003148],
        },
    ] {
        let pose = fk(&m, &j, &setup);
        let sols = ik(&m, &pose, &setup, &IkOptions::default()).unwrap();
        assert!(sols.len() >= 4, "{sols:#?}");
        for s in &sols {
            let (dp, da) = pose_error(&fk(&m, &s.joints, &setup), &pose);
            assert!(dp < 1e-9 && da < 1e-12, "{s:?}: {dp} {da}");
        }
    }
}

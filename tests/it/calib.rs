//! Calibration from test cuts and angle-error fitting, on synthetic data with known answers and
//! on the papers' own figures.

use crate::common;

use kinepost::calib::{self, Measurement};
use kinepost::kinematics::{Joints, Machine, Rotary, Setup, Vec3};

const PAPER: [f64; 5] = [0.1808, -2.95e-2, 2.3e-3, -7e-5, -8e-7];

fn poly(c: &[f64], t: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, k| acc * t + k)
}

#[test]
fn the_papers_polynomial_is_recovered_from_its_own_samples() {
    // The HTM50200 paper's equation (13), sampled every degree on 0..40 as the paper measured.
    let samples: Vec<(f64, f64)> = (0..=40).map(|t| (t as f64, poly(&PAPER, t as f64))).collect();
    let fits = calib::fit_angle_error(&samples, 2..=5).unwrap();
    assert_eq!(fits.len(), 4);
    let f4 = &fits[2];
    for (a, b) in f4.coefficients.iter().zip(PAPER) {
        assert!((a - b).abs() <= 1e-9 * (1.0 + b.abs()), "{:?}", f4.coefficients);
    }
    assert!(f4.rms < 1e-9 && fits[0].rms > 1e-3, "degree 2 cannot, degree 4 can: {fits:?}");
    assert_eq!(calib::choose(&fits).unwrap().degree, 4, "the lowest degree that fits");
}

#[test]
fn a_known_polynomial_through_noise_and_the_vertical_error_route() {
    // Δθ measured as vertical tip errors ΔZ on a 350 mm pendulum (equation 9), back with (10).
    let truth = [0.05, 0.01, -4e-4, 3e-6];
    let l = 350.0;
    let mut rng = 0x2545F4914F6CDD1Du64;
    let mut noise = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        ((rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2e-4
    };
    let samples: Vec<(f64, f64)> = (0..=60)
        .map(|k| {
            let t = 1.0 + k as f64 * 1.5;
            let dtheta = poly(&truth, t);
            let dz = l * (t.to_radians().cos() - (t + dtheta).to_radians().cos());
            (t, calib::delta_from_vertical_error(t, dz, l).unwrap() + noise())
        })
        .collect();
    let fits = calib::fit_angle_error(&samples, 2..=5).unwrap();
    let f3 = &fits[1];
    assert!(f3.rms < 1e-4, "{f3:?}");
    for t in [1.0, 30.0, 90.0] {
        assert!((poly(&f3.coefficients, t) - poly(&truth, t)).abs() < 2e-4, "at {t}°");
    }
    assert!(
        calib::delta_from_vertical_error(10.0, 800.0, 350.0).is_err(),
        "more than the pendulum can swing"
    );
}

/// The Fryer 5X-45 with its pivots where a profile without calibration would put them.
fn uncalibrated(m: &Machine) -> Machine {
    let rotaries: Vec<Rotary> = m
        .rotaries
        .iter()
        .map(|r| Rotary {
            pivot: Vec3::new(0.0, 0.0, if r.name == 'A' { 5.0 } else { 0.0 }),
            ..r.clone()
        })
        .collect();
    m.with_rotaries(rotaries).unwrap()
}

#[test]
fn fryer_offsets_are_recovered_from_test_cuts() {
    // Truth: the thesis' t = (0.002, 0.001, 0) and J = (0, 0.0005, 0) in, as the shipped profile
    // carries them; the nominal profile has none. Cuts at the thesis' C angles, several A.
    let truth = common::library().get("fryer-5x-45").unwrap().machine.clone();
    let nominal = uncalibrated(&truth);
    let setup = Setup::new(3.0, Vec3::zeros());
    let (ci, ai) = (truth.rotary_index('C').unwrap(), truth.rotary_index('A').unwrap());
    let mut meas = Vec::new();
    let mut k = 0u32;
    for c in [0.0f64, 90.0, 180.0, -90.0] {
        for a in [0.0f64, 30.0, 60.0, 90.0] {
            let mut j = Joints {
                linear: [1.0, -0.5, -2.0],
                ..Default::default()
            };
            j.rotary[ci] = c.to_radians();
            j.rotary[ai] = a.to_radians();
            k += 1;
            let noise = Vec3::new(((k * 37) % 7) as f64 - 3.0, ((k * 11) % 5) as f64 - 2.0, 0.0) * 2e-6;
            meas.push(Measurement {
                joints: j,
                deviation: calib::simulated_deviation(&nominal, &truth, &setup, &j) + noise,
            });
        }
    }
    let fit = calib::fit_pivots(&nominal, &setup, &meas).unwrap();
    assert!(fit.rms_before > 1e-3 && fit.rms < 2e-5, "{} -> {}", fit.rms_before, fit.rms);
    let off = |n: char| fit.offsets.iter().find(|(c, _)| *c == n).unwrap().1;
    // Observable parts: C pivot across z; A pivot across x (its x component is along A's axis).
    let (c, a) = (off('C'), off('A'));
    assert!(
        (c.x - -0.002).abs() < 2e-5 && (c.y - -0.0015).abs() < 2e-5,
        "C pivot offset {c:?}"
    );
    assert!((a.y - -0.001).abs() < 2e-5 && a.z.abs() < 2e-5, "A pivot offset {a:?}");
}

#[test]
fn too_few_cuts_are_refused_not_guessed() {
    let truth = common::library().get("fryer-5x-45").unwrap().machine.clone();
    let nominal = uncalibrated(&truth);
    let setup = Setup::new(3.0, Vec3::zeros());
    let j = Joints::default();
    let one = vec![Measurement {
        joints: j,
        deviation: Vec3::zeros(),
    }];
    assert!(calib::fit_pivots(&nominal, &setup, &one).is_err());
    // Enough numbers but all at one pose: the offsets are not determined.
    let same = vec![
        Measurement {
            joints: j,
            deviation: Vec3::new(1e-3, 0.0, 0.0)
        };
        4
    ];
    assert!(matches!(
        calib::fit_pivots(&nominal, &setup, &same),
        Err(calib::Error::Singular(_))
    ));
}

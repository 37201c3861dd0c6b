//! Keeping a machine's geometry true: pivot offsets fitted from test-cut deviations (the Fryer
//! 5X-45 thesis), and a rotary's angle-error polynomial fitted from measurements (the HTM50200
//! paper). Pure numerics over the kinematics; no IO. Fits propose; applying one is a separate,
//! explicit step for the caller.

use crate::kinematics::{self, Joints, Machine, Rotary, Setup, Vec3, fk};
use nalgebra::{DMatrix, DVector};

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum Error {
    #[error("{0}")]
    Input(String),
    #[error("the fit is singular: the measurements do not determine {0}")]
    Singular(String),
}

/// nalgebra's plain `svd` never returns on a matrix holding inf or NaN; bounded, it says so.
const SVD_MAX_ITER: usize = 500;

fn no_convergence() -> Error {
    Error::Input("the measurements hold values too large or not finite to fit".into())
}

/// One fitted polynomial Δ(θ) = Σ c_i θ^i (degrees) and how well it fits.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PolyFit {
    pub degree: usize,
    pub coefficients: Vec<f64>,
    /// Root mean square and largest residual, degrees.
    pub rms: f64,
    pub max: f64,
}

/// The angle error Δθ (degrees) a vertical tip error ΔZ reveals at commanded θ (degrees) on a
/// pendulum of length L: the paper's equation (10), Δθ = acos(cos θ − ΔZ/L) − θ.
pub fn delta_from_vertical_error(theta_deg: f64, dz: f64, pendulum: f64) -> Result<f64, Error> {
    if !(pendulum.is_finite() && pendulum > 0.0) {
        return Err(Error::Input("pendulum length must be positive".into()));
    }
    let c = theta_deg.to_radians().cos() - dz / pendulum;
    if !(-1.0..=1.0).contains(&c) {
        return Err(Error::Input(format!(
            "ΔZ = {dz} is more than the pendulum can swing at θ = {theta_deg}°"
        )));
    }
    Ok(c.acos().to_degrees() - theta_deg)
}

/// Least-squares polynomials of each degree in `degrees` through (θ, Δθ) samples (degrees),
/// solved on θ scaled to [-1, 1] so that degree 5 stays well conditioned.
pub fn fit_angle_error(samples: &[(f64, f64)], degrees: std::ops::RangeInclusive<usize>) -> Result<Vec<PolyFit>, Error> {
    if samples.iter().any(|(a, b)| !a.is_finite() || !b.is_finite()) {
        return Err(Error::Input("samples must be finite".into()));
    }
    let (lo, hi) = samples
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), (t, _)| (l.min(*t), h.max(*t)));
    let (mid, half) = (0.5 * (lo + hi), (0.5 * (hi - lo)).max(1e-9));
    let mut out = Vec::new();
    for deg in degrees {
        if samples.len() <= deg {
            return Err(Error::Input(format!(
                "degree {deg} needs more than {deg} samples, got {}",
                samples.len()
            )));
        }
        let a = DMatrix::from_fn(samples.len(), deg + 1, |r, c| ((samples[r].0 - mid) / half).powi(c as i32));
        let b = DVector::from_iterator(samples.len(), samples.iter().map(|s| s.1));
        let svd = a
            .clone()
            .try_svd(true, true, f64::EPSILON, SVD_MAX_ITER)
            .ok_or_else(no_convergence)?;
        let x = svd.solve(&b, 1e-12).map_err(|e| Error::Singular(e.to_string()))?;
        // Back from the scaled variable: Σ x_j ((θ − m)/h)^j expanded in powers of θ.
        let mut coeffs = vec![0.0; deg + 1];
        for (j, xj) in x.iter().enumerate() {
            for (i, c) in coeffs.iter_mut().enumerate().take(j + 1) {
                let binom = (0..i).fold(1.0, |acc, k| acc * (j - k) as f64 / (k + 1) as f64);
                *c += xj * binom * (-mid).powi((j - i) as i32) / half.powi(j as i32);
            }
        }
        let res: Vec<f64> = samples
            .iter()
            .map(|(t, d)| coeffs.iter().rev().fold(0.0, |acc, c| acc * t + c) - d)
            .collect();
        let rms = (res.iter().map(|r| r * r).sum::<f64>() / res.len() as f64).sqrt();
        let max = res.iter().fold(0.0f64, |m, r| m.max(r.abs()));
        out.push(PolyFit {
            degree: deg,
            coefficients: coeffs,
            rms,
            max,
        });
    }
    Ok(out)
}

/// The degree to propose: the lowest whose RMS residual is within 10 % of the best (more terms
/// that do not fit better only follow the noise).
pub fn choose(fits: &[PolyFit]) -> Option<&PolyFit> {
    let best = fits.iter().map(|f| f.rms).fold(f64::INFINITY, f64::min);
    fits.iter().find(|f| f.rms <= best * 1.1 + 1e-12)
}

/// A test cut: the joint words it was cut at, and how far the tip landed from where the
/// profile says (measured, in the part frame, profile units).
#[derive(Clone, Debug, PartialEq)]
pub struct Measurement {
    pub joints: Joints,
    pub deviation: Vec3,
}

/// Fitted pivot offsets.
#[derive(Clone, Debug)]
pub struct PivotFit {
    /// Per rotary (chain order): name and the offset to add to its pivot (profile units).
    pub offsets: Vec<(char, Vec3)>,
    /// Residual tip error per measurement after the fit, and their RMS (profile units).
    pub residuals: Vec<f64>,
    pub rms: f64,
    pub rms_before: f64,
}

/// Fits pivot offsets (the components across each rotary's axis: along the axis they do not
/// move the tool) so that FK with the offset pivots reproduces the measured tips, by
/// Gauss–Newton on a numerical Jacobian.
pub fn fit_pivots(m: &Machine, setup: &Setup, meas: &[Measurement]) -> Result<PivotFit, Error> {
    let nrot = m.rotaries.len();
    if nrot == 0 {
        return Err(Error::Input("a machine without rotaries has no pivots to calibrate".into()));
    }
    if meas.len() * 3 < 2 * nrot {
        return Err(Error::Input(format!(
            "{} measurements cannot determine {} pivot offsets",
            meas.len(),
            2 * nrot
        )));
    }
    // Two directions across each rotary's axis.
    let basis: Vec<(Vec3, Vec3)> = m
        .rotaries
        .iter()
        .map(|r| {
            let a = r.axis;
            let t = if a.x.abs() < 0.9 { Vec3::x() } else { Vec3::y() };
            let u = (t - a * a.dot(&t)).normalize();
            (u, a.cross(&u))
        })
        .collect();
    let targets: Vec<Vec3> = meas.iter().map(|s| fk(m, &s.joints, setup).tip + s.deviation).collect();
    let with = |x: &DVector<f64>| -> Result<Machine, Error> {
        let rotaries: Vec<Rotary> = m
            .rotaries
            .iter()
            .enumerate()
            .map(|(k, r)| Rotary {
                pivot: r.pivot + basis[k].0 * x[2 * k] + basis[k].1 * x[2 * k + 1],
                ..r.clone()
            })
            .collect();
        m.with_rotaries(rotaries).map_err(|e| Error::Input(e.to_string()))
    };
    let residual = |x: &DVector<f64>| -> Result<DVector<f64>, Error> {
        let mm = with(x)?;
        let mut r = DVector::zeros(meas.len() * 3);
        for (i, s) in meas.iter().enumerate() {
            let d = fk(&mm, &s.joints, setup).tip - targets[i];
            r.fixed_rows_mut::<3>(3 * i).copy_from(&d);
        }
        Ok(r)
    };
    let mut x = DVector::zeros(2 * nrot);
    let mut r = residual(&x)?;
    let rms_of = |r: &DVector<f64>| (r.norm_squared() / meas.len() as f64).sqrt();
    let rms_before = rms_of(&r);
    for _ in 0..20 {
        let mut jac = DMatrix::zeros(r.len(), x.len());
        for c in 0..x.len() {
            let h = 1e-6;
            let mut xp = x.clone();
            xp[c] += h;
            jac.set_column(c, &((residual(&xp)? - &r) / h));
        }
        let svd = jac
            .try_svd(true, true, f64::EPSILON, SVD_MAX_ITER)
            .ok_or_else(no_convergence)?;
        if svd.singular_values.min() < 1e-9 * svd.singular_values.max().max(1e-300) {
            let weak = (0..nrot).map(|k| m.rotaries[k].name).collect::<String>();
            return Err(Error::Singular(format!(
                "all pivot offsets of {weak} (cut at more angle combinations)"
            )));
        }
        let step = svd.solve(&(-&r), 1e-12).map_err(|e| Error::Singular(e.to_string()))?;
        x += &step;
        r = residual(&x)?;
        if step.norm() < 1e-12 {
            break;
        }
    }
    let residuals = (0..meas.len()).map(|i| r.fixed_rows::<3>(3 * i).norm()).collect();
    Ok(PivotFit {
        offsets: m
            .rotaries
            .iter()
            .enumerate()
            .map(|(k, rt)| (rt.name, basis[k].0 * x[2 * k] + basis[k].1 * x[2 * k + 1]))
            .collect(),
        residuals,
        rms: rms_of(&r),
        rms_before,
    })
}

/// The deviation a measurement would show on the true machine `truth` when the profile is
/// `nominal` (for tests and for planning test cuts).
pub fn simulated_deviation(nominal: &Machine, truth: &Machine, setup: &Setup, joints: &Joints) -> Vec3 {
    kinematics::fk(truth, joints, setup).tip - kinematics::fk(nominal, joints, setup).tip
}

//! Generated 5-axis CL paths for any profile: smooth joint trajectories inside travel mapped
//! through FK, so every pose is reachable and the path exercises every rotary (unbounded ones
//! over several turns). For tests, benchmarks and `kinepost generate`; written as CL text, so the
//! whole pipeline (reader included) is what gets checked.
//!
//! The paths are machinable, not just reachable: the tool leans at most [`MAX_TILT`] from the
//! table's normal and the tip stays above the table's top (W's z = 0), so that on a profile with
//! bodies a generated path posts without a collision.

use crate::kinematics::{Joints, Machine, Mount, Setup, Units, Vec3, fk};
use std::f64::consts::{PI, TAU};
use std::io::Write;

/// The largest lean of the tool from W's +z: steeper and the head or holder meets the table on
/// the shipped machines' geometry.
pub const MAX_TILT: f64 = 55.0 * PI / 180.0;

/// Writes `points` GOTO records. `seed` varies phases; `tool_length` must match what the post
/// will use for head machines.
pub fn write_path(m: &Machine, points: usize, seed: u64, tool_length: f64, out: &mut impl Write) -> std::io::Result<()> {
    let setup = Setup::new(tool_length, Vec3::zeros());
    let units = match m.units {
        Units::Mm => ("MM", "MMPM", 1000.0),
        Units::Inch => ("INCHES", "IPM", 40.0),
    };
    writeln!(out, "PARTNO/GENERATED PATH FOR {}", m.id.to_uppercase())?;
    writeln!(out, "UNITS/{}", units.0)?;
    writeln!(out, "LOADTL/1,LENGTH,{tool_length}")?;
    writeln!(out, "SPINDL/6000,RPM,CLW")?;
    writeln!(out, "COOLNT/FLOOD")?;
    let ph = |k: u64| {
        ((seed.wrapping_mul(6364136223846793005).wrapping_add(k.wrapping_mul(1442695040888963407))) >> 11) as f64 / (1u64 << 53) as f64
            * TAU
    };
    for n in 0..points {
        let t = n as f64 / points.max(2) as f64;
        let mut j = joints(m, t, &ph);
        lean_at_most(m, &setup, &mut j, MAX_TILT);
        place_tip(m, &setup, &mut j, t, &ph);
        let p = fk(m, &j, &setup);
        if n == 0 {
            writeln!(out, "RAPID")?;
        }
        if n == 1 {
            writeln!(out, "FEDRAT/{},{}", units.2, units.1)?;
        }
        writeln!(
            out,
            "GOTO/{:.6},{:.6},{:.6},{:.9},{:.9},{:.9}",
            p.tip.x, p.tip.y, p.tip.z, p.axis.x, p.axis.y, p.axis.z
        )?;
    }
    writeln!(out, "SPINDL/OFF")?;
    writeln!(out, "FINI")?;
    Ok(())
}

/// How far a rotary that leans the tool swings from upright (before [`lean_at_most`]).
const SWING: f64 = 45.0 * PI / 180.0;

/// Smooth joints at `t` in [0, 1): linears around the middle of travel; a rotary that spins W or
/// the head about z two full turns if unbounded, else over 70% of its travel; one that leans the
/// tool over 90% of the part of its travel within [`SWING`] of upright (all zero).
fn joints(m: &Machine, t: f64, ph: &impl Fn(u64) -> f64) -> Joints {
    let mut j = Joints::default();
    for i in 0..3 {
        if let Some(l) = &m.linears[i] {
            let (c, a) = (0.5 * (l.min + l.max), 0.25 * (l.max - l.min));
            j.linear[i] = c + a * (TAU * (1.0 + i as f64) * t + ph(i as u64)).sin();
        }
    }
    for (i, r) in m.rotaries.iter().enumerate() {
        let wave = (TAU * (0.5 + i as f64 * 0.5) * t + ph(10 + i as u64)).sin();
        let spins = leaves_lean_alone(m, i);
        j.rotary[i] = match r.limits {
            None if spins => -PI + 2.0 * TAU * t,
            None => 0.9 * SWING * wave,
            Some((lo, hi)) => {
                let (lo, hi, k) = if spins { (lo, hi, 0.7) } else { (lo.max(-SWING), hi.min(SWING), 0.9) };
                0.5 * (lo + hi) + 0.5 * k * (hi - lo) * wave
            }
        };
    }
    j
}

/// Whether turning rotary `k` leaves the tool's lean from W's z alone: an axis along z that is
/// the last table rotary (it spins W about its normal) or the first head rotary (it spins the
/// whole head about M's z).
fn leaves_lean_alone(m: &Machine, k: usize) -> bool {
    let r = &m.rotaries[k];
    let along_z = r.axis.z.abs() > 1.0 - 1e-12;
    let same = |mount: Mount| m.rotaries.iter().enumerate().filter(move |(_, q)| q.mount == mount).map(|(i, _)| i);
    along_z
        && match r.mount {
            Mount::Table => same(Mount::Table).last() == Some(k),
            Mount::Head => same(Mount::Head).next() == Some(k),
        }
}

/// Draws the rotaries that lean the tool toward zero (all zero is upright in every profile) until
/// the lean is at most `max`: the largest fraction of their angles that keeps it there.
fn lean_at_most(m: &Machine, setup: &Setup, j: &mut Joints, max: f64) {
    let lean = |j: &Joints| fk(m, j, setup).axis.z.clamp(-1.0, 1.0).acos();
    if lean(j) <= max {
        return;
    }
    let full = *j;
    let scaled = |s: f64| {
        let mut q = full;
        for k in 0..m.rotaries.len() {
            if !leaves_lean_alone(m, k) {
                q.rotary[k] = s * full.rotary[k];
            }
        }
        q
    };
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if lean(&scaled(mid)) <= max { lo = mid } else { hi = mid }
    }
    *j = scaled(lo);
}

/// Moves the linears so that the tip is at a point of a part above the table: within a radius
/// of W's z axis and between two heights above its top, both a fraction of the machine's
/// smallest half-travel. A machine lacking a linear only lifts the tip with Z.
fn place_tip(m: &Machine, setup: &Setup, j: &mut Joints, t: f64, ph: &impl Fn(u64) -> f64) {
    let scale = m.linears.iter().flatten().map(|l| 0.5 * (l.max - l.min)).fold(f64::INFINITY, f64::min);
    if !scale.is_finite() {
        return;
    }
    let (r, z0, dz) = (0.3 * scale, 0.3 * scale, 0.15 * scale);
    let want = Vec3::new(
        r * (TAU * 3.0 * t + ph(20)).sin(),
        r * (TAU * 2.0 * t + ph(21)).cos(),
        z0 + dz * (TAU * 5.0 * t + ph(22)).sin(),
    );
    // The tip in W is affine in the linears: tip(l) = tip(0) + Σ l_i · col_i.
    let at = |l: [f64; 3]| fk(m, &Joints { linear: l, ..*j }, setup).tip;
    let base = at([0.0; 3]);
    let cols: [Vec3; 3] = std::array::from_fn(|i| {
        let mut l = [0.0; 3];
        l[i] = 1.0;
        at(l) - base
    });
    let mut l = j.linear;
    if m.linears.iter().all(Option::is_some) {
        if let Some(inv) = nalgebra::Matrix3::from_columns(&cols).try_inverse() {
            l = (inv * (want - base)).into();
        }
    } else if m.linears[2].is_some() && cols[2].z.abs() > 0.3 {
        l[2] += (want.z - at(l).z) / cols[2].z;
    }
    // A machine whose travel cannot hold the part there (a turning axis far from W's origin)
    // keeps the joints' own path.
    let inside = m.linears.iter().zip(l).all(|(a, v)| a.as_ref().is_none_or(|a| (a.min..=a.max).contains(&v)));
    if inside {
        j.linear = l;
    }
}

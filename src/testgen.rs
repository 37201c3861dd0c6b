//! Generated 5-axis CL paths for any profile: smooth joint trajectories inside travel mapped
//! through FK, so every pose is reachable and the path exercises every rotary (unbounded ones
//! over several turns). For tests, benchmarks and `kinepost generate`; written as CL text, so the
//! whole pipeline (reader included) is what gets checked.

use crate::kinematics::{Joints, Machine, Setup, Vec3, fk};
use std::io::Write;

/// Writes `points` GOTO records. `seed` varies phases; `tool_length` must match what the post
/// will use for head machines.
pub fn write_path(m: &Machine, points: usize, seed: u64, tool_length: f64, out: &mut impl Write) -> std::io::Result<()> {
    let setup = Setup::new(tool_length, Vec3::zeros());
    let units = match m.units {
        crate::kinematics::Units::Mm => ("MM", "MMPM", 1000.0),
        crate::kinematics::Units::Inch => ("INCHES", "IPM", 40.0),
    };
    writeln!(out, "PARTNO/GENERATED PATH FOR {}", m.id.to_uppercase())?;
    writeln!(out, "UNITS/{}", units.0)?;
    writeln!(out, "LOADTL/1,LENGTH,{tool_length}")?;
    writeln!(out, "SPINDL/6000,RPM,CLW")?;
    writeln!(out, "COOLNT/FLOOD")?;
    let ph = |k: u64| {
        ((seed.wrapping_mul(6364136223846793005).wrapping_add(k * 1442695040888963407)) >> 11) as f64 / (1u64 << 53) as f64
            * std::f64::consts::TAU
    };
    for n in 0..points {
        let t = n as f64 / points.max(2) as f64;
        let mut j = Joints::default();
        for i in 0..3 {
            if let Some(l) = &m.linears[i] {
                let (c, a) = (0.5 * (l.min + l.max), 0.25 * (l.max - l.min));
                j.linear[i] = c + a * (std::f64::consts::TAU * (1.0 + i as f64) * t + ph(i as u64)).sin();
            }
        }
        for (i, r) in m.rotaries.iter().enumerate() {
            j.rotary[i] = match r.limits {
                Some((lo, hi)) => {
                    // Stay clear of the ends: travel of 70% around the middle.
                    let (c, a) = (0.5 * (lo + hi), 0.35 * (hi - lo));
                    c + a * (std::f64::consts::TAU * (0.5 + i as f64 * 0.5) * t + ph(10 + i as u64)).sin()
                }
                // Unbounded: two full turns over the path.
                None => -std::f64::consts::PI + 2.0 * std::f64::consts::TAU * t,
            };
        }
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

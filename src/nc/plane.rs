//! Tilted working planes (3+2): how each control names a frame, and the angle conventions both
//! ways (frame → words for the formatter, words → frame for `verify` and tests).
//!
//! A plane's frame is a rotation whose columns are the plane's X, Y, Z in the program's
//! coordinates at zero rotaries (the joint-mode program zero). Its origin is that zero: plane
//! coordinates are `Fᵀ · p`.

use nalgebra::{Matrix3, Rotation3, Vector3};

/// How a control tilts the working plane. kinepost positions the rotaries itself before the
/// plane, so a control that picks its own solution (G53.1, TURN, CYCLE800's direction) finds
/// the tool already there and moves nothing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Planes {
    /// `G68.2 X0 Y0 Z0 I J K` (Euler angles Z, X', Z'') then `G53.1`; `G69` cancels.
    Fanuc,
    /// `G254` dynamic work offset: the rotaries as positioned define the plane (X Y stay the
    /// machine's as the table carries them); table-table machines only; `G255` cancels.
    Haas,
    /// `CYCLE800(…,57,…)`: axis by axis, X then Y' then Z''; `CYCLE800()` cancels.
    Siemens,
    /// `PLANE SPATIAL SPA SPB SPC TURN FMAX SEQ±` (fixed axes X, then Y, then Z);
    /// `PLANE RESET STAY` cancels.
    Heidenhain,
    /// The control has no tilted-plane command: 3+2 stays 5-axis positioning.
    None,
}

impl Planes {
    pub fn describe(self) -> &'static str {
        match self {
            Planes::Fanuc => "G68.2 X0 Y0 Z0 I J K (Euler ZXZ) + G53.1, G69 cancels",
            Planes::Haas => "G254 dynamic work offset after the rotaries (table-table), G255 cancels",
            Planes::Siemens => "CYCLE800 axis by axis (mode 57: X, Y', Z''), CYCLE800() cancels",
            Planes::Heidenhain => "PLANE SPATIAL SPA SPB SPC TURN FMAX SEQ, PLANE RESET STAY cancels",
            Planes::None => "none: 3+2 is written as 5-axis positioning",
        }
    }
}

fn rot(axis: Vector3<f64>, a: f64) -> Matrix3<f64> {
    Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), a).into_inner()
}

/// `F = Rz(i)·Rx(j)·Rz(k)` (Fanuc G68.2 I J K), radians.
pub fn from_zxz(a: [f64; 3]) -> Matrix3<f64> {
    rot(Vector3::z(), a[0]) * rot(Vector3::x(), a[1]) * rot(Vector3::z(), a[2])
}

/// The inverse of [`from_zxz`]: j in [0, π]; with j = 0 or π, k = 0.
pub fn zxz(f: &Matrix3<f64>) -> [f64; 3] {
    let j = f[(2, 2)].clamp(-1.0, 1.0).acos();
    if j.sin() > 1e-12 {
        [f[(0, 2)].atan2(-f[(1, 2)]), j, f[(2, 0)].atan2(f[(2, 1)])]
    } else {
        [f[(1, 0)].atan2(f[(0, 0)]), j, 0.0]
    }
}

/// `F = Rx(a)·Ry(b)·Rz(c)` (Siemens CYCLE800 axis by axis, X Y' Z''), radians.
pub fn from_xyz(a: [f64; 3]) -> Matrix3<f64> {
    rot(Vector3::x(), a[0]) * rot(Vector3::y(), a[1]) * rot(Vector3::z(), a[2])
}

/// The inverse of [`from_xyz`]: b in [−π/2, π/2]; at b = ±π/2, c = 0.
pub fn xyz(f: &Matrix3<f64>) -> [f64; 3] {
    let b = f[(0, 2)].clamp(-1.0, 1.0).asin();
    if b.cos() > 1e-12 {
        [(-f[(1, 2)]).atan2(f[(2, 2)]), b, (-f[(0, 1)]).atan2(f[(0, 0)])]
    } else {
        [f[(2, 1)].atan2(f[(1, 1)]), b, 0.0]
    }
}

/// `F = Rz(c)·Ry(b)·Rx(a)` (Heidenhain PLANE SPATIAL SPA SPB SPC: about fixed X, then Y, then Z).
pub fn from_spatial(a: [f64; 3]) -> Matrix3<f64> {
    rot(Vector3::z(), a[2]) * rot(Vector3::y(), a[1]) * rot(Vector3::x(), a[0])
}

/// The inverse of [`from_spatial`]: SPB in [−π/2, π/2]; at ±π/2, SPC = 0.
pub fn spatial(f: &Matrix3<f64>) -> [f64; 3] {
    let b = (-f[(2, 0)]).clamp(-1.0, 1.0).asin();
    if b.cos() > 1e-12 {
        [f[(2, 1)].atan2(f[(2, 2)]), b, f[(1, 0)].atan2(f[(0, 0)])]
    } else {
        [(-f[(1, 2)]).atan2(f[(1, 1)]), b, 0.0]
    }
}

/// The three angles a control writes for frame `f` (radians), in its convention.
pub fn angles(p: Planes, f: &Matrix3<f64>) -> [f64; 3] {
    match p {
        Planes::Fanuc => zxz(f),
        Planes::Siemens => xyz(f),
        Planes::Heidenhain => spatial(f),
        Planes::Haas | Planes::None => [0.0; 3],
    }
}

/// The frame a control builds from its three angles (radians).
pub fn frame(p: Planes, a: [f64; 3]) -> Matrix3<f64> {
    match p {
        Planes::Fanuc => from_zxz(a),
        Planes::Siemens => from_xyz(a),
        Planes::Heidenhain => from_spatial(a),
        Planes::Haas | Planes::None => Matrix3::identity(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_convention_round_trips_including_its_gimbal_cases() {
        let cases = [
            [0.3, 0.7, -1.1],
            [-2.0, 1.2, 2.5],
            [0.0, 0.0, 0.0],
            [1.0, std::f64::consts::FRAC_PI_2, 0.0],
            [0.4, -std::f64::consts::FRAC_PI_2, 0.0],
            [0.9, std::f64::consts::PI, 0.0],
        ];
        for p in [Planes::Fanuc, Planes::Siemens, Planes::Heidenhain] {
            for c in cases {
                let f = frame(p, c);
                let back = frame(p, angles(p, &f));
                assert!((back - f).norm() < 1e-12, "{p:?} {c:?}: {f} vs {back}");
            }
        }
        // Fanuc's Z: (sin I sin J, −cos I sin J, cos J).
        let (i, j) = (0.3f64, 0.7f64);
        let z = from_zxz([i, j, 0.5]).column(2).into_owned();
        assert!((z - Vector3::new(i.sin() * j.sin(), -i.cos() * j.sin(), j.cos())).norm() < 1e-15);
        // Heidenhain's SPB alone tilts Z toward +X, like a B axis.
        let z = from_spatial([0.0, 0.5, 0.0]).column(2).into_owned();
        assert!((z - Vector3::new(0.5f64.sin(), 0.0, 0.5f64.cos())).norm() < 1e-15);
    }
}

//! Forward kinematics, written as literally as `docs/machine-model.md` states it, so that it can
//! serve as the independent replay of every block IK produced (self-verification).

use super::model::{Machine, Mount};
use super::{Joints, Pose, Setup, Vec3};

/// Rodrigues: rotate `v` by the angle whose cosine and sine are `c`, `s` about unit `k`:
/// `v c + (k × v) s + k (k·v)(1 − c)`, written out per component (nalgebra's generic operators
/// cost several times the instructions on this path, which replays every block).
#[inline]
pub(crate) fn rotate(k: &Vec3, c: f64, s: f64, v: &Vec3) -> Vec3 {
    let (kx, ky, kz) = (k.x, k.y, k.z);
    let (vx, vy, vz) = (v.x, v.y, v.z);
    let d = (kx * vx + ky * vy + kz * vz) * (1.0 - c);
    Vec3::new(
        vx * c + (ky * vz - kz * vy) * s + kx * d,
        vy * c + (kz * vx - kx * vz) * s + ky * d,
        vz * c + (kx * vy - ky * vx) * s + kz * d,
    )
}

/// The tool pose in the workpiece frame for commanded joints (NC words, radians).
pub fn fk(m: &Machine, joints: &Joints, setup: &Setup) -> Pose {
    fk_actual(m, &joints.linear, &m.actual_angles(&joints.rotary), setup)
}

/// As [`fk`], for actual rotary angles (angle error already applied).
pub fn fk_actual(m: &Machine, linear: &[f64; 3], actual: &[f64; 3], setup: &Setup) -> Pose {
    let (offset, mut axis) = head_offset(m, actual, setup.tool_length);
    let xyz = Vec3::new(
        if m.linears[0].is_some() { linear[0] } else { 0.0 },
        if m.linears[1].is_some() { linear[1] } else { 0.0 },
        if m.linears[2].is_some() { linear[2] } else { 0.0 },
    );
    let mut p = xyz + offset;
    // tip_W = G_tk(-φk) ∘ … ∘ G_t1(-φ1)(tip_M) − work_offset: undo t1 first.
    for (r, &phi) in m.rotaries.iter().zip(actual) {
        if r.mount == Mount::Table {
            let (s, c) = (-phi).sin_cos();
            p = r.pivot + rotate(&r.axis, c, s, &(p - r.pivot));
            axis = rotate(&r.axis, c, s, &axis);
        }
    }
    Pose {
        tip: p - setup.work_offset,
        axis,
    }
}

/// The tool axis in W for commanded rotary words: FK's orientation half alone (no positions),
/// for callers that judge orientations only.
pub fn tool_axis(m: &Machine, rotary_words: &[f64; 3]) -> Vec3 {
    let actual = m.actual_angles(rotary_words);
    let mut a = Vec3::z();
    for (r, &th) in m.rotaries.iter().zip(&actual).rev() {
        if r.mount == Mount::Head {
            let (s, c) = th.sin_cos();
            a = rotate(&r.axis, c, s, &a);
        }
    }
    for (r, &phi) in m.rotaries.iter().zip(&actual) {
        if r.mount == Mount::Table {
            let (s, c) = (-phi).sin_cos();
            a = rotate(&r.axis, c, s, &a);
        }
    }
    a
}

/// What the machine's X, Y and Z directions are in W (columns) at these rotary words: the frame
/// a tilted working plane takes, so that its Z is the tool axis and its X Y are the machine's as
/// the rotaries carry them. Column 2 is [`tool_axis`].
pub fn machine_frame(m: &Machine, rotary_words: &[f64; 3]) -> nalgebra::Matrix3<f64> {
    let actual = m.actual_angles(rotary_words);
    let mut f = nalgebra::Matrix3::identity();
    for (r, &th) in m.rotaries.iter().zip(&actual).rev() {
        if r.mount == Mount::Head {
            let (s, c) = th.sin_cos();
            for k in 0..3 {
                let v = rotate(&r.axis, c, s, &f.column(k).into_owned());
                f.set_column(k, &v);
            }
        }
    }
    for (r, &phi) in m.rotaries.iter().zip(&actual) {
        if r.mount == Mount::Table {
            let (s, c) = (-phi).sin_cos();
            for k in 0..3 {
                let v = rotate(&r.axis, c, s, &f.column(k).into_owned());
                f.set_column(k, &v);
            }
        }
    }
    f
}

/// Tip relative to the controlled point, and the tool axis, both in M, for actual head angles:
/// `G_h1(θ1) ∘ … ∘ G_hm(θm)(0)` with head pivots shifted by the tool length.
#[inline]
pub(crate) fn head_offset(m: &Machine, actual: &[f64; 3], tool_length: f64) -> (Vec3, Vec3) {
    let mut v = Vec3::zeros();
    let mut a = Vec3::z();
    for (r, &th) in m.rotaries.iter().zip(actual).rev() {
        if r.mount == Mount::Head {
            let q = r.pivot + Vec3::new(0.0, 0.0, tool_length);
            let (s, c) = th.sin_cos();
            v = q + rotate(&r.axis, c, s, &(v - q));
            a = rotate(&r.axis, c, s, &a);
        }
    }
    (v, a)
}

/// `T(φ)(P) = G_t1(φ1) ∘ … ∘ G_tk(φk)(P)`: where a point of W (work offset included) sits in M.
#[inline]
pub(crate) fn table_to_machine(m: &Machine, actual: &[f64; 3], p: Vec3) -> Vec3 {
    let mut p = p;
    for (r, &phi) in m.rotaries.iter().zip(actual).rev() {
        if r.mount == Mount::Table {
            let (s, c) = phi.sin_cos();
            p = r.pivot + rotate(&r.axis, c, s, &(p - r.pivot));
        }
    }
    p
}

/// The controlled point `(X, Y, Z)` that puts the tip at `tip_w` for the given actual angles.
#[inline]
pub fn controlled_point(m: &Machine, actual: &[f64; 3], tip_w: &Vec3, setup: &Setup) -> Vec3 {
    let (off, _) = head_offset(m, actual, setup.tool_length);
    table_to_machine(m, actual, tip_w + setup.work_offset) - off
}

/// TCP mode's X Y Z for joints: the tip a control's TCP puts there, its kinematics nominal (the
/// rotary words taken as the angles: no control knows the angle error a profile declares). With
/// the linears at the real controlled point, the real tip is the wanted one; on a profile
/// without angle error this is FK's tip.
pub fn tcp_point(m: &Machine, joints: &Joints, setup: &Setup) -> Vec3 {
    fk_actual(m, &joints.linear, &joints.rotary, setup).tip
}

/// The pose a TCP block really reaches: the control places the linears for tip `p` at the
/// nominal angles (the rotary words), the axes stand at the words plus their error.
pub fn tcp_fk(m: &Machine, p: &Vec3, rotary_words: &[f64; 3], setup: &Setup) -> Pose {
    let q = controlled_point(m, rotary_words, p, setup);
    fk_actual(m, &[q.x, q.y, q.z], &m.actual_angles(rotary_words), setup)
}

//! What `kinepost verify` is given for a program posted with a profile's defaults.

use kinepost::kinematics::{Machine, Setup, Vec3};
use kinepost::post::Mode;
use kinepost::post::verify::VerifyOptions;

/// The profile's tool length until the CL sets one, no work offset, 0.01 (profile units) and
/// 0.01°.
pub fn options(m: &Machine, mode: Mode) -> VerifyOptions {
    VerifyOptions {
        mode,
        setup: Setup::new(m.default_tool_length, Vec3::zeros()),
        tolerance: 0.01,
        angle_tolerance_deg: 0.01,
        cl_units: None,
        cl_tool_length: true,
        tool_table: None,
    }
}

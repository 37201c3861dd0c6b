//! kinepost: a 5-axis CNC postprocessor. See ARCHITECTURE.md for the map.

pub mod cli;
pub mod kinematics;
pub mod machines;
pub mod cl;
pub mod diag;

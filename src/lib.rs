//! kinepost: a 5-axis CNC postprocessor. See ARCHITECTURE.md for the map.

pub mod calib;
pub mod collide;
pub mod cl;
pub mod db;
pub mod diag;
pub mod http;
pub mod jobs;
pub mod kinematics;
pub mod machines;
pub mod nc;
pub mod output;
pub mod post;
pub mod spool;
pub mod testgen;
pub mod text;

//! The integration tests, one binary: each file here was a test crate of its own, and each
//! linked the whole library and its dependencies again (29 links were most of `cargo test`'s
//! compile time). A file is a module now; `common/` is what they share. Run one file's tests
//! with its module path as the filter: `cargo test --test it post::`.

mod common;

mod architecture;
mod calib;
mod cli;
mod collide;
mod cutcom;
mod dialect_files;
mod dialects;
mod faults;
mod hardening;
mod hostile;
mod http;
mod job_diagnostics;
mod job_lines;
mod jobs;
mod kinematics;
mod linuxcnc;
mod machines_api;
mod malformed;
mod policy;
mod post;
mod profiles;
mod readme;
mod replicas;
mod setups;
mod shutdown;
mod threads;
mod tools;
mod tools_api;
mod vocabulary;

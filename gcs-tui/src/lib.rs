//! `mech-gcs`: the MECH ground-control station.

pub mod gamepad;
pub mod ui;

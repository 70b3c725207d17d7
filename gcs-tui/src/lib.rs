//! `mech-gcs`: the MECH ground-control station.
pub mod control;

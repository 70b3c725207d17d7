//! `mech-gcs`: the MECH ground-control station.

//! Terminal user interface.

pub mod viewport;

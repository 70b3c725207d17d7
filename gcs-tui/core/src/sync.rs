//! Locking shared by the station's layers.

use std::sync::{Mutex, MutexGuard, PoisonError};

/// Locks a mutex, recovering the data if a panicking thread poisoned it.
/// Every critical section in the station is a few assignments or counter
/// increments, so no half-written state survives a panic, and the router,
/// fleet model and controllers stay usable rather than fail for good.
pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

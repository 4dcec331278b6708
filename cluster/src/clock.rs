//! Wall-clock stamps for messages and recordings (every process on one clock convention).

use std::time::{SystemTime, UNIX_EPOCH};

/// Nanoseconds since the Unix epoch (MCAP log times).
pub fn unix_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// Milliseconds since the Unix epoch (`Metrics.unix_time_ms`).
pub fn unix_ms() -> u64 {
    unix_ns() / 1_000_000
}

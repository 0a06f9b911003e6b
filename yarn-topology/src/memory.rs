//! Memory the system can still give out, so that a fabric too large for it
//! is refused with an error instead of the process being killed part way
//! through building it.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::TopologyError;

/// The cap [`limit_memory`] set, `u64::MAX` for none.
static LIMIT: AtomicU64 = AtomicU64::new(u64::MAX);

/// Cap the memory yarnify's checks count as available at `bytes`, for the
/// whole process, or lift the cap with `None`: a tool that shares the
/// machine keeps its fabrics within a budget, and they are refused with
/// [`TopologyError::OutOfMemory`] past it, exactly as past the system's
/// free memory.
///
/// ```
/// use yarn_topology::{Chart, Fabric, Geometry, TopologyError, limit_memory};
///
/// limit_memory(Some(1 << 20));
/// let refused = Chart::stockinette(64, 64).and_then(|c| Fabric::from_chart(&c, &Geometry::default()));
/// assert!(matches!(refused, Err(TopologyError::OutOfMemory { available: 1_048_576, .. })));
/// limit_memory(None);
/// ```
pub fn limit_memory(bytes: Option<u64>) {
    LIMIT.store(bytes.unwrap_or(u64::MAX), Ordering::Relaxed);
}

/// Bytes the system can still allocate without swapping, `MemAvailable`
/// in `/proc/meminfo` on Linux, capped by [`limit_memory`]; `None` where
/// neither is known (other systems without a cap), and then nothing is
/// refused for memory.
pub fn available_memory() -> Option<u64> {
    let limit = Some(LIMIT.load(Ordering::Relaxed)).filter(|&l| l != u64::MAX);
    match (system_available(), limit) {
        (Some(free), Some(limit)) => Some(free.min(limit)),
        (free, limit) => free.or(limit),
    }
}

/// `MemAvailable` from `/proc/meminfo`, in bytes.
fn system_available() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// Refuse `needed` bytes for `what` when fewer are `available`.
///
/// # Errors
/// [`TopologyError::OutOfMemory`], naming both figures.
pub fn check_memory(what: &'static str, needed: u64, available: Option<u64>) -> Result<(), TopologyError> {
    match available {
        Some(available) if needed > available => Err(TopologyError::OutOfMemory { what, needed, available }),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn more_than_is_available_is_refused_with_both_figures() {
        assert!(check_memory("x", 10, Some(10)).is_ok());
        assert!(check_memory("x", 10, None).is_ok(), "unknown memory refuses nothing");
        let error = check_memory("the fabric (bytes)", 11, Some(10)).unwrap_err();
        assert_eq!(error, TopologyError::OutOfMemory { what: "the fabric (bytes)", needed: 11, available: 10 });
        let text = error.to_string();
        assert!(text.contains("11") && text.contains("10") && text.contains("MemAvailable"), "{text}");
    }

    #[test]
    fn this_system_reports_some_memory() {
        if cfg!(target_os = "linux") {
            let bytes = available_memory().expect("Linux has /proc/meminfo");
            assert!(bytes > 1 << 20, "only {bytes} bytes available");
        }
    }
}

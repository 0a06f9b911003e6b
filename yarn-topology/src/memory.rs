//! Memory the system can still give out, so that a fabric too large for it
//! is refused with an error instead of the process being killed part way
//! through building it.

use crate::TopologyError;

/// Bytes the system can still allocate without swapping: `MemAvailable` in
/// `/proc/meminfo` on Linux; `None` where that is not known (other systems),
/// and then nothing is refused for memory.
pub fn available_memory() -> Option<u64> {
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

//! The process's peak resident memory, as the kernel counts it (Linux: `VmHWM` in
//! `/proc/self/status`, reset by writing 5 to `/proc/self/clear_refs`). Elsewhere the figures
//! are `None`.

/// Resets the peak to the memory resident now, so that [`peak_mib`] measures what follows.
/// Returns false where the kernel does not offer it (the peak then runs from the start).
pub fn reset_peak() -> bool {
    std::fs::write("/proc/self/clear_refs", b"5").is_ok()
}

/// The largest resident memory since the start or the last [`reset_peak`], MiB.
pub fn peak_mib() -> Option<f64> {
    status_kib("VmHWM:").map(|kib| kib / 1024.0)
}

/// The memory resident now, MiB.
pub fn resident_mib() -> Option<f64> {
    status_kib("VmRSS:").map(|kib| kib / 1024.0)
}

fn status_kib(field: &str) -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(field))?;
    line[field.len()..]
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_peak_covers_memory_touched_after_a_reset() {
        if !reset_peak() {
            return; // Not Linux: nothing to check.
        }
        let before = peak_mib().unwrap();
        // black_box: an optimizer may drop an allocation nothing reads, and the test with it.
        let block = std::hint::black_box(vec![1u8; 64 << 20]);
        let after = peak_mib().unwrap();
        assert!(after >= before + 60.0, "{before} MiB -> {after} MiB");
        assert!(resident_mib().unwrap() <= after + 1.0);
        drop(block);
    }
}

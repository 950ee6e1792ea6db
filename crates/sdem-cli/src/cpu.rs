//! The CPU time this process's threads have used, as the kernel counts it (Linux: the first
//! field of `/proc/self/task/*/schedstat`, nanoseconds). Elsewhere the figures are `None`.
//!
//! Unlike the wall clock it does not count what other jobs on the machine take: a bench's CPU
//! time per stop holds on a loaded machine where its wall time does not. It counts the threads
//! alive when it is read (rayon's pool lives as long as the process), so a difference of two
//! readings can only miss the work of a thread that ended in between.

/// The CPU time of every thread of this process so far, ms; `None` where the kernel does not
/// say.
pub fn used_ms() -> Option<f64> {
    let tasks = std::fs::read_dir("/proc/self/task").ok()?;
    let ns: Vec<f64> = (tasks.flatten())
        .filter_map(|task| std::fs::read_to_string(task.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse().ok())
        .collect();
    (!ns.is_empty()).then(|| ns.iter().sum::<f64>() / 1e6)
}

/// The CPU time used between a reading `before` and now, ms (never below 0).
pub fn since_ms(before: Option<f64>) -> Option<f64> {
    Some((used_ms()? - before?).max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fixed amount of work: its CPU time does not depend on the machine's load.
    fn work() {
        let mut x = 0u64;
        for _ in 0..30_000_000 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
        }
    }

    #[test]
    fn work_on_two_threads_counts_twice() {
        const CHILD: &str = "SDEM_CPU_TEST_ALONE";
        if std::env::var_os(CHILD).is_none() {
            // Other tests run on threads of this process, and their time counts too: the
            // check runs alone, in a process of its own.
            let status = std::process::Command::new(std::env::current_exe().unwrap())
                .args(["--exact", "cpu::tests::work_on_two_threads_counts_twice"])
                .args(["--test-threads=1", "--nocapture"])
                .env(CHILD, "1")
                .status()
                .unwrap();
            assert!(status.success(), "{status}");
            return;
        }
        let Some(before) = used_ms() else {
            return; // Not Linux: nothing to check.
        };
        work();
        let one = since_ms(Some(before)).unwrap();
        let before = used_ms();
        let (worked, has_worked) = std::sync::mpsc::channel::<()>();
        let (read, was_read) = std::sync::mpsc::channel::<()>();
        std::thread::scope(|s| {
            s.spawn(move || {
                work();
                worked.send(()).unwrap();
                // Alive until read: a thread that has ended is no longer counted.
                let _ = was_read.recv();
            });
            work();
            has_worked.recv().unwrap();
            let two = since_ms(before).unwrap();
            read.send(()).unwrap();
            assert!(two > 1.6 * one, "one thread {one:.1} ms, two {two:.1} ms");
        });
    }
}

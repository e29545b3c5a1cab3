//! The process's allocator settings: glibc's malloc keeps freed memory for the next fit instead
//! of handing it back to the OS after every model evaluation (issue 38, point 2).
//!
//! Why: a single-joint fit allocates its simulation, sensitivity and Jacobian arrays per model
//! evaluation; a 30 s, 500 Hz record's are 120–360 kB each. glibc serves blocks ≥ 128 kB
//! (`M_MMAP_THRESHOLD`, adjusted upward only as far as the last freed block) with `mmap` and
//! returns the heap's free top ≥ 128 kB (`M_TRIM_THRESHOLD`) with `brk`, so every evaluation
//! touched fresh pages: measured on `J5_baseline.json` (14,676 samples; `joint_fit_probe
//! --repeat 200`, `perf stat`), 358 page faults per fit and 11 % of its CPU time, all of it in the
//! kernel. With the settings below: 4 faults per fit, no kernel time.
//!
//! Cost, stated: the process keeps up to [`TRIM_THRESHOLD_BYTES`] of freed heap per arena
//! instead of returning it, and blocks up to [`MMAP_THRESHOLD_BYTES`] come from the heap (a
//! 100k-sample record's largest arrays are a few MB). The worker's memory therefore stays near
//! its high-water mark between fits, which is what a process that fits trace after trace
//! needs anyway. Only on glibc (`target_env = "gnu"`); elsewhere [`tune`] does nothing.

/// Blocks below this come from the heap, not from their own `mmap` (glibc's largest allowed
/// value on 64-bit: `HEAP_MAX_SIZE / 2`).
pub const MMAP_THRESHOLD_BYTES: i32 = 32 * 1024 * 1024;

/// Free memory at an arena's top is returned to the OS only above this.
pub const TRIM_THRESHOLD_BYTES: i32 = 128 * 1024 * 1024;

/// What [`tune`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tuned {
    /// Both thresholds set.
    Set,
    /// glibc refused a setting (`mallopt` returned 0); the defaults stay.
    Refused,
    /// Not glibc: nothing to set.
    NotGlibc,
}

/// Sets glibc malloc's mmap and trim thresholds for a process that fits trace after trace.
/// Call once at the start of `main`, before threads start (each binary does). Idempotent.
pub fn tune() -> Tuned {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: mallopt only changes malloc's parameters; it is called with glibc's own
        // constants and in-range values, and glibc serialises it against allocation.
        let ok = unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1
                && libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1
        };
        if ok { Tuned::Set } else { Tuned::Refused }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        Tuned::NotGlibc
    }
}

#[cfg(all(test, target_os = "linux", target_env = "gnu"))]
mod tests {
    use super::*;

    /// Minor page faults of this thread so far.
    fn minor_faults() -> i64 {
        // SAFETY: getrusage writes the struct it is given.
        unsafe {
            let mut u: libc::rusage = std::mem::zeroed();
            assert_eq!(libc::getrusage(libc::RUSAGE_THREAD, &mut u), 0);
            u.ru_minflt
        }
    }

    /// Allocate, touch every page of, and free a `bytes` block; the faults it took.
    fn touch_and_free(bytes: usize) -> i64 {
        let before = minor_faults();
        let v = std::hint::black_box(vec![1u8; bytes]);
        let sum: u64 = v.iter().step_by(4096).map(|&b| u64::from(b)).sum();
        assert_eq!(sum as usize, bytes.div_ceil(4096));
        drop(v);
        minor_faults() - before
    }

    #[test]
    fn a_freed_block_is_reused_without_new_page_faults() {
        assert_eq!(tune(), Tuned::Set);
        assert_eq!(tune(), Tuned::Set, "idempotent");
        // 2 MB: far above glibc's default thresholds (128 kB). Without the settings the first
        // block is an mmap, returned on free; glibc then raises its thresholds only as far as
        // that block, so the heap grows and shrinks again and the reuses fault too (measured:
        // 512 faults over the five).
        let bytes = 2 * 1024 * 1024;
        let first = touch_and_free(bytes);
        let again: i64 = (0..5).map(|_| touch_and_free(bytes)).sum();
        assert!(
            again < 20,
            "five reuses of a freed 2 MB block took {again} page faults (the first took {first})"
        );
    }
}

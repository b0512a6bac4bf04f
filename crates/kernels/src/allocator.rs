//! Keeps freed buffers in the process's heap instead of handing them back to the system.
//!
//! Design decision: a forward pass allocates and frees buffers of one to tens of megabytes in
//! every iteration (each convolution's output, the host kernels' copies of their inputs). glibc
//! serves such sizes with fresh `mmap` pages or trims its heap after they are freed, so the next
//! pass faults the pages in again and the kernel zero-fills them: in a profile of a 384x448 pass,
//! page faults and page clearing took about 8 % of the cycles. Raising the `mmap` threshold to
//! its maximum (32 MiB), disabling trimming and growing the heap in 256 MiB steps keeps those
//! pages mapped for reuse: -13 to -17 % wall time for the same pass on this project's 2-core
//! machine, the same peak memory (the buffers a pass needs are live at once anyway). The binary
//! and the benchmarks call [`retain_freed_memory`] once at start; a library never changes
//! process-wide allocator settings on its own. A no-op other than on Linux with glibc.
#![allow(unsafe_code)]

/// Tunes glibc's allocator to keep freed memory for reuse (see the module documentation).
/// Returns whether every setting was accepted (always `false` where it does nothing).
pub fn retain_freed_memory() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        const MMAP_THRESHOLD_MAX: libc::c_int = 32 << 20;
        const TOP_PAD: libc::c_int = 256 << 20;
        // SAFETY: `mallopt` only changes allocator parameters; it is called with valid option
        // codes and values in range, and glibc serialises it against concurrent allocation.
        unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_MAX) == 1
                && libc::mallopt(libc::M_TRIM_THRESHOLD, libc::c_int::MAX) == 1
                && libc::mallopt(libc::M_TOP_PAD, TOP_PAD) == 1
        }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}

/// Hands the heap's free memory back to the system (glibc's `malloc_trim`), for a caller that
/// has finished one unit of work (a stereo pair) and starts the next: with
/// [`retain_freed_memory`] the buffers freed during a pass stay resident, and the next pass's
/// largest tensors (above the `mmap` threshold, mapped fresh) would add to them. The next pass
/// faults its heap pages in again, as a fresh process does. Returns whether memory was released
/// (always `false` where it does nothing).
pub fn release_freed_memory() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: `malloc_trim` only returns free heap pages to the system; glibc serialises it
        // against concurrent allocation.
        unsafe { libc::malloc_trim(0) == 1 }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}

/// The size of the last pass [`release_before_pass`] was told of (0 before the first).
static LAST_PASS_SIZE: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Called before each pass of a sequence (pairs of a data set, a benchmark's runs) with the
/// pass's working size: hands the freed memory back ([`release_freed_memory`]) only where the
/// size differs from the last pass's. Returns whether it released.
///
/// Design decision: a pass of the same size reuses the very buffers the last one freed, and
/// handing them back made it fault every page in again. Measured on the Xeon (`bench`, same
/// binary, releasing between runs or not, alternating): 384x448 x 12, three rounds, median
/// 3.52 / 3.72 / 3.57 s -> 3.54 / 3.39 / 3.47 s (min 3.50 / 3.58 / 3.48 -> 3.44 / 3.30 /
/// 3.38), peak 370 -> 395 MiB; a KITTI frame (375x1242) x 8: 7.38 -> 7.05 s, peak 667 -> 739
/// MiB (the retained heap plus the next pass's tensors above the `mmap` threshold, which are
/// mapped afresh either way). Where the size changes, the last pass's buffers fit the new one
/// badly and would only add to its peak, so they go back.
pub fn release_before_pass([h, w]: [usize; 2]) -> bool {
    let key = ((h as u64) << 32) | (w as u64 & 0xffff_ffff);
    let last = LAST_PASS_SIZE.swap(key, std::sync::atomic::Ordering::Relaxed);
    last != 0 && last != key && release_freed_memory()
}

#[cfg(test)]
mod tests {
    /// A new size releases, the same size again does not, the first pass never does.
    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn only_a_change_of_size_releases() {
        // The only test that touches the process-wide last size.
        assert!(!super::release_before_pass([3, 5]), "the first pass");
        assert!(!super::release_before_pass([3, 5]), "the same size");
        assert!(super::release_before_pass([5, 3]), "a new size");
        assert!(!super::release_before_pass([5, 3]), "the same size again");
    }

    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn glibc_accepts_the_settings() {
        assert!(super::retain_freed_memory());
        // Allocation still works and memory is reused.
        let a = vec![1.0f32; 4 << 20];
        assert_eq!(a.iter().sum::<f32>(), (4 << 20) as f32);
    }
}

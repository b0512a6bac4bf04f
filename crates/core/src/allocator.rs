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

#[cfg(test)]
mod tests {
    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn glibc_accepts_the_settings() {
        assert!(super::retain_freed_memory());
        // Allocation still works and memory is reused.
        let a = vec![1.0f32; 4 << 20];
        assert_eq!(a.iter().sum::<f32>(), (4 << 20) as f32);
    }
}

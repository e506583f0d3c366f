//! The heap's settings for a long run on many threads.
//!
//! glibc gives freed memory at the top of each arena back to the system once more than its
//! trim threshold is free there, and serves blocks above its mmap threshold with fresh
//! mappings. The registration's per-frame buffers (a few hundred KiB each, allocated and freed
//! thousands of times on rayon's threads) then fault their pages in anew each time: the
//! demo build spent 11 s in the kernel. Keeping freed memory in the process: 2 s, and the
//! build 80 -> 73 s wall (BENCHMARKS.md, session 41).

/// Keep freed memory in the process rather than returning it to the system after each free
/// (glibc on Linux; elsewhere nothing). Call once, before the work starts.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets the allocator's tuning parameters; it is called before any
    // thread is started. A value it refuses leaves the default (its return value).
    unsafe {
        // 32 MiB is the largest mmap threshold glibc accepts on 64-bit systems; setting it also
        // stops glibc from moving the threshold (and the trim threshold) on its own.
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
        libc::mallopt(libc::M_TOP_PAD, 256 << 20);
    }
}

//! How the two commands' allocator keeps freed memory.

/// Asks glibc's allocator to keep freed memory for reuse instead of handing it back to the
/// system: blocks of up to 32 MiB (the most glibc allows) come from the heap rather than fresh
/// mappings, the heap is trimmed only beyond 1 GiB of free space at its top, and it grows
/// 64 MiB at a time. Each DAG level allocates and frees buffers of tens of megabytes (a large
/// mesh's level-0 samples, measured again at every level); with the defaults each came from
/// pages the system had to zero again (the Stanford dragon: about 118 K page faults against
/// 100 K; docs/BENCHMARKS.md, thirteenth session). The writer still
/// trims the heap itself where it frees the encoded clusters (`mres_format::write`), so peak
/// memory does not grow by what is kept here. Call first thing in `main`, before any thread
/// starts. Elsewhere than glibc it does nothing.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes the allocator's tuning parameters; called before any other
    // thread exists, it cannot race an allocation.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
        libc::mallopt(libc::M_TOP_PAD, 64 << 20);
    }
}

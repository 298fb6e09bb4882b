//! How the process's memory is kept bounded and given back to the system (glibc's allocator).
//!
//! Left to itself, glibc keeps what the program frees: each of the runtime's threads gets an arena
//! of its own (up to 8 per core), whose freed pages stay resident, and after the console's password
//! hashing (a buffer of about 19 MB, freed at once) it raises its thresholds so far that the main
//! heap is never trimmed again. A running system then holds about 18 MB it does not use, and its
//! resident memory creeps up for minutes as the threads' arenas take turns growing.
//!
//! [`bound`] limits the arenas and fixes the thresholds before any thread starts; [`give_back`]
//! returns the free pages to the system now and then. Other C libraries: nothing to do.

use std::time::Duration;

/// How often free memory is given back.
pub const EVERY: Duration = Duration::from_secs(10);

/// Limits the allocator's arenas and fixes its thresholds; call before any thread starts.
pub fn bound() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets the allocator's parameters; no thread allocates yet
    unsafe {
        libc::mallopt(libc::M_ARENA_MAX, 2);
        // set explicitly, they no longer grow with the largest block freed: large blocks are
        // mapped and unmapped, and the top of the heap is trimmed past 1 MB
        libc::mallopt(libc::M_MMAP_THRESHOLD, 256 * 1024);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1024 * 1024);
    }
}

/// Returns the allocator's free pages to the system (a pass over its free lists, well under a
/// millisecond at a running system's size).
pub fn give_back() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim takes the allocator's own locks
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Gives free memory back every [`EVERY`], for as long as the system runs.
pub async fn keep_giving_back() {
    let mut tick = tokio::time::interval(EVERY);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tick.tick().await;
        give_back();
    }
}

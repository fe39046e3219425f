//! This thread's CPU time, for benchmarks that report it beside wall time (on a loaded,
//! shared machine it is the steadier figure). Shared by benches/full_frame.rs and
//! benches/sim.rs.
//!
//! `clock_gettime(CLOCK_THREAD_CPUTIME_ID)`: nanosecond resolution. (`/proc/thread-self/schedstat`,
//! used before, reads 0 on kernels built without scheduler statistics — this machine's.)

/// This thread's CPU time in nanoseconds; `None` where the clock is not available.
#[cfg(unix)]
pub fn thread_cpu_ns() -> Option<u64> {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec for the duration of the call.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    (rc == 0).then(|| ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64)
}

/// This thread's CPU time in nanoseconds; `None` where the clock is not available.
#[cfg(not(unix))]
pub fn thread_cpu_ns() -> Option<u64> {
    None
}

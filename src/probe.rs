//! A machine probe for benchmarks: how long a cache line takes to go from one core to another
//! and back. On a VM whose host sometimes places its two vCPUs far apart this changes by ~4x,
//! and with it the speed of two threads that exchange data every step (`benchmarks/NOTES.md`,
//! eighth session): a benchmark that records it can tell the two states apart.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// The bounced value, alone on its 128 bytes (a line and its adjacent-line prefetch partner).
#[repr(align(128))]
struct Line(AtomicU64);

/// Spin this often before yielding the core: on a busy or single-core machine the partner
/// thread may not be running, and a spin without end would hold its core for a time slice.
const SPINS: u32 = 2000;

fn wait_for(line: &Line, v: u64) {
    let mut spins = 0u32;
    while line.0.load(Ordering::Acquire) != v {
        if spins < SPINS {
            spins += 1;
            std::hint::spin_loop();
        } else {
            std::thread::yield_now();
        }
    }
}

/// Pinning the calling thread to one CPU (Linux), with a guard that restores its CPU set.
#[cfg(target_os = "linux")]
pub mod pin {
    /// Restores the thread's CPU set when dropped.
    pub struct Restore(libc::cpu_set_t);

    fn current() -> Option<libc::cpu_set_t> {
        // SAFETY: a zeroed cpu_set_t is valid; the call writes at most its size
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            (libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) == 0)
                .then_some(set)
        }
    }

    /// The first two CPUs this thread may run on.
    pub fn two_cpus() -> Option<(usize, usize)> {
        let set = current()?;
        // SAFETY: CPU_ISSET reads the set within its size
        let mut cpus =
            (0..libc::CPU_SETSIZE as usize).filter(|&c| unsafe { libc::CPU_ISSET(c, &set) });
        Some((cpus.next()?, cpus.next()?))
    }

    /// Pin the calling thread to `cpu`; the guard (if pinning worked) restores its set.
    pub fn to(cpu: usize) -> Option<Restore> {
        let old = current()?;
        // SAFETY: as above; sched_setaffinity on the calling thread (pid 0)
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(cpu, &mut set);
            (libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0)
                .then_some(Restore(old))
        }
    }

    impl Drop for Restore {
        fn drop(&mut self) {
            // SAFETY: the set read before pinning
            unsafe {
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &self.0);
            }
        }
    }
}

/// Mean round trip, in nanoseconds, of a value bounced `iters` times (at least once) between
/// the calling thread and a helper thread through one cache line. On Linux the two threads
/// are pinned to the first two CPUs the caller may use (the caller's own set restored
/// after); elsewhere, or with one CPU, the OS places them.
pub fn core_round_trip_ns(iters: u64) -> f64 {
    let iters = iters.max(1);
    let line = Line(AtomicU64::new(0));
    #[cfg(target_os = "linux")]
    let cpus = pin::two_cpus();
    #[cfg(target_os = "linux")]
    let _restore = cpus.and_then(|(a, _)| pin::to(a));
    std::thread::scope(|s| {
        s.spawn(|| {
            #[cfg(target_os = "linux")]
            let _pinned = cpus.and_then(|(_, b)| pin::to(b));
            for i in 0..iters {
                wait_for(&line, 2 * i + 1);
                line.0.store(2 * i + 2, Ordering::Release);
            }
        });
        // one bounce first, so that the helper is running before the clock starts
        line.0.store(1, Ordering::Release);
        wait_for(&line, 2);
        let t0 = Instant::now();
        for i in 1..iters {
            line.0.store(2 * i + 1, Ordering::Release);
            wait_for(&line, 2 * i + 2);
        }
        t0.elapsed().as_secs_f64() * 1e9 / (iters - 1).max(1) as f64
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn round_trip_is_a_positive_time() {
        let t = super::core_round_trip_ns(1000);
        assert!(t.is_finite() && t > 0.0, "{t}");
        // one bounce only: no timed round trip, still a number
        assert!(super::core_round_trip_ns(1).is_finite());
    }
}

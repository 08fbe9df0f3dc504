//! Test support that does not depend on the crate under test: whether real OpenVDB is
//! there to compare with, and small deterministic random numbers. Shared by the
//! preprocessor's and the lab's integration tests (the lab includes this file by path).

use std::process::Command;

/// Is `/usr/bin/python3 -c 'import pyopenvdb'` available?
pub fn have_pyopenvdb() -> bool {
    Command::new("/usr/bin/python3")
        .args(["-c", "import pyopenvdb"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

/// Small deterministic random numbers (xorshift64*).
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// Uniform in [0, 1).
    pub fn next(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in `0..n`.
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n
    }
}

/// Waits for `child`, checks that it exited with status 0, and returns its peak resident
/// memory in bytes (the maximum resident set `wait4` reports): for tests that bound a
/// program's memory, which is measured, not its time.
#[allow(unsafe_code)]
pub fn peak_memory(child: std::process::Child) -> u64 {
    let pid = child.id() as libc::pid_t;
    let mut status = 0;
    // SAFETY: `rusage` is plain data that `wait4` fills; the child is ours and not waited
    // for elsewhere (`child` is only dropped, which does not wait).
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let reaped = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    assert_eq!(reaped, pid, "wait4");
    assert!(
        libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0,
        "exit status {status}"
    );
    drop(child);
    usage.ru_maxrss as u64 * 1024 // kilobytes on Linux
}

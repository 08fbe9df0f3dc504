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

//! Any byte string given to the VDB reader must give a grid list or an error, never a
//! panic, hang or huge allocation.
#![no_main]

use libfuzzer_sys::fuzz_target;
use qbricks_preprocess::vdb::{inspect, VdbFile};

fuzz_target!(|data: &[u8]| {
    if let Ok(file) = VdbFile::from_bytes("fuzz.vdb", data.to_vec()) {
        for i in 0..file.grids().len() {
            let _ = file.read_grid(i);
        }
        let _ = inspect::report(&file);
    }
});

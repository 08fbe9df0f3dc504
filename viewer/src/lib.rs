//! qbricks-view: ray casting of `.qbk` brick files.

//! How both qbricks programs treat their files and the machine: one policy, written once,
//! that every command (bake, synth, accuracy, render, sequences, bench, probe, the window)
//! goes through, so a new command cannot re-open an old bug.
//!
//! - [`input`]: inputs are opened without blocking (a FIFO with no writer cannot hang a
//!   run) and read whole only within a limit checked before allocating.
//! - [`output`]: outputs are written to a temporary file and put in place only when
//!   complete; a symlink is written through, a device, FIFO or `/dev/stdout` is written
//!   into, never replaced.
//! - [`guard`]: before anything runs, every output of a command is checked against every
//!   input and every other output (frame patterns expanded, symlinks and hard links seen
//!   through), so no run overwrites what it reads.
//! - [`limits`]: the bounds of every count (threads, repeats, frames) and the one memory
//!   estimate every large allocation is checked against.
//! - [`scratch`]: values kept in a scratch file and read through a mapping whose pages a
//!   pass lets go behind itself.
//! - [`signals`]: temporary files are removed when the process is interrupted.

pub mod guard;
pub mod input;
pub mod limits;
pub mod output;
pub mod scratch;
pub mod signals;

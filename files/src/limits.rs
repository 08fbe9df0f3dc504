//! The bounds every command applies, in one place: counts a user may ask for (threads,
//! repeats, frames, plane samples) and the memory a run may allocate.
//!
//! A count outside its range is refused before any work starts, with the same message in
//! every command (`--threads: expected 1..=256, found 100000`). Memory is checked the same
//! way: a command estimates what a request needs (an image of W×H pixels, a grid of N
//! cells, a list of P points) and [`check_memory`] compares it with [`memory_limit`] —
//! three quarters of the physical memory, or less when an address-space limit
//! (`ulimit -v`) leaves less — so a request the machine cannot serve is refused with its
//! size and the limit instead of killing the process half-way through.

use std::fmt::Display;

/// Most worker threads: far more than any machine's cores, few enough that a typo
/// (`--threads 100000`) cannot exhaust the process's thread and stack limits.
pub const MAX_THREADS: usize = 256;
/// Most repetitions of a timed render (a median needs a handful, not billions).
pub const MAX_REPEAT: u32 = 1000;
/// Most frames in one sequence, `--frames` range or `synth --frames` (a typo like
/// `1..1000000000` would otherwise stand for a billion files).
pub const MAX_FRAMES: u64 = 100_000;
/// Most UI frames of a scripted orbit (`--orbit-frames`): an hour at 30 frames per second.
pub const MAX_ORBIT_FRAMES: u32 = 108_000;
/// Most samples along each side of a sampled plane (`probe --plane … --resolution`): as
/// many as the largest image a render may make is wide.
pub const MAX_PLANE_SIDE: u64 = 16_384;

/// A request outside the bounds.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LimitError {
    #[error("{flag}: expected {min}..={max}, found {found}")]
    Count {
        flag: String,
        min: String,
        max: String,
        found: String,
    },
    #[error(
        "{what} needs about {} MiB, more than the limit of {} MiB ({why})",
        need >> 20,
        limit >> 20
    )]
    Memory {
        what: String,
        need: u64,
        limit: u64,
        why: String,
    },
    #[error(
        "{what} needs up to {} MiB, more than the {} MiB free in {}",
        need >> 20,
        free >> 20,
        dir.display()
    )]
    Disk {
        what: String,
        need: u64,
        free: u64,
        dir: std::path::PathBuf,
    },
}

/// `value` if it lies in `min..=max`, else the error naming `flag`.
pub fn count<T: PartialOrd + Display + Copy>(
    flag: &str,
    value: T,
    min: T,
    max: T,
) -> Result<T, LimitError> {
    if value >= min && value <= max {
        Ok(value)
    } else {
        Err(LimitError::Count {
            flag: flag.to_string(),
            min: min.to_string(),
            max: max.to_string(),
            found: value.to_string(),
        })
    }
}

/// `--threads`: `None` (one per core) or 1..=[`MAX_THREADS`].
pub fn threads(value: Option<usize>) -> Result<Option<usize>, LimitError> {
    value
        .map(|t| count("--threads", t, 1, MAX_THREADS))
        .transpose()
}

/// `--repeat`: 1..=[`MAX_REPEAT`].
pub fn repeat(value: u32) -> Result<u32, LimitError> {
    count("--repeat", value, 1, MAX_REPEAT)
}

/// Smallest memory budget (`--memory`): below it nothing bakes, whatever the input.
pub const MIN_MEMORY_BUDGET: u64 = 16 << 20;

/// A memory size as a user writes it (`--memory 2G`): a number of bytes, or of KiB, MiB,
/// GiB or TiB with the suffix `K`, `M`, `G`, `T` (binary units, as `ulimit` and container
/// limits read them; `KiB`, `MB`, `g` … are taken the same way); fractions allowed
/// (`1.5G`). Refused outside [`MIN_MEMORY_BUDGET`] to 2^50 bytes.
pub fn memory_size(flag: &str, text: &str) -> Result<u64, LimitError> {
    let t = text.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (number, unit) = t.split_at(split);
    let shift = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => Some(0),
        "k" | "kb" | "kib" => Some(10),
        "m" | "mb" | "mib" => Some(20),
        "g" | "gb" | "gib" => Some(30),
        "t" | "tb" | "tib" => Some(40),
        _ => None,
    };
    let (min, max) = (MIN_MEMORY_BUDGET, 1u64 << 50);
    let bad = || LimitError::Count {
        flag: flag.to_string(),
        min: "16M".to_string(),
        max: "1024T (a size: bytes, or K, M, G, T)".to_string(),
        found: text.to_string(),
    };
    let (Some(shift), Ok(n)) = (shift, number.parse::<f64>()) else {
        return Err(bad());
    };
    let bytes = n * (1u64 << shift) as f64;
    if !(bytes >= min as f64 && bytes <= max as f64) {
        return Err(bad());
    }
    Ok(bytes as u64)
}

/// Refuses `bytes` of address space for `what` when an address-space limit (`ulimit -v`)
/// leaves less. Memory mapped from files takes address space whether its pages are
/// resident or not: a run that keeps gigabytes in mapped scratch files checks this beside
/// [`check_memory`], which looks at what it holds.
pub fn check_address_space(what: impl Display, bytes: u64) -> Result<(), LimitError> {
    match address_space_left() {
        Some(left) if bytes > left => Err(LimitError::Memory {
            what: what.to_string(),
            need: bytes,
            limit: left,
            why: "what the address-space limit, ulimit -v, leaves".to_string(),
        }),
        _ => Ok(()),
    }
}

/// `--resolution NU,NV` of a sampled plane: each side 1..=[`MAX_PLANE_SIDE`]. The memory
/// the samples take is checked by the command, which knows how many fields it keeps.
pub fn plane_resolution(nu: u64, nv: u64) -> Result<[u32; 2], LimitError> {
    let side = |n| count("--resolution", n, 1, MAX_PLANE_SIDE).map(|n| n as u32);
    Ok([side(nu)?, side(nv)?])
}

/// What a run may allocate, and why it is that much.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MemoryLimit {
    pub bytes: u64,
    pub why: String,
}

/// Three quarters of the physical memory, or what the address-space limit leaves above
/// what the process has mapped already, whichever is less. Without either figure (not
/// Linux), no limit.
pub fn memory_limit() -> MemoryLimit {
    let physical = physical_memory().map(|m| MemoryLimit {
        bytes: m / 4 * 3,
        why: "three quarters of this machine's memory".to_string(),
    });
    let address_space = address_space_left().map(|left| MemoryLimit {
        bytes: left,
        why: "what the address-space limit, ulimit -v, leaves".to_string(),
    });
    match (physical, address_space) {
        (Some(p), Some(a)) => {
            if a.bytes < p.bytes {
                a
            } else {
                p
            }
        }
        (Some(l), None) | (None, Some(l)) => l,
        (None, None) => MemoryLimit {
            bytes: u64::MAX,
            why: "no limit known".to_string(),
        },
    }
}

/// Refuses `need` bytes for `what` (`a 16384x16384 image`) when it is over
/// [`memory_limit`].
pub fn check_memory(what: impl Display, need: u64) -> Result<(), LimitError> {
    check_memory_within(what, need, memory_limit())
}

/// [`check_memory`] with a fixed cap of its own as well (`cap`, said as `cap_why`), for
/// requests that should stay small whatever the machine.
pub fn check_memory_capped(
    what: impl Display,
    need: u64,
    cap: u64,
    cap_why: &str,
) -> Result<(), LimitError> {
    let mut limit = memory_limit();
    if cap < limit.bytes {
        limit = MemoryLimit {
            bytes: cap,
            why: cap_why.to_string(),
        };
    }
    check_memory_within(what, need, limit)
}

fn check_memory_within(
    what: impl Display,
    need: u64,
    limit: MemoryLimit,
) -> Result<(), LimitError> {
    if need <= limit.bytes {
        return Ok(());
    }
    Err(LimitError::Memory {
        what: what.to_string(),
        need,
        limit: limit.bytes,
        why: limit.why,
    })
}

/// A vector of `n` default values, after checking its size against the memory limit and
/// reserving it fallibly (an allocation the system refuses is an error, not an abort).
pub fn vec_of<T: Clone + Default>(what: impl Display, n: usize) -> Result<Vec<T>, LimitError> {
    let mut v = with_capacity(what, n)?;
    v.resize(n, T::default());
    Ok(v)
}

/// A vector of `n` zero values, checked as [`vec_of`], whose pages the system hands out
/// only as they are first written: a large one costs no resident memory up front, so a
/// caller that fills it while freeing what it fills it from (the bake's cells from the
/// decoded leaves) never holds both whole.
pub fn zeroed_vec_of<T: bytemuck::Zeroable>(
    what: impl Display,
    n: usize,
) -> Result<Vec<T>, LimitError> {
    let need = (n as u64).saturating_mul(std::mem::size_of::<T>() as u64);
    let limit = memory_limit();
    check_memory_within(&what, need, limit.clone())?;
    bytemuck::allocation::try_zeroed_vec(n).map_err(|()| LimitError::Memory {
        what: what.to_string(),
        need,
        limit: limit.bytes,
        why: "the system refused the allocation".to_string(),
    })
}

/// An empty vector with room for `n` values, checked as [`vec_of`].
pub fn with_capacity<T>(what: impl Display, n: usize) -> Result<Vec<T>, LimitError> {
    let need = (n as u64).saturating_mul(std::mem::size_of::<T>() as u64);
    let limit = memory_limit();
    check_memory_within(&what, need, limit.clone())?;
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| LimitError::Memory {
        what: what.to_string(),
        need,
        limit: limit.bytes,
        why: "the system refused the allocation".to_string(),
    })?;
    Ok(v)
}

/// Total physical memory from `/proc/meminfo` (Linux); `None` where it cannot be read.
pub fn physical_memory() -> Option<u64> {
    meminfo("MemTotal:")
}

/// Memory available to new allocations without swapping (`MemAvailable`, Linux).
pub fn available_memory() -> Option<u64> {
    meminfo("MemAvailable:")
}

fn meminfo(key: &str) -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with(key))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// The soft address-space limit minus the address space in use (`VmSize`), when there
/// is such a limit.
pub fn address_space_left() -> Option<u64> {
    #[cfg(unix)]
    {
        let limit = rustix::process::getrlimit(rustix::process::Resource::As).current?;
        Some(limit.saturating_sub(own_status_bytes("VmSize:")?))
    }
    #[cfg(not(unix))]
    None
}

/// This process's peak resident memory in bytes (`VmHWM`: the most it held at once since
/// it started, its own program's, unlike `getrusage`, which also counts what the parent
/// held when it was started), where the system tells.
pub fn peak_resident() -> Option<u64> {
    own_status_bytes("VmHWM:")
}

/// A size line (`key  1234 kB`) of `/proc/self/status`, in bytes.
fn own_status_bytes(key: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let kib: u64 = status
        .lines()
        .find(|l| l.starts_with(key))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()?;
    kib.checked_mul(1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_sizes_read_in_binary_units_and_out_of_range_ones_are_refused() {
        let m = |t: &str| memory_size("--memory", t);
        assert_eq!(m("64M"), Ok(64 << 20));
        assert_eq!(m("64MiB"), Ok(64 << 20));
        assert_eq!(m(" 2g "), Ok(2 << 30));
        assert_eq!(m("1.5G"), Ok(3 << 29));
        assert_eq!(m("16777216"), Ok(16 << 20));
        assert_eq!(m("1T"), Ok(1 << 40));
        for bad in ["", "M", "15M", "64Q", "-1G", "1e9", "2000T", "nan", "1..5G"] {
            let e = m(bad).expect_err(bad);
            assert!(
                e.to_string().starts_with("--memory: expected 16M..="),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn counts_name_the_flag_the_range_and_the_value() {
        assert_eq!(threads(Some(8)), Ok(Some(8)));
        assert_eq!(threads(None), Ok(None));
        let e = threads(Some(100_000)).expect_err("too many");
        assert_eq!(e.to_string(), "--threads: expected 1..=256, found 100000");
        assert_eq!(
            repeat(0).expect_err("zero").to_string(),
            "--repeat: expected 1..=1000, found 0"
        );
        assert_eq!(plane_resolution(16_384, 1), Ok([16_384, 1]));
        assert_eq!(
            plane_resolution(256, 16_385)
                .expect_err("too many")
                .to_string(),
            "--resolution: expected 1..=16384, found 16385"
        );
        assert_eq!(
            plane_resolution(0, 8).expect_err("zero").to_string(),
            "--resolution: expected 1..=16384, found 0"
        );
    }

    #[test]
    fn memory_beyond_the_limit_is_refused_with_size_and_limit() {
        let e = check_memory_capped("a 16384x16384 image", 12 << 30, 8 << 30, "8 GiB")
            .expect_err("too large");
        assert!(
            e.to_string()
                .starts_with("a 16384x16384 image needs about 12288 MiB, more than the limit of"),
            "{e}"
        );
        assert!(check_memory("a small table", 1 << 20).is_ok());
        let e = vec_of::<u64>("the cells", usize::MAX / 8).expect_err("too large");
        assert!(matches!(e, LimitError::Memory { .. }), "{e}");
        assert_eq!(vec_of::<u8>("a few", 3).expect("small"), vec![0; 3]);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn the_machine_reports_its_memory() {
        assert!(physical_memory().is_some_and(|m| m > 1 << 20));
        assert!(memory_limit().bytes > 1 << 20);
    }
}

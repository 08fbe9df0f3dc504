//! Every hostile command-line case of issues 12 and 32 in one table: the command, the exit
//! code, the start of what it prints on stderr (or all of it), and the files that must be
//! byte-identical (or absent) afterwards.
//!
//! Each case runs in a fresh directory holding copies of the inputs it names, under an
//! address-space limit (`ulimit -v`, so a runaway allocation fails inside the case instead of
//! swapping the machine) and a wall-clock timeout (a hang fails the case, the process is
//! killed). Messages are compared from their start, so a case pins the program, the file
//! named and what is said about it.

use crate::common;
use crate::hostile_inputs;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Address-space limit for every case: far above what the sample needs (≈ 300 MB), far
/// below what the unbounded reads of the issue took (12.9 GB).
const MEMORY_LIMIT_KIB: u64 = 3 << 20;
/// Wall-clock limit per case (the slowest case reads 1 GiB of `/dev/zero`).
const TIMEOUT: Duration = Duration::from_secs(60);

#[derive(Clone, Copy, PartialEq)]
enum Out {
    /// Stdout is captured.
    Captured,
    /// Stdout is a pipe whose reader is already gone (`… | true`).
    Closed,
}

struct Case {
    program: &'static str,
    args: &'static [&'static str],
    code: i32,
    /// Stderr must start with this; empty means stderr must be empty.
    stderr: &'static str,
    /// Lines stderr must have (one, unless a case says otherwise).
    lines: usize,
    /// Stderr must contain each of these too.
    has: &'static [&'static str],
    /// Files that must still be symbolic links to the same target afterwards.
    links: &'static [&'static str],
    /// Address-space limit of the case, KiB.
    limit_kib: u64,
    /// Stderr must be exactly `stderr` (one line), not only start with it: for messages
    /// whose fault was saying something twice.
    exact: bool,
    /// Stdout must contain this (ignored when empty or when stdout is closed).
    stdout: &'static str,
    /// Files that must be byte-identical to what the case directory held before.
    same: &'static [&'static str],
    /// Files that must not exist afterwards (no output, no temporary file of it).
    absent: &'static [&'static str],
    /// Outputs that must exist afterwards, each byte-identical to a reference in the case
    /// directory when one is given (`("o.qbk", "w.qbk")`), else non-empty.
    made: &'static [(&'static str, &'static str)],
    out: Out,
}

const BAKE: &str = "qbricks-bake";
const VIEW: &str = "qbricks-view";
const LAB: &str = "qbricks-lab";

const fn case(
    program: &'static str,
    args: &'static [&'static str],
    code: i32,
    stderr: &'static str,
) -> Case {
    Case {
        program,
        args,
        code,
        stderr,
        lines: 1,
        has: &[],
        links: &[],
        limit_kib: MEMORY_LIMIT_KIB,
        exact: false,
        stdout: "",
        same: &[],
        absent: &[],
        made: &[],
        out: Out::Captured,
    }
}

impl Case {
    const fn same(mut self, files: &'static [&'static str]) -> Self {
        self.same = files;
        self
    }
    const fn absent(mut self, files: &'static [&'static str]) -> Self {
        self.absent = files;
        self
    }
    const fn made(mut self, files: &'static [(&'static str, &'static str)]) -> Self {
        self.made = files;
        self
    }
    const fn closed(mut self) -> Self {
        self.out = Out::Closed;
        self
    }
    const fn stdout(mut self, text: &'static str) -> Self {
        self.stdout = text;
        self
    }
    const fn lines(mut self, n: usize, has: &'static [&'static str]) -> Self {
        self.lines = n;
        self.has = has;
        self
    }
    const fn links(mut self, files: &'static [&'static str]) -> Self {
        self.links = files;
        self
    }
    const fn limit_kib(mut self, kib: u64) -> Self {
        self.limit_kib = kib;
        self
    }
    const fn exact(mut self) -> Self {
        self.exact = true;
        self
    }
}

/// Malformed first lines of a points file: each must be an error at line 1, not a header.
const BAD_FIRST_LINES: &[&str] = &[
    "0,0",
    "0,0,0,0",
    "nan,0,0",
    "1e309,0,0",
    "0;0;0",
    "0 0 0",
    "0x1,0,0",
];

const CASES: &[Case] = &[
    // 1. No lost files: an output that is an input is refused and the input kept.
    case(BAKE, &["bake", "w.vdb", "-o", "w.vdb"], 2,
        "qbricks-bake: w.vdb: -o would overwrite the input file w.vdb, an input of this run")
        .same(&["w.vdb"]),
    // 1. Non-regular outputs are written into, not replaced (checked after the table).
    case(BAKE, &["bake", "w.vdb", "-o", "/dev/null"], 0, ""),
    case(LAB, &["synth", "wake", "--n0", "8", "--levels", "1", "-o", "/dev/null"], 0, ""),
    case(VIEW, &["render", "w.qbk", "-o", "/dev/null", "--width", "8", "--height", "6",
        "--save-state", "/dev/null"], 0, ""),
    // 2. A closed stdout ends quietly, with the output file complete.
    case(BAKE, &["inspect", "--json", "w.vdb"], 0, "").closed(),
    case(BAKE, &["inspect", "w.vdb"], 0, "").closed(),
    // (The baked file records its source's name: bake the sample under its own name.)
    case(BAKE, &["bake", "wake_small.vdb", "-o", "o.qbk"], 0, "")
        .closed()
        .made(&[("o.qbk", "w.qbk")]),
    case(BAKE, &["bake", "wake_small.vdb", "-o", "o.qbk", "--json"], 0, "")
        .closed()
        .made(&[("o.qbk", "w.qbk")]),
    case(LAB, &["synth", "wake", "--n0", "8", "--levels", "2", "-o", "s.vdb"], 0, "")
        .closed()
        .made(&[("s.vdb", "")]),
    case(VIEW, &["info", "--json", "w.qbk"], 0, "").closed(),
    case(VIEW, &["info", "w.qbk"], 0, "").closed(),
    case(VIEW, &["probe", "w.qbk", "--line", "0,0,0:1,0,0:1000", "--json"], 0, "").closed(),
    case(VIEW, &["probe", "w.qbk", "--line", "0,0,0:1,0,0:1000"], 0, "").closed(),
    case(VIEW, &["render", "w.qbk", "-o", "r.png", "--width", "8", "--height", "6", "--json"],
        0, "")
        .closed()
        .made(&[("r.png", "")]),
    case(VIEW, &["render", "w.qbk", "-o", "r.png", "--width", "8", "--height", "6",
        "--pixel", "3,3"], 0, "")
        .closed()
        .made(&[("r.png", "")]),
    // 3. Bounded memory: inputs read whole are size-checked, devices read with a cap.
    case(BAKE, &["bake", "/dev/zero", "-o", "z.qbk"], 2,
        "qbricks-bake: /dev/zero: is not a regular file and is longer than 1073741824 bytes")
        .absent(&["z.qbk"]),
    case(BAKE, &["inspect", "/dev/zero"], 2,
        "qbricks-bake: /dev/zero: is not a regular file and is longer than 1073741824 bytes"),
    case(BAKE, &["inspect", "huge.vdb"], 2,
        "qbricks-bake: huge.vdb: file is 1099511627776 bytes, more than the limit of"),
    case(VIEW, &["probe", "w.qbk", "--points", "/dev/zero"], 2,
        "qbricks-view: /dev/zero: is not a regular file and is longer than 1073741824 bytes"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--mesh", "/dev/zero"], 2,
        "qbricks-view: /dev/zero: is not a regular file and is longer than 1073741824 bytes")
        .absent(&["x.png"]),
    case(VIEW, &["info", "/dev/zero"], 2,
        "qbricks-view: /dev/zero: is not a regular file and is longer than 1073741824 bytes"),
    // `synth` streams its grids (issue 29): a file is refused by its size bound (values
    // raw, 1 TiB), not by what holding it would take.
    case(LAB, &["synth", "abc", "--n0", "20000", "-o", "a.vdb"], 2,
        "qbricks-lab: synth abc: scene \"abc\" with n0 20000 in 1 grid(s) would write 15625000000 leaves, up to 92516 GiB, more than the limit of 1024 GiB")
        .absent(&["a.vdb"]),
    case(LAB, &["synth", "abc", "--n0", "12000", "--float", "-o", "a.vdb"], 2,
        "qbricks-lab: synth abc: scene \"abc\" with n0 12000 in 1 grid(s) would write 3375000000 leaves")
        .absent(&["a.vdb"]),
    case(LAB, &["synth", "wake", "--n0", "65536", "--levels", "10", "-o", "a.vdb"], 2,
        "qbricks-lab: synth wake: scene \"wake\" with n0 65536 in 10 grid(s) would write")
        .absent(&["a.vdb"]),
    // 4. Clear messages naming the file.
    case(BAKE, &["bake", "dir", "-o", "d.qbk"], 2, "qbricks-bake: dir: is a directory, not a file")
        .absent(&["d.qbk"]),
    case(BAKE, &["inspect", "dir"], 2, "qbricks-bake: dir: is a directory, not a file"),
    case(BAKE, &["inspect", "missing.vdb"], 2,
        "qbricks-bake: missing.vdb: cannot read: No such file or directory"),
    case(VIEW, &["info", "dir"], 2, "qbricks-view: dir: is a directory, not a file"),
    case(VIEW, &["render", "dir", "-o", "x.png"], 2, "qbricks-view: dir: is a directory, not a file")
        .absent(&["x.png"]),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--mesh", "dir"], 2,
        "qbricks-view: dir: is a directory, expected an OBJ file")
        .absent(&["x.png"]),
    case(VIEW, &["info", "--no-checksum", "flip.qbk"], 2,
        "qbricks-view: flip.qbk: archive is invalid: invalid UTF-8 (while checking field 'source'"),
    // 1. Render: no output over an input or another output (path, symlink, hard link).
    case(VIEW, &["render", "w.qbk", "-o", "w.qbk"], 2,
        "qbricks-view: w.qbk: -o would overwrite the brick file w.qbk")
        .same(&["w.qbk"]),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--save-state", "w.qbk"], 2,
        "qbricks-view: w.qbk: --save-state would overwrite the brick file w.qbk")
        .same(&["w.qbk"])
        .absent(&["x.png"]),
    case(VIEW, &["render", "w.qbk", "-o", "link.qbk"], 2,
        "qbricks-view: link.qbk: -o would overwrite the brick file w.qbk")
        .same(&["w.qbk", "link.qbk"]),
    case(VIEW, &["render", "w.qbk", "-o", "hard.qbk"], 2,
        "qbricks-view: hard.qbk: -o would overwrite the brick file w.qbk")
        .same(&["w.qbk", "hard.qbk"]),
    case(VIEW, &["render", "w.qbk", "-o", "dir/../w.qbk"], 2,
        "qbricks-view: dir/../w.qbk: -o would overwrite the brick file w.qbk")
        .same(&["w.qbk"]),
    case(VIEW, &["render", "w.qbk", "--state", "st.json", "-o", "st.json"], 2,
        "qbricks-view: st.json: -o would overwrite the --state file st.json")
        .same(&["st.json"]),
    case(VIEW, &["render", "w.qbk", "--state", "st.json", "-o", "x.png", "--save-state",
        "st.json"], 2,
        "qbricks-view: st.json: --save-state would overwrite the --state file st.json")
        .same(&["st.json"])
        .absent(&["x.png"]),
    case(VIEW, &["render", "w.qbk", "-o", "s.obj", "--mesh", "s.obj"], 2,
        "qbricks-view: s.obj: -o would overwrite the mesh s.obj")
        .same(&["s.obj"]),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--save-state", "x.png"], 2,
        "qbricks-view: x.png: --save-state and -o name the same file")
        .absent(&["x.png"]),
    // 1. All or nothing: a failing run writes none of its outputs.
    case(VIEW, &["render", "w.qbk", "-o", "nodir/x.png", "--save-state", "st.json",
        "--width", "8", "--height", "6"], 2,
        "qbricks-view: nodir/x.png: No such file or directory")
        .same(&["st.json"]),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--save-state", "nodir/k.json",
        "--width", "8", "--height", "6"], 2,
        "qbricks-view: nodir/k.json: No such file or directory")
        .absent(&["x.png"]),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--mesh", "missing.obj"], 2,
        "qbricks-view: missing.obj: cannot read OBJ file")
        .absent(&["x.png"]),
    // 3. Bounded work: step floor, thread/repeat/spp/mesh/image bounds.
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--step", "1e-30"], 2,
        "qbricks-view: view state: step: expected a finite number ≥ 0.001 (cell widths), found 1e-30")
        .absent(&["x.png"]),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--step", "1e-30", "--mode", "dvr"], 2,
        "qbricks-view: view state: step: expected a finite number ≥ 0.001"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--threads", "100000"], 2,
        "qbricks-view: --threads: expected 1..=256, found 100000"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--repeat", "4294967295"], 2,
        "qbricks-view: --repeat: expected 1..=1000, found 4294967295"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--spp", "4294967295"], 2,
        "qbricks-view: view state: spp: expected 1..=4096, found 4294967295"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--width", "16384", "--height", "16384"],
        2, "qbricks-view: a 16384x16384 image needs about 16384 MiB, more than the limit of"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--state", "st_meshes.json"], 2,
        "qbricks-view: st_meshes.json: meshes: expected at most 64 entries, found 65"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--state", "st_lights.json"], 2,
        "qbricks-view: st_lights.json: lights: expected at most 64 entries, found 65"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--state", "/dev/zero"], 2,
        "qbricks-view: /dev/zero: expected a JSON view state of at most 16777216 bytes"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--state", "dir"], 2,
        "qbricks-view: dir: is a directory, not a file"),
    // 5. No silent wrong answers from render.
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--eye", "0,0,5", "--look-at", "0,0,0",
        "--up", "0,0,1"], 2,
        "qbricks-view: view state: camera.up: [0.0, 0.0, 1.0] is zero or parallel to the view direction"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--state", "st_field.json"], 2,
        "qbricks-view: w.qbk: colormap.field: field \"nope\" is not in the file (fields: q, speed)")
        .exact(),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--state", "st_points.json"], 2,
        "qbricks-view: st_points.json: colormap.points: expected at least one control point"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--state", "st.json", "--strategy", "exact",
        "--json"], 0, "")
        .stdout("\"inexact_segments\":0,\"truncated_segments\":0}"),
    // 5. No silent wrong answers from probe.
    case(VIEW, &["probe", "w.qbk", "--points", "bad0.csv"], 2, "qbricks-view: bad0.csv: line 1: "),
    case(VIEW, &["probe", "w.qbk", "--points", "bad1.csv"], 2, "qbricks-view: bad1.csv: line 1: "),
    case(VIEW, &["probe", "w.qbk", "--points", "bad2.csv"], 2, "qbricks-view: bad2.csv: line 1: "),
    case(VIEW, &["probe", "w.qbk", "--points", "bad3.csv"], 2, "qbricks-view: bad3.csv: line 1: "),
    case(VIEW, &["probe", "w.qbk", "--points", "bad4.csv"], 2, "qbricks-view: bad4.csv: line 1: "),
    case(VIEW, &["probe", "w.qbk", "--points", "bad5.csv"], 2, "qbricks-view: bad5.csv: line 1: "),
    case(VIEW, &["probe", "w.qbk", "--points", "bad6.csv"], 2, "qbricks-view: bad6.csv: line 1: "),
    case(VIEW, &["probe", "w.qbk", "--points", "header.csv"], 0, "")
        .stdout("\n0.5,0,0,"),
    case(VIEW, &["probe", "w.qbk", "--line", "-1e308,0,0:1e308,0,0:3"], 0, "")
        .stdout("\n0,0,0,"),
    case(VIEW, &["probe", "w.qbk", "--line", "nan,0,0:1,0,0:3"], 2,
        "qbricks-view: --line: expected a finite number, found `nan`"),
    // Issue 32, 1. One output policy: frame patterns are expanded over the frames that
    // exist before anything is written.
    case(BAKE, &["bake", "f_####.vdb", "-o", "f_1###.vdb"], 2,
        "qbricks-bake: f_1001.vdb: -o (frame 1) would overwrite the frame 1001 f_1001.vdb, an input of this run")
        .same(&["f_0001.vdb", "f_1001.vdb"]),
    case(VIEW, &["render", "f_####.qbk", "-o", "f_1###.qbk", "--width", "8", "--height", "6"], 2,
        "qbricks-view: f_1001.qbk: -o (frame 1) would overwrite the frame 1001 f_1001.qbk, an input of this run")
        .same(&["f_0001.qbk", "f_1001.qbk"]),
    // 1. Streams are written into, symbolic links written through and kept.
    case(VIEW, &["render", "w.qbk", "-o", "/dev/stdout", "--width", "8", "--height", "6"], 0, "")
        .stdout("PNG"),
    case(BAKE, &["bake", "w.vdb", "-o", "/dev/stdout"], 0, "").stdout("QBRICKS"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--width", "8", "--height", "6",
        "--save-state", "/dev/stdout"], 0, "")
        .stdout("\"camera\"")
        .made(&[("x.png", "")]),
    case(VIEW, &["render", "w.qbk", "-o", "ln_fd1", "--width", "8", "--height", "6"], 0, "")
        .stdout("PNG")
        .links(&["ln_fd1"]),
    case(BAKE, &["bake", "w.vdb", "-o", "ln_fd1"], 0, "").stdout("QBRICKS").links(&["ln_fd1"]),
    case(VIEW, &["render", "w.qbk", "-o", "ln_real.png", "--width", "8", "--height", "6"], 0, "")
        .links(&["ln_real.png"])
        .made(&[("real.png", "")]),
    case(VIEW, &["render", "w.qbk", "-o", "ln_dir.png", "--width", "8", "--height", "6"], 2,
        "qbricks-view: ln_dir.png: is a directory")
        .links(&["ln_dir.png"]),
    case(BAKE, &["bake", "w.vdb", "-o", "ln_dir.png"], 2, "qbricks-bake: ln_dir.png: is a directory")
        .links(&["ln_dir.png"]),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--save-state", "ln_w.qbk"], 2,
        "qbricks-view: ln_w.qbk: --save-state would overwrite the brick file w.qbk")
        .same(&["w.qbk", "ln_w.qbk"])
        .links(&["ln_w.qbk"])
        .absent(&["x.png"]),
    // 1. Every command's outputs against its inputs.
    case(LAB, &["bench", "w.qbk", "--plot", "w.qbk", "--size", "8x6"], 2,
        "qbricks-lab: w.qbk: --plot would overwrite the brick file w.qbk, an input of this run")
        .same(&["w.qbk"]),
    case(LAB, &["bench", "w.qbk", "--state", "st.json", "--plot", "st.json"], 2,
        "qbricks-lab: st.json: --plot would overwrite the --state file st.json")
        .same(&["st.json"]),
    case(VIEW, &["open", "w.qbk", "--screenshot", "w.qbk"], 2,
        "qbricks-view: w.qbk: --screenshot would overwrite the brick file w.qbk")
        .same(&["w.qbk"]),
    case(VIEW, &["open", "w.qbk", "--state", "st.json", "--screenshot", "ln_st.json"], 2,
        "qbricks-view: ln_st.json: --screenshot would overwrite the --state file st.json")
        .same(&["st.json"]),
    case(VIEW, &["render", "f_####.qbk", "-o", "p_####.png", "--width", "8", "--height", "6",
        "--save-state", "f_0001.qbk"], 2,
        "qbricks-view: f_0001.qbk: --save-state would overwrite the frame 1 f_0001.qbk")
        .same(&["f_0001.qbk"])
        .absent(&["p_0001.png"]),
    case(VIEW, &["render", "f_####.qbk", "-o", "p_####.png", "--width", "8", "--height", "6",
        "--mesh", "s.obj", "--save-state", "s.obj"], 2,
        "qbricks-view: s.obj: --save-state would overwrite the mesh s.obj")
        .same(&["s.obj"])
        .absent(&["p_0001.png"]),
    case(VIEW, &["render", "f_####.qbk", "-o", "p_####.png", "--state", "st.json",
        "--save-state", "st.json"], 2,
        "qbricks-view: st.json: --save-state would overwrite the --state file st.json")
        .same(&["st.json"]),
    case(VIEW, &["render", "f_####.qbk", "-o", "p_####.png", "--width", "8", "--height", "6",
        "--save-state", "p_0001.png"], 2,
        "qbricks-view: p_0001.png: --save-state and -o (frame 1) name the same file")
        .absent(&["p_0001.png"]),
    // 1. A run that fails writes nothing: every frame fails, so no --save-state.
    case(VIEW, &["render", "bad_####.qbk", "-o", "p_####.png", "--width", "8", "--height", "6",
        "--save-state", "st.json"], 2, "qbricks-view: bad_####.qbk: no manifest")
        .lines(5, &["qbricks-view: bad_0001.qbk: ", "1 of 1 frames failed"])
        .same(&["st.json"])
        .absent(&["p_0001.png"]),
    // 2. Sizes bounded before allocating.
    case(LAB, &["bench", "w.qbk", "--size", "16384x16384"], 2,
        "qbricks-lab: a 16384x16384 image (2 copies) needs about 32768 MiB, more than the limit of"),
    case(VIEW, &["probe", "w.qbk", "--points", "big.csv", "--json"], 0, "")
        .closed()
        .limit_kib(1 << 20),
    // 3. Counts bounded the same way in every command.
    case(LAB, &["bench", "w.qbk", "--repeat", "100000"], 2,
        "qbricks-lab: --repeat: expected 1..=1000, found 100000"),
    case(LAB, &["bench", "w.qbk", "--threads", "100000"], 2,
        "qbricks-lab: --threads: expected 1..=256, found 100000"),
    case(VIEW, &["open", "w.qbk", "--threads", "100000"], 2,
        "qbricks-view: --threads: expected 1..=256, found 100000"),
    case(VIEW, &["open", "w.qbk", "--orbit-frames", "1000000000"], 2,
        "qbricks-view: --orbit-frames: expected 1..=108000, found 1000000000"),
    case(LAB, &["synth", "ring-plume", "-o", "r_####.vdb", "--frames", "1000000"], 2,
        "qbricks-lab: --frames: expected 1..=100000, found 1000000"),
    // 4. No blocking opens: a FIFO nobody writes to is reported at once.
    case(VIEW, &["info", "ff"], 2,
        "qbricks-view: ff: is a FIFO (named pipe) and no program wrote to it"),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--state", "ff"], 2,
        "qbricks-view: ff: is a FIFO (named pipe) and no program wrote to it")
        .absent(&["x.png"]),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--mesh", "ff"], 2,
        "qbricks-view: ff: is a FIFO (named pipe) and no program wrote to it")
        .absent(&["x.png"]),
    case(VIEW, &["probe", "w.qbk", "--points", "ff"], 2,
        "qbricks-view: ff: is a FIFO (named pipe) and no program wrote to it"),
    case(BAKE, &["bake", "ff", "-o", "ff.qbk"], 2,
        "qbricks-bake: ff: is a FIFO (named pipe) and no program wrote to it")
        .absent(&["ff.qbk"]),
    case(BAKE, &["inspect", "ff"], 2,
        "qbricks-bake: ff: is a FIFO (named pipe) and no program wrote to it"),
    case(VIEW, &["render", "g_####.qbk", "--frames", "1..2", "-o", "p_####.png",
        "--width", "8", "--height", "6"], 2, "qbricks-view: g_####.qbk: no manifest")
        .lines(5, &["qbricks-view: g_0002.qbk: is a FIFO (named pipe) and no program wrote to it"])
        .made(&[("p_0001.png", "")])
        .absent(&["p_0002.png"]),
    // 6. No silently wrong answers: the manifest says which files are frames of the bake.
    case(VIEW, &["render", "m_####.qbk", "-o", "p_####.png", "--width", "8", "--height", "6"], 0,
        "qbricks-view: m_####.qbk: field ranges of the whole sequence from m_sequence.json")
        .lines(5, &[
            "qbricks-view: warning: m_0002.qbk: skipped, its bake failed (in_0002.vdb: truncated)",
            "qbricks-view: warning: m_0004.qbk: skipped, the manifest of the bake does not list it",
        ])
        .made(&[("p_0001.png", ""), ("p_0003.png", "")])
        .absent(&["p_0002.png", "p_0004.png"]),
    case(LAB, &["bench", "w.qbk", "--reference-step", "1e-30", "--size", "8x6"], 2,
        "qbricks-lab: w.qbk: --reference-step: step: expected a finite number ≥ 0.001 (cell widths), found 1e-30"),
    // Issue 32, 2. A 9 kB file holding one active 640³ tile: refused by the bake's memory
    // estimate (it aborted with SIGABRT at 6.5 GB). Under the cases' `ulimit -v` the
    // address space counts: 0.85 GiB held, and 5 GiB of cell and field values mapped from
    // scratch files.
    case(BAKE, &["bake", "tile640.vdb", "-o", "t.qbk"], 2,
        "qbricks-bake: tile640.vdb: the bake of 262144000 input cells (grid \"vel\") needs about 5831 MiB, more than the limit of")
        .absent(&["t.qbk"]),
    // Issue 27: `probe --plane` writes through the same policy: never over its input (also
    // through a link), into streams, through links; refused requests leave no file; the
    // sides and the memory are bounded before anything is sampled.
    case(VIEW, &["probe", "w.qbk", "--plane", "z=0", "-o", "w.qbk"], 2,
        "qbricks-view: w.qbk: -o would overwrite the brick file w.qbk, an input of this run")
        .exact()
        .same(&["w.qbk"]),
    case(VIEW, &["probe", "w.qbk", "--plane", "z=0", "--format", "npy", "-o", "ln_w.qbk"], 2,
        "qbricks-view: ln_w.qbk: -o would overwrite the brick file w.qbk, an input of this run")
        .same(&["w.qbk"])
        .links(&["ln_w.qbk"]),
    case(VIEW, &["probe", "w.qbk", "--plane", "z=0", "--resolution", "4,2", "--format", "npy",
        "-o", "/dev/stdout"], 0, "qbricks-view: --plane: 4x2 samples (NU x NV) of q, speed on")
        .stdout("NUMPY"),
    case(VIEW, &["probe", "w.qbk", "--plane", "x=1", "--resolution", "3", "--format", "npy",
        "-o", "ln_real.png"], 0, "qbricks-view: --plane: 3x3 samples")
        .links(&["ln_real.png"])
        .made(&[("real.png", "")]),
    case(VIEW, &["probe", "w.qbk", "--plane", "z=0"], 0,
        "qbricks-view: --plane: 256x131 samples (NU x NV) of q, speed on")
        .closed(),
    case(VIEW, &["probe", "w.qbk", "--plane", "0,0,0:1,1,0:2,2,0", "-o", "p.npy"], 2,
        "qbricks-view: --plane: U [1.0, 1.0, 0.0] and V [2.0, 2.0, 0.0] are parallel: they span no plane")
        .exact()
        .absent(&["p.npy"]),
    case(VIEW, &["probe", "w.qbk", "--plane", "z=0", "--resolution", "100000", "-o", "p.csv"], 2,
        "qbricks-view: --resolution: expected 1..=16384, found 100000")
        .exact()
        .absent(&["p.csv"]),
    case(VIEW, &["probe", "w.qbk", "--plane", "z=0", "--resolution", "16384,16384", "-o",
        "p.npy"], 2,
        "qbricks-view: a 16384x16384 plane of 2 field(s) needs about 2048 MiB, more than the limit of")
        .limit_kib(1 << 20)
        .absent(&["p.npy"]),
    // Issue 31: the commands that moved to `qbricks-lab` say so, whatever their arguments.
    case(BAKE, &["synth", "wake", "-o", "a.vdb"], 2,
        "qbricks-bake: synth: moved: run `qbricks-lab synth …` (same arguments)")
        .absent(&["a.vdb"]).exact(),
    case(BAKE, &["accuracy", "wake", "--json"], 2,
        "qbricks-bake: accuracy: moved: run `qbricks-lab accuracy …` (same arguments)").exact(),
    case(VIEW, &["bench", "w.qbk", "--plot", "b.png"], 2,
        "qbricks-view: bench: moved: run `qbricks-lab bench …` (same arguments)")
        .absent(&["b.png"]).exact(),
    // 2. Estimated from n0 and the levels before anything is sampled.
    case(LAB, &["accuracy", "lamb-oseen", "--n0", "512"], 2,
        "qbricks-lab: n0 512: measuring scene \"lamb-oseen\" (sampled, baked and compared in memory) needs about 8086 MiB, more than the limit of"),
    case(LAB, &["synth", "lamb-oseen", "--n0", "4000", "-o", "a.vdb"], 2,
        "qbricks-lab: synth lamb-oseen: scene \"lamb-oseen\" with n0 4000 in 1 grid(s) (125000000 leaves, written a batch at a time) needs about 38146 MiB, more than the limit of")
        .absent(&["a.vdb"]),
    // 3. Coordinates beyond double precision: refused by the baker, and by the viewer for
    // a file made by hand (it said "camera.up is parallel to the view direction").
    case(BAKE, &["bake", "far.vdb", "-o", "f.qbk"], 2,
        "qbricks-bake: far.vdb: grid \"vel\" (voxel size 0.1): voxels reach 1e300 from the origin, 1.0e301 voxels of the finest size 0.1 out: too far for double precision to place cells exactly (the bake takes 2^26, about 6.7e7, finest voxels); translate the grid towards the origin")
        .exact()
        .absent(&["f.qbk"]),
    case(VIEW, &["render", "far.qbk", "-o", "x.png"], 2,
        "qbricks-view: far.qbk: the data's bounds [1e300, 1e300, 1e300]..[1e300, 1e300, 1e300] reach 1.0e301 cells of the finest width 0.1 from the origin, more than the 2^40 within which double precision places cells to 1/4096 of a cell; re-bake the data nearer the origin")
        .exact()
        .absent(&["x.png"]),
    // 4. Q beyond f32: a warning at the bake (a refusal with --strict); the stored ±f32::MAX
    // range gives valid defaults (it said "colormap.band: expected a finite number").
    case(BAKE, &["bake", "huge_q.vdb", "-o", "h.qbk", "--fields", "q"], 0,
        "qbricks-bake: warning: huge_q.vdb: field \"q\": 512 values are not finite as 32-bit floats: 512 in grid \"vel\" (first at voxel [0, 0, 0]); stored as ±3.4028235e38 (infinities) and 0 (NaN)")
        .exact()
        .made(&[("h.qbk", "")]),
    case(BAKE, &["bake", "huge_q.vdb", "-o", "h.qbk", "--strict"], 2,
        "qbricks-bake: huge_q.vdb: field \"q\": 512 values are not finite as 32-bit floats: 512 in grid \"vel\" (first at voxel [0, 0, 0]); refused because of --strict")
        .absent(&["h.qbk"]),
    case(VIEW, &["render", "huge_q.qbk", "-o", "x.png", "--width", "8", "--height", "6"], 0, "")
        .made(&[("x.png", "")]),
    // 5a. Unknown field names said once.
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--state", "st_iso.json"], 2,
        "qbricks-view: w.qbk: iso_field: field \"nope\" is not in the file (fields: q, speed)")
        .exact(),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--iso-field", "nope"], 2,
        "qbricks-view: w.qbk: --iso-field: no field named \"nope\" (fields: q, speed)")
        .exact(),
    case(VIEW, &["render", "w.qbk", "-o", "x.png", "--colour-field", "nope"], 2,
        "qbricks-view: w.qbk: --colour-field: no field named \"nope\" (fields: q, speed)")
        .exact(),
    case(BAKE, &["bake", "w.vdb", "-o", "x.qbk", "--fields", "q,nope"], 2,
        "qbricks-bake: w.vdb: --fields: no scalar grid named \"nope\" (the file has no scalar grids)")
        .exact()
        .absent(&["x.qbk"]),
    // 5b. A duplicated component grid is named.
    case(BAKE, &["bake", "dup_component.vdb", "-o", "d.qbk"], 2,
        "qbricks-bake: dup_component.vdb: component grids \"vel.x\", \"vel.y\", \"vel.z\" cannot make the velocity \"vel\": 2 grids are named \"vel.x\" (each component must be exactly one grid; rename or remove the others)")
        .exact()
        .absent(&["d.qbk"]),
    case(BAKE, &["bake", "dup_component.vdb", "-o", "d.qbk", "--velocity", "vel"], 2,
        "qbricks-bake: dup_component.vdb: component grids \"vel.x\", \"vel.y\", \"vel.z\" cannot make the velocity \"vel\": 2 grids are named \"vel.x\"")
        .absent(&["d.qbk"]),
    // 5c. A vec3 grid asked for as a field says what it is and what to do.
    case(BAKE, &["bake", "vec3_field.vdb", "-o", "v.qbk", "--fields", "q,vel2"], 2,
        "qbricks-bake: vec3_field.vdb: --fields: \"vel2\" is a vec3 grid, and a field list takes q, speed, vorticity, lambda2, helicity, velocity and scalar grids: to bake it as the velocity, give --velocity vel2 (with --fields q,speed,velocity for its components)")
        .exact()
        .absent(&["v.qbk"]),
    // 5d. Non-finite values in two grids: both named, each with its count.
    case(BAKE, &["bake", "nan_two.vdb", "-o", "n.qbk"], 0,
        "qbricks-bake: warning: nan_two.vdb: replaced 3 non-finite values by the average of their finite neighbours: 2 in grid \"fine\" (first at voxel [0, 0, 1]), 1 in grid \"coarse\" (first at voxel [7, 7, 7])")
        .exact()
        .made(&[("n.qbk", "")]),
    // 6a. Two grids of one voxel size overlapping with different values: a warning;
    // with equal values (one field in two grids) none.
    case(BAKE, &["bake", "overlap.vdb", "-o", "o.qbk"], 0,
        "qbricks-bake: warning: overlap.vdb: grids \"a\" and \"b\" (voxel size 1) overlap in 2048 cells, 2048 of them with different values (largest difference 1, at voxel [8, 0, 0] of \"a\"); the file keeps both and the viewer averages them there")
        .exact()
        .made(&[("o.qbk", "")]),
    case(BAKE, &["bake", "overlap_equal.vdb", "-o", "o.qbk"], 0, "")
        .made(&[("o.qbk", "")]),
    // 6b. An extra field that covers part of the velocity: a warning with the share; one
    // that covers none: refused.
    case(BAKE, &["bake", "density_half.vdb", "-o", "d.qbk", "--fields", "q,speed,density"], 0,
        "qbricks-bake: warning: density_half.vdb: field \"density\": grid \"density\" covers 50.0 % of the velocity's leaf cells (2048 of 4096); the others read its background 0")
        .exact()
        .made(&[("d.qbk", "")]),
    case(BAKE, &["bake", "density_elsewhere.vdb", "-o", "d.qbk", "--fields", "q,speed,density"], 2,
        "qbricks-bake: density_elsewhere.vdb: field \"density\": grid \"density\" has no active voxel at any of the velocity's 4096 leaf cells, so every value would be its background 0 (its voxels lie in [95.5, 95.5, 95.5]..[103.5, 103.5, 103.5], the velocity's cells in [-0.5, -0.5, -0.5]..[15.5, 15.5, 15.5])")
        .exact()
        .absent(&["d.qbk"]),
];

/// Writes the inputs a case may name into `dir`: copies of the bundled sample, a directory,
/// a sparse 1 TiB file, an archive with byte 48 flipped and the points files.
fn populate(dir: &Path, case: &Case) {
    let names: Vec<&str> = case
        .args
        .iter()
        .chain(case.same)
        .chain(case.made.iter().map(|(_, r)| r))
        .copied()
        .collect();
    let data = common::root().join("data");
    let wanted = |n: &str| names.contains(&n);
    if wanted("w.qbk") {
        std::fs::copy(data.join("wake_small.qbk"), dir.join("w.qbk")).expect("copy qbk");
    }
    for name in ["w.vdb", "wake_small.vdb"] {
        if wanted(name) {
            std::fs::copy(data.join("wake_small.vdb"), dir.join(name)).expect("copy vdb");
        }
    }
    if wanted("s.obj") {
        std::fs::copy(data.join("sphere.obj"), dir.join("s.obj")).expect("copy obj");
    }
    if wanted("flip.qbk") {
        let mut bytes = std::fs::read(data.join("wake_small.qbk")).expect("read qbk");
        // The provenance's source name, made invalid UTF-8 (wherever the layout puts it; its
        // last byte, as the first of a short string held inline also marks it as such).
        let at = bytes
            .windows(14)
            .position(|w| w == b"wake_small.vdb")
            .expect("the source name is in the file");
        bytes[at + 13] ^= 0xff;
        std::fs::write(dir.join("flip.qbk"), bytes).expect("write flipped");
    }
    if wanted("huge.vdb") {
        let f = std::fs::File::create(dir.join("huge.vdb")).expect("create sparse");
        f.set_len(1 << 40).expect("sparse 1 TiB file");
    }
    std::fs::create_dir(dir.join("dir")).expect("mkdir");
    #[cfg(unix)]
    if wanted("link.qbk") || wanted("hard.qbk") {
        std::os::unix::fs::symlink("w.qbk", dir.join("link.qbk")).expect("symlink");
        std::fs::hard_link(dir.join("w.qbk"), dir.join("hard.qbk")).expect("hard link");
    }
    if names.iter().any(|n| n.starts_with("st")) {
        write_states(dir);
    }
    for (i, line) in BAD_FIRST_LINES.iter().enumerate() {
        std::fs::write(
            dir.join(format!("bad{i}.csv")),
            format!("{line}\n0.5,0,0\n"),
        )
        .expect("csv");
    }
    std::fs::write(dir.join("header.csv"), "x,y,z\n0.5,0,0\n").expect("csv");
    populate_issue_32(dir, &wanted);
    for name in hostile_inputs::NAMES {
        if wanted(name) {
            hostile_inputs::write(dir, name);
        }
    }
    for name in hostile_inputs::QBK_NAMES {
        if wanted(name) {
            hostile_inputs::write_qbk(dir, name);
        }
    }
}

/// The inputs of the output-policy cases: frames named so that a pattern's output lands
/// on another input frame, symbolic links (to a file, a directory, the process's stdout,
/// an input), a FIFO, a sequence with a manifest, a large points list.
fn populate_issue_32(dir: &Path, wanted: &dyn Fn(&str) -> bool) {
    let data = common::root().join("data");
    let qbk = data.join("wake_small.qbk");
    let copy = |from: &Path, to: &str| {
        std::fs::copy(from, dir.join(to)).expect("copy");
    };
    if wanted("f_####.vdb") {
        copy(&data.join("wake_small.vdb"), "f_0001.vdb");
        copy(&data.join("wake_small.vdb"), "f_1001.vdb");
    }
    if wanted("f_####.qbk") {
        copy(&qbk, "f_0001.qbk");
        copy(&qbk, "f_1001.qbk");
    }
    if wanted("bad_####.qbk") {
        std::fs::write(dir.join("bad_0001.qbk"), b"not a brick file").expect("write");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::symlink;
        symlink("/proc/self/fd/1", dir.join("ln_fd1")).expect("symlink");
        symlink("real.png", dir.join("ln_real.png")).expect("symlink");
        symlink("dir", dir.join("ln_dir.png")).expect("symlink");
        symlink("w.qbk", dir.join("ln_w.qbk")).expect("symlink");
        symlink("st.json", dir.join("ln_st.json")).expect("symlink");
        let fifo = |name: &str| {
            let st = std::process::Command::new("mkfifo")
                .arg(dir.join(name))
                .status()
                .expect("mkfifo");
            assert!(st.success(), "mkfifo {name}");
        };
        if wanted("ff") {
            fifo("ff");
        }
        if wanted("g_####.qbk") {
            copy(&qbk, "g_0001.qbk");
            fifo("g_0002.qbk");
        }
    }
    if wanted("m_####.qbk") {
        // Frames 1 and 3 baked, 2 failed (its file left from an earlier bake), 4 not in
        // the manifest at all.
        for f in 1..=4 {
            copy(&qbk, &format!("m_{f:04}.qbk"));
        }
        let view = format::BrickFileView::open(&qbk).expect("open sample");
        let fields: Vec<serde_json::Value> = view
            .file()
            .fields
            .iter()
            .map(|f| {
                serde_json::json!({"name": f.name.as_str(), "min": f.min.to_native(), "max": f.max.to_native()})
            })
            .collect();
        let frame = |f: u64| {
            serde_json::json!({"frame": f, "input": format!("in_{f:04}.vdb"),
                "output": format!("m_{f:04}.qbk"), "leaf_cells": 1, "fields": fields})
        };
        let manifest = serde_json::json!({
            "input_pattern": "in_####.vdb", "output_pattern": "m_####.qbk",
            "frames": [frame(1), frame(3)],
            "failed": [{"frame": 2, "input": "in_0002.vdb", "error": "in_0002.vdb: truncated"}],
            "missing": [], "fields": fields,
        });
        std::fs::write(dir.join("m_sequence.json"), manifest.to_string()).expect("manifest");
    }
    if wanted("big.csv") {
        // 4 M points (36 MB): the report once held every point as a JSON value (≈ 2 GB).
        use std::io::Write;
        let f = std::fs::File::create(dir.join("big.csv")).expect("create");
        let mut w = std::io::BufWriter::new(f);
        for i in 0..4_000_000u32 {
            writeln!(w, "{},0,0", f64::from(i % 1000) * 1e-3).expect("write");
        }
        w.flush().expect("flush");
    }
}

/// View states for the sample: a small valid one, and ones with a colour field the file
/// lacks, no colour points, and one mesh entry too many.
fn write_states(dir: &Path) {
    use viewer::view_state::ViewState;
    let view = format::BrickFileView::open(&common::root().join("data/wake_small.qbk"))
        .expect("open sample");
    let vol = viewer::volume::Volume::new(&view).expect("volume");
    let mut st = ViewState::default_for_volume(&vol);
    st.width = 8;
    st.height = 6;
    let save = |name: &str, s: &ViewState| {
        std::fs::write(dir.join(name), s.to_json()).expect("write state");
    };
    save("st.json", &st);
    let mut bad = st.clone();
    bad.colormap.field = "nope".into();
    save("st_field.json", &bad);
    let mut bad = st.clone();
    bad.iso_field = "nope".into();
    save("st_iso.json", &bad);
    let mut bad = st.clone();
    bad.colormap.points.clear();
    save("st_points.json", &bad);
    let mut bad = st.clone();
    bad.meshes = vec![viewer::mesh::MeshInstance::at_origin("s.obj"); 65];
    save("st_meshes.json", &bad);
    let mut bad = st.clone();
    bad.lights = vec![st.lights[0]; 65];
    save("st_lights.json", &bad);
}

struct Outcome {
    code: Option<i32>,
    stdout: String,
    stderr: String,
    elapsed: Duration,
}

/// Runs `program args` in `dir` under the memory limit, killing it after [`TIMEOUT`].
fn run(program: &str, args: &[&str], dir: &Path, out: Out, limit_kib: u64) -> Outcome {
    let bin = common::bin(program);
    let mut cmd = Command::new("sh");
    cmd.arg("-c")
        .arg(format!("ulimit -v {limit_kib} && exec \"$0\" \"$@\""))
        .arg(&bin)
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let start = Instant::now();
    let mut child = cmd.spawn().expect("spawn");
    let mut stdout_pipe = child.stdout.take().expect("stdout");
    let mut stderr_pipe = child.stderr.take().expect("stderr");
    // Drain both pipes on threads so a chatty child cannot block on a full pipe.
    let err_thread = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr_pipe.read_to_string(&mut s);
        s
    });
    let out_thread = match out {
        // Bytes, shown lossily: some cases write a PNG or a .qbk to stdout.
        Out::Captured => Some(std::thread::spawn(move || {
            let mut b = Vec::new();
            let _ = stdout_pipe.read_to_end(&mut b);
            String::from_utf8_lossy(&b).into_owned()
        })),
        // The reader goes away at once: every write to stdout fails with EPIPE.
        Out::Closed => {
            drop(stdout_pipe);
            None
        }
    };
    let code = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status.code();
        }
        if start.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    Outcome {
        code,
        stdout: out_thread
            .map(|t| t.join().expect("stdout thread"))
            .unwrap_or_default(),
        stderr: err_thread.join().expect("stderr thread"),
        elapsed: start.elapsed(),
    }
}

fn snapshot(dir: &Path, files: &[&str]) -> Vec<(PathBuf, Option<Vec<u8>>)> {
    files
        .iter()
        .map(|f| {
            let p = dir.join(f);
            let bytes = std::fs::read(&p).ok();
            (p, bytes)
        })
        .collect()
}

/// Hidden temporary files an interrupted or failed write could leave behind.
fn temp_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .expect("read dir")
        .filter_map(|e| {
            let name = e.ok()?.file_name().to_string_lossy().into_owned();
            (name.starts_with('.') && name.contains("tmp")).then_some(name)
        })
        .collect()
}

#[test]
fn every_case_exits_with_its_code_and_message() {
    let mut failures = Vec::new();
    for case in CASES {
        let dir = tempfile::tempdir().expect("tempdir");
        populate(dir.path(), case);
        let before = snapshot(dir.path(), case.same);
        let links: Vec<_> = case
            .links
            .iter()
            .map(|f| std::fs::read_link(dir.path().join(f)).ok())
            .collect();
        let o = run(
            case.program,
            case.args,
            dir.path(),
            case.out,
            case.limit_kib,
        );
        let shown = format!("{} {}", case.program, case.args.join(" "));
        let mut why = Vec::new();
        match o.code {
            None => why.push(format!(
                "killed after {:.1} s (timeout or signal)",
                o.elapsed.as_secs_f64()
            )),
            Some(c) if c != case.code => why.push(format!("exit {c}, expected {}", case.code)),
            Some(_) => {}
        }
        let stderr_ok = if case.stderr.is_empty() {
            o.stderr.is_empty()
        } else if case.exact {
            o.stderr.trim_end() == case.stderr
        } else {
            o.stderr.starts_with(case.stderr)
                && o.stderr.trim_end().lines().count() == case.lines
                && case.has.iter().all(|h| o.stderr.contains(h))
        };
        if !stderr_ok {
            let how = if case.exact {
                "exactly".to_string()
            } else {
                format!("{} line(s) starting", case.lines)
            };
            why.push(format!(
                "stderr {:?}, expected {how} {:?} with {:?}",
                o.stderr, case.stderr, case.has
            ));
        }
        for (f, before) in case.links.iter().zip(&links) {
            let after = std::fs::read_link(dir.path().join(f)).ok();
            if before.is_none() || after != *before {
                why.push(format!(
                    "{f} is no longer the same symbolic link ({after:?})"
                ));
            }
        }
        if case.out == Out::Captured && !o.stdout.contains(case.stdout) {
            why.push(format!("stdout lacks {:?}: {:?}", case.stdout, o.stdout));
        }
        for ((path, old), (_, new)) in before.iter().zip(snapshot(dir.path(), case.same)) {
            if *old != new {
                why.push(format!("{} changed", path.display()));
            }
        }
        for (f, reference) in case.made {
            match std::fs::read(dir.path().join(f)) {
                Err(e) => why.push(format!("{f} not written: {e}")),
                Ok(b) if reference.is_empty() && b.is_empty() => why.push(format!("{f} is empty")),
                Ok(b)
                    if !reference.is_empty()
                        && std::fs::read(dir.path().join(reference)).ok().as_ref() != Some(&b) =>
                {
                    why.push(format!("{f} differs from {reference}"))
                }
                Ok(_) => {}
            }
        }
        for f in case.absent {
            if dir.path().join(f).exists() {
                why.push(format!("{f} exists"));
            }
        }
        let temps = temp_files(dir.path());
        if !temps.is_empty() {
            why.push(format!("temporary files left: {temps:?}"));
        }
        if !why.is_empty() {
            failures.push(format!("{shown}: {}", why.join("; ")));
        }
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let null = std::fs::metadata("/dev/null").expect("/dev/null");
        assert!(
            null.file_type().is_char_device(),
            "/dev/null was replaced by a regular file"
        );
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        CASES.len(),
        failures.join("\n")
    );
}

/// The table covers each malformed points line once (a guard against the list and the
/// files drifting apart).
#[test]
fn table_has_a_case_per_bad_points_line() {
    for i in 0..BAD_FIRST_LINES.len() {
        let name = format!("bad{i}.csv");
        assert!(
            CASES.iter().any(|c| c.args.contains(&name.as_str())),
            "no case for {name}"
        );
    }
}

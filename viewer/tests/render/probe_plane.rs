//! `probe --plane` in the library: a sampled plane against `probe` at the same points (bit
//! for bit, on level boundaries too), continuity across a level boundary, and the CSV,
//! JSON and `.npy` outputs read back.

use qbricks_viewer::probe;
use qbricks_viewer::probe::plane::{self, Plane, PlaneSamples, PlaneSpec, Resolution};
use qbricks_viewer::probe::plane_file::{self, PlaneFormat};
use qbricks_viewer::testvol;
use qbricks_viewer::volume::Volume;

/// Two smooth fields on [`testvol::nested`] with n = 8: coarse cells of width 2 over
/// [0, 16]³ (supports reach [-1, 17]³), fine cells of width 1 over [4, 12]³ (the fine
/// bricks' supports reach [3.5, 12.5]³).
fn two_level_file() -> format::BrickFile {
    let q = |p: [f64; 3]| (p[0] / 3.0).sin() + (p[1] / 4.0).cos() + p[2] / 5.0;
    let s = |p: [f64; 3]| 0.5 + 0.01 * p[0] * p[1] - 0.02 * p[2];
    testvol::nested(8, [0.0; 3], &[("q", &q), ("speed", &s)], 4)
}

/// Every sample of `s` against `probe::probe` at the sample's own point: the same value,
/// bit for bit, NaN exactly where probe reports NaN. Returns the samples compared inside.
fn assert_equals_probe(vol: &Volume, s: &PlaneSamples, fields: &[usize]) -> usize {
    let mut inside = 0;
    let mut outside = 0;
    for j in 0..s.resolution.nv {
        for i in 0..s.resolution.nu {
            let p = s.point(i, j);
            let probed = &probe::probe(vol, &[p], 0)[0];
            let got = s.sample(i, j);
            for (k, &f) in fields.iter().enumerate() {
                let want = probed.values[f];
                let have = f64::from(got[k]);
                assert!(
                    have.to_bits() == want.to_bits() || (have.is_nan() && want.is_nan()),
                    "sample ({i}, {j}) at {p:?}, field {f}: plane {have}, probe {want}"
                );
            }
            if probed.values[0].is_nan() {
                outside += 1;
            } else {
                inside += 1;
            }
        }
    }
    assert_eq!(s.outside, outside, "outside count");
    inside
}

#[test]
fn plane_samples_equal_probe_bit_for_bit_also_on_level_boundaries() {
    let file = two_level_file();
    let view = testvol::open(&file).unwrap();
    let vol = Volume::new(&view).unwrap();
    let all = [0, 1];
    // `z=8` over the data's x, y extent [-1, 17]: 9 samples per side sit at x, y = 0, 2, …,
    // 16, on the fine grid's box faces 4 and 12 (coarse cell faces); 18 per side sit at
    // -0.5, 0.5, …, 16.5, on the fine supports' faces 3.5 and 12.5.
    let world = (file.bounds.min, file.bounds.max);
    assert_eq!(world, ([-1.0; 3], [17.0; 3]));
    let z8 = PlaneSpec::parse("z=8")
        .unwrap()
        .resolve(world.0, world.1)
        .unwrap();
    for (n, faces) in [(9, [4.0, 12.0]), (18, [3.5, 12.5])] {
        let res = Resolution { nu: n, nv: n };
        let s = plane::sample(&vol, &z8, res, &all).unwrap();
        let on_faces = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .filter(|&(i, j)| faces.contains(&s.point(i, j)[0]))
            .count();
        assert_eq!(on_faces, 2 * n as usize, "samples on the faces {faces:?}");
        assert_eq!(s.outside, 0, "the patch is the data's extent");
        assert_eq!(assert_equals_probe(&vol, &s, &all), (n * n) as usize);
    }
    // A tilted patch larger than the data, fields in another order: outside samples are NaN
    // in both, and counted.
    let tilted = Plane::new([-3.0, -2.0, 1.0], [22.0, 3.0, 4.0], [-1.0, 21.0, 9.0]).unwrap();
    let s = plane::sample(&vol, &tilted, Resolution { nu: 37, nv: 29 }, &[1, 0]).unwrap();
    let inside = assert_equals_probe(&vol, &s, &[1, 0]);
    assert!(
        inside > 100 && s.outside > 100,
        "{inside} in, {} out",
        s.outside
    );
    assert_eq!(s.fields, ["speed", "q"]);
    // The same on any number of threads.
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| plane::sample(&vol, &tilted, s.resolution, &[1, 0]).unwrap());
    assert_eq!(
        one.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        s.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
}

#[test]
fn plane_values_are_continuous_across_a_level_boundary() {
    let file = two_level_file();
    let view = testvol::open(&file).unwrap();
    let vol = Volume::new(&view).unwrap();
    // A strip one sample high across x = 3.5 (fine supports begin) and x = 4 (fine box),
    // through the coarse-only, blended and fine-only parts; and one across y = 12..12.5.
    let dx = 1e-3;
    let strips = [
        Plane::new([2.0, 7.3, 8.1], [4.0, 0.0, 0.0], [0.0, 1e-6, 0.0]).unwrap(),
        Plane::new([6.2, 11.0, 5.3], [0.0, 2.5, 0.0], [0.0, 0.0, 1e-6]).unwrap(),
    ];
    for strip in strips {
        let n = (plane::length(strip.u) / dx).round() as u32;
        let s = plane::sample(&vol, &strip, Resolution { nu: n, nv: 1 }, &[0]).unwrap();
        assert_eq!(s.outside, 0);
        // q's slope is at most 1/3 + 1/4 + 1/5 < 0.8 (the reconstruction's steepest step
        // here is about 0.26 per unit); a crack, as a reconstruction from the finest level
        // alone makes, jumps by the coarse level's interpolation error within one step of
        // 0.001: a slope of about 150.
        let steepest = s
            .values
            .windows(2)
            .map(|w| (w[1] - w[0]).abs() / dx as f32)
            .fold(0.0f32, f32::max);
        assert!(
            steepest < 2.0,
            "{strip:?}: slope {steepest} between samples"
        );
    }
}

/// A small sampled plane with samples inside and outside the data.
fn small_samples() -> (format::BrickFile, Plane, Resolution) {
    let plane = Plane::new([-2.0, 1.0, 7.5], [20.0, 0.0, 0.0], [0.0, 10.0, 1.0]).unwrap();
    (two_level_file(), plane, Resolution { nu: 13, nv: 7 })
}

fn written(s: &PlaneSamples, format: PlaneFormat) -> Vec<u8> {
    let mut out = Vec::new();
    plane_file::write(&mut out, s, format).unwrap();
    out
}

fn same_value(have: f64, want: f32) -> bool {
    have.to_bits() == f64::from(want).to_bits() || (have.is_nan() && want.is_nan())
}

#[test]
fn csv_json_and_npy_read_back_to_the_samples() {
    let (file, plane, res) = small_samples();
    let view = testvol::open(&file).unwrap();
    let vol = Volume::new(&view).unwrap();
    let s = plane::sample(&vol, &plane, res, &[0, 1]).unwrap();
    assert!(s.outside > 0 && s.outside < res.count());

    // CSV: header, then row j = 0 first, i fastest; x, y, z and the values read back
    // exactly.
    let csv = String::from_utf8(written(&s, PlaneFormat::Csv)).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("i,j,x,y,z,q,speed"));
    let mut n = 0;
    for (k, line) in lines.enumerate() {
        let cols: Vec<&str> = line.split(',').collect();
        assert_eq!(cols.len(), 7, "{line}");
        let (i, j): (u32, u32) = (cols[0].parse().unwrap(), cols[1].parse().unwrap());
        assert_eq!((i, j), (k as u32 % res.nu, k as u32 / res.nu));
        let p: Vec<f64> = cols[2..5].iter().map(|c| c.parse().unwrap()).collect();
        assert_eq!(p, s.point(i, j));
        for f in 0..2 {
            let v: f64 = cols[5 + f].parse().unwrap();
            assert!(same_value(v, s.sample(i, j)[f]), "{line}");
        }
        n += 1;
    }
    assert_eq!(n, res.count());

    // JSON: the geometry, the field order, the count outside, values[field][j][i].
    let j: serde_json::Value = serde_json::from_slice(&written(&s, PlaneFormat::Json)).unwrap();
    assert_eq!(j["origin"], serde_json::json!(plane.origin));
    assert_eq!(j["u"], serde_json::json!(plane.u));
    assert_eq!(j["v"], serde_json::json!(plane.v));
    assert_eq!(j["resolution"], serde_json::json!([13, 7]));
    assert_eq!(j["fields"], serde_json::json!(["q", "speed"]));
    assert_eq!(j["outside"], s.outside);
    assert!(j["samples_at"].as_str().unwrap().contains("(i + 0.5) / NU"));
    for (f, name) in ["q", "speed"].iter().enumerate() {
        let rows = j["values"][name].as_array().unwrap();
        assert_eq!(rows.len(), res.nv as usize);
        for (jj, row) in rows.iter().enumerate() {
            let row = row.as_array().unwrap();
            assert_eq!(row.len(), res.nu as usize);
            for (i, v) in row.iter().enumerate() {
                let want = s.sample(i as u32, jj as u32)[f];
                let have = v.as_f64().unwrap_or(f64::NAN);
                assert!(v.is_null() == want.is_nan(), "({i}, {jj}): {v}");
                assert!(same_value(have, want), "({i}, {jj}): {v} vs {want}");
            }
        }
    }

    // .npy: float32, little-endian, shape (NV, NU, nfields), C order.
    let npy = written(&s, PlaneFormat::Npy);
    let read = npyz::NpyFile::new(&npy[..]).unwrap();
    assert_eq!(read.shape(), [7, 13, 2]);
    assert_eq!(read.dtype().descr(), "'<f4'");
    assert_eq!(read.order(), npyz::Order::C);
    let values: Vec<f32> = read.into_vec().unwrap();
    assert_eq!(
        values.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        s.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    // a[j, i, f] is sample (i, j)'s field f.
    let (i, jj) = (5, 3);
    assert_eq!(
        values[(jj * 13 + i) * 2 + 1].to_bits(),
        s.sample(i as u32, jj as u32)[1].to_bits()
    );
}

#[test]
fn sampling_refuses_no_fields_unknown_fields_and_empty_grids() {
    let (file, plane, res) = small_samples();
    let view = testvol::open(&file).unwrap();
    let vol = Volume::new(&view).unwrap();
    assert_eq!(
        plane::sample(&vol, &plane, res, &[])
            .unwrap_err()
            .to_string(),
        "no field to sample"
    );
    assert_eq!(
        plane::sample(&vol, &plane, res, &[0, 2])
            .unwrap_err()
            .to_string(),
        "field 2 is not in the file (2 fields)"
    );
    assert_eq!(
        plane::sample(&vol, &plane, Resolution { nu: 0, nv: 3 }, &[0])
            .unwrap_err()
            .to_string(),
        "--resolution: expected 1..=16384, found 0"
    );
    let e = plane::check_memory(
        Resolution {
            nu: 16384,
            nv: 16384,
        },
        1 << 20,
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .starts_with("a 16384x16384 plane of 1048576 field(s) needs about"),
        "{e}"
    );
}

"""The Python module against the CLIs: same pictures, same probes, same errors."""

import json
import math
import shutil
import threading
import time
from importlib import metadata

import numpy as np
import pytest

import qbricks
from conftest import SAMPLE, SAMPLE_VDB
from png import read_png

VIEW = dict(width=160, height=120, overlays="legend,axes,title,box", colormap="magma")


def test_render_equals_cli(ds, cli, tmp_path):
    out, saved = tmp_path / "cli.png", tmp_path / "state.json"
    cli("qbricks-view", "render", SAMPLE, "-o", out, "--width", 160, "--height", 120,
        "--overlays", "legend,axes,title,box", "--colormap", "magma", "--save-state", saved)
    expected = read_png(out)
    img = ds.render(**VIEW)
    assert img.array.shape == (120, 160, 4) and img.array.dtype == np.uint8
    assert (img.array[:, :, 3] == 255).all()
    np.testing.assert_array_equal(img.array[:, :, :3], expected)
    # The effective state is the one the CLI saves, and rendering from it (a path or a
    # dict) gives the same picture.
    assert img.state == json.loads(saved.read_text())
    np.testing.assert_array_equal(ds.render(saved).array, img.array)
    np.testing.assert_array_equal(ds.render(img.state).array, img.array)


def test_render_flags_equal_cli(ds, cli, tmp_path):
    """Camera, iso list, clip planes and slices pass through as the CLI's flags."""
    out = tmp_path / "cli.png"
    args = ["--width", 96, "--height", 64, "--iso", "0.5,2", "--eye", "3,2,1.5",
            "--look-at", "0,0,0", "--fov", 35, "--clip", "x>-0.5", "--slice", "0,0,0:0,0,1",
            "--overlays", "none"]
    cli("qbricks-view", "render", SAMPLE, "-o", out, *args)
    img = ds.render(width=96, height=64, iso=[0.5, 2], eye=(3, 2, 1.5), look_at=[0, 0, 0],
                    fov=35, clip=["x>-0.5"], slices=[((0, 0, 0), (0, 0, 1))], overlays="none")
    np.testing.assert_array_equal(img.array[:, :, :3], read_png(out))


def test_keyword_values(ds):
    """numpy numbers and arrays, tuples and empty lists read as the CLI's text would."""
    a = ds.state(eye=np.array([3.0, 2.0, 1.5]), look_at=(np.float32(0), 0, 0), fov=np.int64(35),
                 colour_range=(np.float64(0.0), 0.05), overlays=[], spp=np.uint8(2))
    b = ds.state(eye="3,2,1.5", look_at="0,0,0", fov=35, colour_range="0,0.05",
                 overlays="none", spp=2)
    assert a == b


def test_state_round_trip(ds):
    s = ds.state(width=64, height=48, iso=1.5)
    assert s["width"] == 64 and s["iso"] == 1.5
    # A state given back comes back unchanged, and renders as the flags did.
    assert ds.state(s) == s
    a, b = ds.render(s), ds.render(width=64, height=48, iso=1.5)
    assert a.state == s
    np.testing.assert_array_equal(a.array, b.array)
    # A flag over a state changes only what it names.
    t = ds.state(s, spp=2)
    assert t["spp"] == 2 and {k: v for k, v in t.items() if k != "spp"} == {
        k: v for k, v in s.items() if k != "spp"}


def test_depth_and_png(ds, tmp_path):
    img = ds.render(width=48, height=32, depth=True)
    assert img.depth.shape == (32, 48) and img.depth.dtype == np.float32
    assert np.isfinite(img.depth).any()
    img.save(tmp_path / "a.png")
    np.testing.assert_array_equal(read_png(tmp_path / "a.png"), img.array[:, :, :3])
    assert img._repr_png_().startswith(b"\x89PNG")


def test_probe_equals_cli(ds, cli, tmp_path):
    (lo, hi) = ds.bounds
    rng = np.random.default_rng(7)
    pts = rng.uniform(np.array(lo) - 0.2, np.array(hi) + 0.2, size=(200, 3))
    csv = tmp_path / "p.csv"
    csv.write_text("x,y,z\n" + "".join(f"{float(x)!r},{float(y)!r},{float(z)!r}\n"
                                        for x, y, z in pts))
    text = cli("qbricks-view", "probe", SAMPLE, "--points", csv).decode()
    lines = text.strip().split("\n")
    header = lines[0].split(",")
    rows = np.array([[float(v) for v in l.split(",")] for l in lines[1:]])
    got = ds.probe(pts)
    for name in ds.fields:
        np.testing.assert_array_equal(got[name], rows[:, header.index(name)])
    g = [i for i, h in enumerate(header) if h.startswith("d")][:3]
    np.testing.assert_array_equal(got["gradient"], rows[:, g])
    n = [header.index(f"normal_{a}") for a in "xyz"]
    np.testing.assert_array_equal(got["normal"], rows[:, n])
    outside = ~((pts >= lo) & (pts <= hi)).all(axis=1)
    assert outside.any() and np.isnan(got["q"][outside]).all()


def test_info_and_histogram(ds, cli):
    info = json.loads(cli("qbricks-view", "info", SAMPLE, "--json"))
    mine = ds.info()
    assert {k: mine[k] for k in info} == info
    assert list(ds.fields) == [f["name"] for f in info["fields"]]
    counts, edges = ds.histogram("q")
    assert len(edges) == len(counts) + 1 and counts.sum() > 0
    assert (edges[0], edges[-1]) == pytest.approx(ds.fields["q"])


def test_errors(ds, tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.qbk"):
        qbricks.open(tmp_path / "nope.qbk")
    bad = tmp_path / "bad.qbk"
    bad.write_bytes(SAMPLE.read_bytes()[:100000])
    with pytest.raises(qbricks.FormatError, match="bad.qbk: .*truncated"):
        qbricks.open(bad)
    assert issubclass(qbricks.FormatError, ValueError)
    with pytest.raises(ValueError, match="nofield"):
        ds.render(width=8, height=8, colour_field="nofield")
    with pytest.raises(ValueError, match="strategy"):
        ds.render(strategy="bogus")
    with pytest.raises(ValueError):
        ds.probe(np.zeros((3, 2)))
    with pytest.raises(FileNotFoundError):
        ds.render(tmp_path / "missing-state.json")


def test_gil_released_during_render(ds):
    ticks = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    t = threading.Thread(target=count)
    t.start()
    try:
        t0 = time.perf_counter()
        ds.render(width=512, height=512, spp=4, threads=1)
        t1 = time.perf_counter()
    finally:
        stop.set()
        t.join()
    during = [x for x in ticks if t0 < x < t1]
    assert t1 - t0 > 0.05, "render too fast to tell"
    # The other thread ran throughout the render, not only before and after.
    assert len(during) >= 10


def test_dataset_outlives_nothing(tmp_path):
    """Results are copies: they stay valid after the dataset (and its map) is gone."""
    path = tmp_path / "copy.qbk"
    shutil.copy(SAMPLE, path)
    ds = qbricks.open(path)
    img = ds.render(width=32, height=24)
    p = ds.probe([[0.0, 0.0, 0.0]])
    del ds
    path.unlink()
    assert img.array.sum() > 0 and p["q"].shape == (1,)


def test_bake_equals_cli(cli, tmp_path):
    summary = qbricks.bake(SAMPLE_VDB, tmp_path / "py.qbk", fields="q,speed,vorticity")
    cli_summary = json.loads(cli("qbricks-bake", "bake", SAMPLE_VDB, "-o", tmp_path / "cli.qbk",
                                 "--fields", "q,speed,vorticity", "--json"))
    for k in ("seconds", "output"):
        summary.pop(k), cli_summary.pop(k)
    summary.pop("warnings")
    assert cli_summary.pop("peak_memory") > 0
    assert summary == cli_summary
    assert (tmp_path / "py.qbk").read_bytes() == (tmp_path / "cli.qbk").read_bytes()
    # A memory budget changes where values are kept, not the file; one below any bake is
    # refused by its size.
    qbricks.bake(SAMPLE_VDB, tmp_path / "m.qbk", fields="q,speed,vorticity", memory="64M")
    assert (tmp_path / "m.qbk").read_bytes() == (tmp_path / "cli.qbk").read_bytes()
    with pytest.raises(ValueError, match="memory: expected 16M"):
        qbricks.bake(SAMPLE_VDB, tmp_path / "x.qbk", memory=1 << 20)
    assert list(qbricks.open(tmp_path / "py.qbk").fields) == ["q", "speed", "vorticity"]
    with pytest.raises(FileNotFoundError):
        qbricks.bake(tmp_path / "missing.vdb")


def test_wheel_is_abi3():
    wheel = metadata.distribution("qbricks").read_text("WHEEL")
    tags = [l.split(":", 1)[1].strip() for l in wheel.splitlines() if l.startswith("Tag:")]
    assert tags and all(t.startswith("cp39-abi3-") for t in tags), tags


def test_ctrl_c_interrupts_render(ds):
    """Ctrl-C (here `_thread.interrupt_main`, which raises SIGINT's KeyboardInterrupt in
    the main thread) stops a long render: KeyboardInterrupt soon, no crash, and the
    dataset still renders afterwards."""
    import _thread

    timer = threading.Timer(0.3, _thread.interrupt_main)
    timer.start()
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        ds.render(width=2048, height=2048, spp=64, threads=1)
    stopped = time.perf_counter() - t0
    timer.join()
    assert stopped < 10, stopped
    assert ds.render(width=16, height=16).array.shape == (16, 16, 4)


def test_probe_plane_equals_cli(ds, cli, tmp_path):
    out = tmp_path / "plane.npy"
    cli("qbricks-view", "probe", SAMPLE, "--plane", "z=0.1", "--resolution", "40,24",
        "--fields", "speed,q", "-o", out)
    expected = np.load(out)
    got = ds.probe_plane("z=0.1", resolution=(40, 24), fields=["speed", "q"])
    assert expected.shape == (24, 40, 2) and got["speed"].shape == (24, 40)
    np.testing.assert_array_equal(np.stack([got["speed"], got["q"]], axis=2), expected)
    assert got["outside"] == int(np.isnan(expected[:, :, 0]).sum())
    everything = ds.probe_plane("z=0.1", resolution=40)
    assert set(ds.fields) <= set(everything)
    with pytest.raises(ValueError, match="plane"):
        ds.probe_plane("nonsense")


def test_view_state_round_trip(ds, cli, tmp_path):
    """A qbricks.ViewState reads, writes and renders as the CLI's state files do."""
    saved, mine, out_cli = tmp_path / "cli.json", tmp_path / "py.json", tmp_path / "cli.png"
    cli("qbricks-view", "render", SAMPLE, "-o", tmp_path / "first.png", "--width", 96,
        "--height", 64, "--iso", "0.5,2", "--clip", "x>-0.5", "--save-state", saved)
    vs = qbricks.ViewState.load(saved)
    assert vs == json.loads(saved.read_text())
    assert vs.to_json() + "\n" == saved.read_text()
    assert qbricks.ViewState(vs.to_dict()) == vs and qbricks.ViewState.from_json(vs.to_json()) == vs
    # Attribute and item access, each change checked; a bad one leaves the state as it was.
    vs.width = 80
    vs["spp"] = 2
    assert (vs.width, vs["spp"], vs.height) == (80, 2, 64)
    with pytest.raises(ValueError, match="width"):
        vs.width = 0
    with pytest.raises(ValueError):
        vs.no_such_key = 1
    with pytest.raises(ValueError):
        qbricks.ViewState({**vs.to_dict(), "colour_feild": "speed"})
    assert vs.width == 80 and "no_such_key" not in vs
    # Nested values are copies: changing one changes nothing until it is set back.
    cam = vs.camera
    cam["eye"] = [4.0, 2.0, 1.0]
    assert vs.camera["eye"] != [4.0, 2.0, 1.0]
    vs.camera = cam
    assert vs.camera["eye"] == [4.0, 2.0, 1.0]
    assert vs.replace(height=50).height == 50 and vs.height == 64
    # Saved by Python, rendered by the CLI: the same picture as Python renders.
    vs.save(mine)
    assert qbricks.ViewState.load(mine) == vs
    cli("qbricks-view", "render", SAMPLE, "--state", mine, "-o", out_cli)
    img = ds.render(vs)
    np.testing.assert_array_equal(img.array[:, :, :3], read_png(out_cli))
    assert isinstance(img.state, qbricks.ViewState) and img.state == vs
    with pytest.raises(FileNotFoundError):
        qbricks.ViewState.load(tmp_path / "none.json")


def test_aov_buffers(ds, cli, tmp_path):
    """aov= gives the debug buffers as numbers, and the CLI's --aov picture."""
    view = dict(width=64, height=48, eye=(3, 2, 1.5), look_at=(0, 0, 0))
    shaded = ds.render(depth=True, **view)
    levels = {l["level"] for l in ds.levels}
    bufs = {}
    for aov in ("normal", "depth", "level", "value"):
        out = tmp_path / f"{aov}.png"
        cli("qbricks-view", "render", SAMPLE, "-o", out, "--aov", aov, "--width", 64,
            "--height", 48, "--eye", "3,2,1.5", "--look-at", "0,0,0")
        img = ds.render(aov=aov, **view)
        np.testing.assert_array_equal(img.array[:, :, :3], read_png(out))
        assert img.aov.dtype == np.float32
        assert img.aov.shape == (48, 64, 3 if aov == "normal" else 1)
        bufs[aov] = img.aov
    t = bufs["depth"][:, :, 0]
    hit = np.isfinite(t)
    assert hit.any() and (~hit).any()
    # The iso-surface's first hit is the shaded picture's depth where no mesh is in front.
    np.testing.assert_allclose(t[hit], shaded.depth[hit], rtol=1e-6)
    n = bufs["normal"]
    np.testing.assert_allclose(np.linalg.norm(n[hit], axis=1), 1.0, atol=1e-5)
    assert np.isnan(n[~hit]).all()
    assert set(np.unique(bufs["level"][hit])) <= levels and np.isnan(bufs["level"][~hit]).all()
    lo, hi = ds.fields[ds.state(**view)["colormap"]["field"]]
    v = bufs["value"][hit]
    assert np.isfinite(v).all() and (v >= lo).all() and (v <= hi).all()
    with pytest.raises(ValueError, match="aov"):
        ds.render(aov="bogus", width=8, height=8)


def test_missing_mesh_is_file_not_found(ds, tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.obj"):
        ds.render(width=8, height=8, meshes=[str(tmp_path / "nope.obj")])


def _frames(tmp_path, n):
    """A frame sequence of `n` frames: links to the bundled sample."""
    src = tmp_path / "cache"
    src.mkdir()
    for i in range(1, n + 1):
        (src / f"frame_{i:04d}.vdb").symlink_to(SAMPLE_VDB)
    return src


def test_bake_sequence_equals_cli(cli, tmp_path):
    src = _frames(tmp_path, 3)
    summary = qbricks.bake(src / "frame_####.vdb", tmp_path / "py" / "f_####.qbk", jobs=2)
    cli_summary = json.loads(cli("qbricks-bake", "bake", src / "frame_####.vdb", "-o",
                                 tmp_path / "cli" / "f_####.qbk", "--jobs", 2, "--json"))
    for s in (summary, cli_summary):
        s.pop("seconds")
        s.pop("manifest")
    assert summary == cli_summary and summary["frames"] == 3
    for i in (1, 2, 3):
        assert (tmp_path / "py" / f"f_{i:04d}.qbk").read_bytes() == \
            (tmp_path / "cli" / f"f_{i:04d}.qbk").read_bytes()
    manifest = [p for p in (tmp_path / "py").iterdir() if p.suffix == ".json"]
    assert len(manifest) == 1 and len(json.loads(manifest[0].read_text())["frames"]) == 3
    # A broken frame: named in the error once the others are baked, and in the manifest.
    (src / "frame_0004.vdb").write_bytes(b"not a vdb")
    with pytest.raises(ValueError, match="1 of 4 frames failed: .*frame_0004.vdb"):
        qbricks.bake(src / "frame_####.vdb", tmp_path / "py2" / "f_####.qbk")
    assert len(list((tmp_path / "py2").glob("f_*.qbk"))) == 3
    with pytest.raises(ValueError, match="must be one too"):
        qbricks.bake(src / "frame_####.vdb", tmp_path / "one.qbk")


def test_ctrl_c_interrupts_bake(tmp_path):
    """Ctrl-C stops a long sequence bake between frames: KeyboardInterrupt, frames already
    written are whole, no manifest, and the module still bakes afterwards."""
    import _thread

    src = _frames(tmp_path, 400)
    out = tmp_path / "out"
    timer = threading.Timer(0.5, _thread.interrupt_main)
    timer.start()
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        qbricks.bake(src / "frame_####.vdb", out / "f_####.qbk", jobs=1, threads=1)
    stopped = time.perf_counter() - t0
    timer.join()
    done = sorted(out.glob("f_*.qbk"))
    assert stopped < 10 and 0 < len(done) < 400, (stopped, len(done))
    assert not list(out.glob("*.json")) and not list(out.glob(".*"))
    for p in done:
        qbricks.open(p)
    assert qbricks.bake(SAMPLE_VDB, tmp_path / "after.qbk")["bricks"] > 0


def test_saves_never_overwrite_inputs(tmp_path):
    """Image.save and ViewState.save refuse the files a picture was made from (as the CLI's
    outputs do) and write atomically through symlinks and into FIFOs."""
    import os
    path = tmp_path / "copy.qbk"
    shutil.copy(SAMPLE, path)
    ds = qbricks.open(path)
    state_file = tmp_path / "view.json"
    ds.state(width=32, height=24).save(state_file)
    img = ds.render(state_file)
    before = path.read_bytes()
    with pytest.raises(ValueError, match="copy.qbk"):
        img.save(path)
    link = tmp_path / "link.png"
    link.symlink_to(path)
    with pytest.raises(ValueError):
        img.save(link)
    with pytest.raises(ValueError, match="view.json"):
        img.save(state_file)
    assert path.read_bytes() == before
    mesh = tmp_path / "m.obj"
    shutil.copy(SAMPLE.parent / "sphere.obj", mesh)
    vs = ds.state(width=32, height=24, meshes=[f"{mesh}@0,0,0,0.5"])
    with pytest.raises(ValueError, match="m.obj"):
        vs.save(mesh)
    # A symlink to a new file is written through; a FIFO is written into.
    target = tmp_path / "real.png"
    out_link = tmp_path / "out.png"
    out_link.symlink_to(target)
    img.save(out_link)
    assert out_link.is_symlink() and read_png(target).shape == (24, 32, 3)
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(open(fifo, "rb").read()))
    reader.start()
    img.save(fifo)
    reader.join(10)
    assert got and got[0].startswith(b"\x89PNG")

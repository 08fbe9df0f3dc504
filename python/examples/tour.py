"""A tour of the qbricks module on the bundled sample: bake it, render it, plot the
histogram of Q and the values along a line (with matplotlib when it is installed).

    .venv/bin/python python/examples/tour.py [OUT_DIR]      # from the repository root
"""

import pathlib
import sys
import tempfile

import numpy as np

import qbricks

repo = pathlib.Path(__file__).resolve().parents[2]
out = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="qbricks-"))
out.mkdir(parents=True, exist_ok=True)

# Bake the bundled OpenVDB velocity into a brick file, with vorticity besides Q and speed.
summary = qbricks.bake(repo / "data" / "wake_small.vdb", out / "wake.qbk",
                       fields="q,speed,vorticity")
print(f"baked {summary['leaf_cells']} cells into {summary['bricks']} bricks "
      f"in {summary['seconds']:.2f} s: {summary['output']}")

ds = qbricks.open(out / "wake.qbk")
print(ds, ds.fields)

# The default view, then the same view coloured by vorticity with a legend.
img = ds.render(width=640, height=360, colour_field="vorticity", colormap="magma",
                overlays="legend,axes,title")
img.save(out / "wake.png")
print("picture:", img.array.shape, "->", out / "wake.png")

# The view that made it is a qbricks.ViewState: change it, save it for `qbricks-view
# render --state` or the window, render it again.
view = img.state
view.width, view.height = 320, 180
view.save(out / "view.json")
small = ds.render(view, aov="depth")             # the distance to the surface, as numbers
hit = np.isfinite(small.aov[:, :, 0])
print(f"view -> {out / 'view.json'}; {hit.mean():.0%} of a {view.width}x{view.height} "
      f"picture shows the surface, {small.aov[hit].min():.3g} to {small.aov[hit].max():.3g} away")

# The stored histogram of Q and a probe along the wake's axis.
counts, edges = ds.histogram("q")
(lo, hi) = ds.bounds
xs = np.linspace(lo[0], hi[0], 400)
line = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], axis=1)
values = ds.probe(line)
print(f"q along the x axis (through the rings): {np.nanmin(values['q']):.4g} to "
      f"{np.nanmax(values['q']):.4g}; vorticity up to {np.nanmax(values['vorticity']):.4g}")

try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    print("(matplotlib not installed: no plots)")
else:
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(15, 4))
    a.imshow(img.array)
    a.set_axis_off()
    b.stairs(counts, edges)
    b.set_yscale("log")
    b.set_xlabel("Q")
    b.set_ylabel("leaf cells")
    c.plot(xs, values["q"], label="Q")
    c.plot(xs, values["vorticity"], label="|ω|")
    c.set_xlabel("x (y = z = 0)")
    c.legend()
    fig.tight_layout()
    fig.savefig(out / "tour.png", dpi=100)
    print("plots ->", out / "tour.png")

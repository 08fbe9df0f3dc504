"""Q on each level of a nested-box velocity file, for yt.

Run with the system Python that has OpenVDB's bindings (Debian's python3-openvdb):
    /usr/bin/python3 levels.py independent.vdb levels.npz
Every grid of the file is one level: its active bounding box is copied to a dense array,
the velocity gradient is taken by second-order central differences (one-sided at the
box's faces, numpy.gradient), and Q = (|W|^2 - |S|^2) / 2 is saved with the box's lower
corner and cell width.
"""
import sys

import numpy as np
import pyopenvdb as vdb


def main(src, dst):
    grids, _ = vdb.readAll(src)
    out = {}
    widths = []
    for g in grids:
        lo, hi = g.evalActiveVoxelBoundingBox()
        h = g.transform.voxelSize()[0]
        dims = tuple(hi[a] - lo[a] + 1 for a in range(3))
        vel = np.zeros(dims + (3,), dtype=np.float32)
        g.copyToArray(vel, ijk=lo)
        u = vel.astype(np.float64)
        jac = np.empty(dims + (3, 3))
        for c in range(3):
            for a, d in enumerate(np.gradient(u[..., c], h)):
                jac[..., c, a] = d
        s = 0.5 * (jac + np.swapaxes(jac, -1, -2))
        w = 0.5 * (jac - np.swapaxes(jac, -1, -2))
        q = 0.5 * ((w**2).sum(axis=(-1, -2)) - (s**2).sum(axis=(-1, -2)))
        left = np.array(g.transform.indexToWorld(lo)) - 0.5 * h
        print(f"{g.name}: cell {h}, {dims[0]}x{dims[1]}x{dims[2]} from {left}, "
              f"Q in [{q.min():.4g}, {q.max():.4g}]")
        out[f"q_{h}"] = q.astype(np.float64)
        out[f"left_{h}"] = left
        widths.append(h)
    # Level 0 is the coarsest, as yt numbers them.
    out["widths"] = np.array(sorted(widths, reverse=True))
    np.savez(dst, **out)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])

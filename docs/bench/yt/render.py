"""yt's AMR volume render of the levels levels.py saved, timed.

    python render.py levels.npz SIZE REPEATS OUT.png
The camera is docs/bench/speed_goals.sh's (eye 3.5,-4.5,2, looking at 2.3,0,0, up +z,
30 degrees field of view) through yt's perspective lens, and the transfer function one
narrow Gaussian layer at Q = 0.05, the iso value qbricks renders there: the closest yt's
volume renderer comes to an iso-surface. Prints every render's seconds and their median
(the first includes yt's set-up of the scene).
"""
import sys
import time

import numpy as np
import yt


def main(levels, size, repeats, png):
    d = np.load(levels)
    grids = []
    for lvl, h in enumerate(d["widths"]):
        q = d[f"q_{h}"]
        left = d[f"left_{h}"]
        grids.append(dict(left_edge=left, right_edge=left + np.array(q.shape) * h,
                          level=lvl, dimensions=np.array(q.shape), q=q))
    lo = grids[0]["left_edge"]
    hi = grids[0]["right_edge"]
    ds = yt.load_amr_grids(grids, grids[0]["dimensions"],
                           bbox=np.array([lo, hi]).T, refine_by=2)
    sc = yt.create_scene(ds, ("stream", "q"))
    src = sc[0]
    src.log_field = False
    tf = yt.ColorTransferFunction((0.0, 0.2))
    tf.add_gaussian(0.05, 0.002, [0.2, 0.8, 0.3, 1.0])
    src.set_transfer_function(tf)
    cam = sc.camera
    cam.resolution = (size, size)
    eye = np.array([3.5, -4.5, 2.0])
    focus = np.array([2.3, 0.0, 0.0])
    dist = np.linalg.norm(focus - eye)
    cam.focus = ds.arr(focus, "code_length")
    cam.set_position(ds.arr(eye, "code_length"), north_vector=[0, 0, 1])
    cam.set_lens("perspective")
    # yt's perspective lens puts the image plane `width[2]` in front of the camera.
    half = dist * np.tan(np.radians(15))
    cam.set_width(ds.arr([2 * half, 2 * half, dist], "code_length"))
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        sc.render()
        times.append(time.perf_counter() - t)
    sc.save(png, sigma_clip=4)
    ms = sorted(t * 1000 for t in times)
    print("yt_ms", " ".join(f"{t * 1000:.1f}" for t in times), "median", f"{ms[len(ms) // 2]:.1f}")


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4])

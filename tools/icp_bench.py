#!/usr/bin/env python3
"""Open3D's half of the ICP comparison in `cargo xtask ort-bench` (issue 13).

Reads DIR/icp/ as `train-host/eval/examples/ort_bench.rs` wrote it (templates,
sources, true poses, our ICP's poses), runs Open3D's point-to-point
`registration_icp` on the same pairs from the identity on one thread, with
every nearest neighbour as a correspondence (no distance cut-off, as ours):
  - fixed: exactly as many iterations as ours (no stop rule on either side);
  - stop rule: Open3D's default convergence criteria beside ours.
Times are per registration, the median and the best round of each side,
timed in turn round by round with ours (`bench_timing.paired`; our rounds run
by OURS, `ort_bench serve`).
Prints the time ratios, each side's rotation errors, and how far the two
fixed-iteration poses are apart.

Usage: icp_bench.py DIR OURS
"""

import json
import os
import pathlib
import sys

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import open3d as o3d  # noqa: E402
from bench_timing import Ours, paired, time_round  # noqa: E402

POINTS = 1024
reg = o3d.pipelines.registration


def rotation_error_deg(r_est, r_gt):
    c = (np.trace(r_est @ r_gt.T) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def cloud(points):
    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(points.astype(np.float64))
    return pc


def main():
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    ours_side = Ours(sys.argv[2], sys.argv[1])
    d = pathlib.Path(sys.argv[1]) / "icp"
    templates = np.fromfile(d / "template.f32", dtype="<f4").reshape(-1, POINTS, 3)
    sources = np.fromfile(d / "source.f32", dtype="<f4").reshape(len(templates), -1, 3)
    truth = json.loads((d / "truth.json").read_text())
    ours = json.loads((d / "ours.json").read_text())
    pairs = [(cloud(s), cloud(t)) for s, t in zip(sources, templates)]
    init = np.eye(4)
    # Row name: (our setting's name, Open3D's criteria).
    settings = {
        "fixed": (
            "fixed",
            reg.ICPConvergenceCriteria(
                relative_fitness=0.0, relative_rmse=0.0, max_iteration=ours["fixed_iterations"]
            ),
        ),
        "stop rule": ("stop", reg.ICPConvergenceCriteria()),
    }
    print(f"open3d {o3d.__version__}, OMP_NUM_THREADS={os.environ['OMP_NUM_THREADS']}; {len(pairs)} pairs")
    print()
    print(
        "| ICP | ours ms | Open3D ms | ours / Open3D | best rounds: ours / Open3D | "
        "rotation error mean / median, ours | Open3D | poses apart (max) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name, (setting, criteria) in settings.items():

        def run(p):
            return reg.registration_icp(
                p[0], p[1], 1e9, init, reg.TransformationEstimationPointToPoint(), criteria
            )

        results = [run(p) for p in pairs]
        (ours_ms, ours_best), (o3d_ms, o3d_best) = paired(
            lambda: ours_side.round(f"icp {setting}"), lambda: time_round(run, pairs)
        )
        gt = [np.array(x["r"]) for x in truth]
        theirs = [np.array(x.transformation[:3, :3]) for x in results]
        mine = [np.array(x["r"]) for x in ours[setting]["poses"]]
        err_theirs = [rotation_error_deg(a, b) for a, b in zip(theirs, gt)]
        err_mine = [rotation_error_deg(a, b) for a, b in zip(mine, gt)]
        apart = max(rotation_error_deg(a, b) for a, b in zip(mine, theirs))
        print(
            f"| {name} | {ours_ms:.3f} | {o3d_ms:.3f} | {ours_ms / o3d_ms:.2f}x | "
            f"{ours_best:.3f} / {o3d_best:.3f} = {ours_best / o3d_best:.2f}x | "
            f"{np.mean(err_mine):.2f}° / {np.median(err_mine):.2f}° | "
            f"{np.mean(err_theirs):.2f}° / {np.median(err_theirs):.2f}° | {apart:.2e}° |"
        )
    ours_side.close()


if __name__ == "__main__":
    main()

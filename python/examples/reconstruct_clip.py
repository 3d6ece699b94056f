"""Reconstruct a clip from Python, plot its camera path, write transforms.json, and score it.

    python3 python/examples/reconstruct_clip.py [VIDEO [GROUNDTRUTH]] [--out OUT]

Without a video, a short synthetic one is rendered first (loopsfm.synth), with its exact
ground truth. Writes OUT/path.png (the path seen from above, aligned to the ground truth where
there is one) beside what reconstruct writes (OUT/transforms.json for nerfstudio, OUT/sparse/0
for COLMAP, ...). Needs matplotlib (Debian's python3-matplotlib).
"""

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files, not windows
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import loopsfm  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("video", nargs="?", help="video or image folder (default: a synthetic one)")
    parser.add_argument("groundtruth", nargs="?", help="ground truth trajectory (TUM-like)")
    parser.add_argument("--out", default="loopsfm_example", help="output folder")
    parser.add_argument("--frames", type=int, default=60, help="frames of the synthetic video")
    args = parser.parse_args()
    out = Path(args.out)

    options = {}
    video, groundtruth = args.video, args.groundtruth
    if video is None:
        scene = out / "scene"
        loopsfm.synth("cylinder", scene, video=True, frames=args.frames, width=480, height=360,
                      quiet=True)
        video, groundtruth = scene / "video.mp4", scene / "groundtruth.txt"
        options = {"intrinsics": scene / "intrinsics.txt", "every": 1}

    def progress(stage: str, done: int, total: int) -> None:
        print(f"\r{stage:>10}: {done}{f' of {total}' if total else ''}", end="", flush=True)

    report = loopsfm.reconstruct(video, out, progress=progress, quiet=True,
                                 export=["colmap", "ply", "tum", "nerfstudio"], **options)
    print()
    if not report["models"]:
        print("no model: see the log above", file=sys.stderr)
        return 1
    model = loopsfm.read_model(out)
    print(f"{len(model)} of {report['num_frames']} frames in the largest model, "
          f"{len(model.xyz)} points, {report['total_seconds']:.1f} s")
    print(f"transforms.json for nerfstudio: {out / 'transforms.json'}")

    figure, axes = plt.subplots(figsize=(6, 6))
    if groundtruth:
        metrics = loopsfm.evaluate(out / "sparse" / "0", groundtruth)
        print(f"ATE {100 * metrics['ate_fraction_of_path']:.3f} % of the path, rotation error "
              f"{metrics['rotation_error_mean_deg']:.3f} deg on average")
        # Ground truth: "name tx ty tz qx qy qz qw" per line, camera-to-world.
        truth = np.loadtxt(groundtruth, usecols=(1, 2, 3), comments="#", ndmin=2)
        aligned = np.array([f["aligned_centre"] for f in metrics["frames"]], dtype=float)
        axes.plot(truth[:, 0], truth[:, 2], color="0.6", label="ground truth")
        axes.plot(aligned[:, 0], aligned[:, 2], color="tab:blue", label="loopsfm (aligned)")
    else:
        axes.plot(model.centres[:, 0], model.centres[:, 2], color="tab:blue", label="loopsfm")
    axes.set_aspect("equal")
    axes.set_xlabel("x")
    axes.set_ylabel("z")
    axes.legend()
    figure.savefig(out / "path.png", dpi=100)
    print(f"path plot: {out / 'path.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""How loopsfm grows with the length of a video (issue 39): rendered street walks of 1k, 2k,
5k and 10k frames at the same density, end to end, with time and peak memory per stage,
fitted exponents, and accuracy against ground truth at each size.

    bench/scale/scale.py render --workdir DIR [--sizes 1k,2k,5k,10k | 1k-avenue,...]
    bench/scale/scale.py run --workdir DIR [--sizes ...] [--loopsfm build/loopsfm]
        [-- EXTRA RECONSTRUCT FLAGS]
    bench/scale/scale.py report --workdir DIR [--sizes ...]

`render` writes DIR/<size>/video.mp4 and groundtruth.txt with `loopsfm synth street`: 30 fps,
about 0.1 m a frame (a brisk walk), hand-held shake (1 degree) and jitter (2 cm), sensor
noise, JPEG, the view turned 20 degrees ahead. 1k and 2k walk one and two laps round a
block, 5k two and a half laps of a figure eight round two blocks, 10k five laps: every one
of these default sizes returns to places it has seen (loops to close). The avenue sizes,
rendered and run only when --sizes names them (1k-avenue, 2k-avenue, 5k-avenue, 10k-avenue,
21k-avenue), walk as far at the same density straight along a row of blocks and never come
back: how mapping grows with the length of a walk without laps over the same facades (give
them a DIR of their own: the table and the fits go by frame count). 21k-avenue keeps about
4,500 frames, the views of the thesis' Figure 6.2 (`views.py`). `run` reconstructs each with default
flags (self-calibrated, adaptive keyframes), one after the other, scores it with `loopsfm
eval`, prints a Markdown table and the fitted exponents (time ~ frames^k by least squares on
log-log), and writes DIR/scale.json; sizes run earlier into DIR with the same flags stay in the
table, so the sizes can be run one at a time. `report` rebuilds the table from the logs and
outputs of earlier runs (the peak memory then from loopsfm's own report line). Standard
library only.
"""

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "vs_colmap"))
from vsc_tools import (LOOPSFM_TIME, LOOPSFM_TOTAL, eval_trajectory,  # noqa: E402
                       fit_exponent, fmt, log, num_models, run_measured)

COMMON = ["--video", "--width", "640", "--height", "360", "--look-ahead", "20", "--shake", "1",
          "--jitter", "2", "--noise", "2", "--jpeg-quality", "80"]
SCENES = {
    "1k": ["--frames", "1000", "--route", "block", "--laps", "1", "--revisit", "0"],
    "2k": ["--frames", "2000", "--route", "block", "--laps", "2", "--revisit", "0"],
    "5k": ["--frames", "5000", "--route", "figure8", "--laps", "2", "--revisit", "0.5"],
    "10k": ["--frames", "10000", "--route", "figure8", "--laps", "5", "--revisit", "0"],
}
DEFAULT_SIZES = tuple(SCENES)
# Optional: walks as long as the default sizes' that never revisit a place.
SCENES.update({f"{k}k-avenue": ["--frames", str(1000 * k), "--route", "avenue", "--laps", str(k),
                                "--revisit", "0"] for k in (1, 2, 5, 10, 21)})
STAGES = ("extract", "match", "fill-in", "map", "localise")


def render(args, sizes):
    for size in sizes:
        out = args.workdir / size
        if (out / "video.mp4").exists():
            log(f"{size}: {out / 'video.mp4'} exists; not rendered again")
            continue
        cmd = [args.loopsfm, "synth", "street", "-o", out, "-q"] + SCENES[size] + COMMON
        log(f"{size}: {' '.join(str(c) for c in cmd)}")
        if subprocess.run([str(c) for c in cmd]).returncode != 0:
            log(f"{size}: rendering failed")
            return 1
    return 0


def run_one(args, size, extra):
    scene = args.workdir / size
    out = args.workdir / f"{size}_out"
    shutil.rmtree(out, ignore_errors=True)
    cmd = [args.loopsfm, "reconstruct", scene / "video.mp4", "-o", out, "--export", "colmap,tum"]
    cmd += extra
    log(f"{size}: {' '.join(str(c) for c in cmd)}")
    proc = run_measured(cmd, args.workdir / f"{size}.log")
    result = collect(args, size)
    result.update({"rc": proc["rc"], "wall_s": proc["wall_s"], "peak_mib": proc["peak_mib"]})
    log(f"{size}: {result['total_s']} s, peak {result['peak_mib']} MiB, kept {result['kept']}, "
        f"{result['mapped']}")
    return result


def collect(args, size):
    """What DIR/<size>.log and DIR/<size>_out say of a finished run."""
    scene = args.workdir / size
    out = args.workdir / f"{size}_out"
    text = (args.workdir / f"{size}.log").read_text()
    result = {"size": size,
              "stages": {k: float(v) for k, v in LOOPSFM_TIME.findall(text)},
              "video_frames": sum(1 for l in (scene / "groundtruth.txt").read_text().splitlines()
                                  if l.strip() and not l.startswith("#"))}
    total = LOOPSFM_TOTAL.search(text)
    result["total_s"] = float(total.group(1)) if total else None
    # The run's own peak (loopsfm's report line); run_one replaces it by the measured one.
    result["peak_mib"] = float(total.group(2)) if total else None
    frames = [l for l in text.splitlines() if l.startswith("frames ")]
    result["kept"] = int(frames[-1].split()[1]) if frames else None
    result["models"] = num_models(out / "sparse")
    result["mapped"] = eval_trajectory(args.loopsfm, out / "sparse" / "0",
                                       scene / "groundtruth.txt") or {}
    return result


def stage_seconds(stages, stage):
    """A stage's seconds from the run's `time` lines: its own line, or the sum of its parts
    (the global mapper's `map: view graph`, `map: positions`, ...) and its second pass."""
    parts = [t for name, t in stages.items()
             if name == stage or name.startswith(stage + ": ") or name == stage + "-again"]
    return sum(parts) if parts else None


def report(results):
    rows = ["| video frames | kept | models | mapped | extract s | match s | map s | total s | "
            "peak MiB | ATE % path | rot. deg | loop gap max |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        s, m = r["stages"], r["mapped"]
        rows.append(f"| {r['video_frames']} | {r['kept']} | {r['models']} | {m.get('frames')} | "
                    f"{fmt(stage_seconds(s, 'extract'))} | {fmt(stage_seconds(s, 'match'))} | "
                    f"{fmt(stage_seconds(s, 'map'))} | "
                    f"{fmt(r['total_s'])} | {fmt(r['peak_mib'], 0)} | {fmt(m.get('ate_pct'), 4)} | "
                    f"{fmt(m.get('rot_deg'), 3)} | {fmt(m.get('gap_max'), 4)} |")
    xs = [r["video_frames"] for r in results]
    fits = {"total": fit_exponent(xs, [r["total_s"] for r in results]),
            "peak memory": fit_exponent(xs, [r["peak_mib"] for r in results]),
            "kept frames": fit_exponent(xs, [r["kept"] for r in results])}
    for stage in STAGES:
        times = [stage_seconds(r["stages"], stage) for r in results]
        if max((t or 0) for t in times) >= 1.0:  # a stage that took no time has no growth
            fits[stage] = fit_exponent(xs, times)
    lines = ["", "Fitted exponents (quantity ~ video frames^k):"]
    lines += [f"- {name}: {fmt(k, 2)}" for name, k in fits.items() if k is not None]
    return "\n".join(rows + lines), fits


def main(argv):
    extra = []
    if "--" in argv:
        extra = argv[argv.index("--") + 1:]
        argv = argv[:argv.index("--")]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("action", choices=("render", "run", "report"))
    parser.add_argument("--workdir", type=Path, required=True)
    parser.add_argument("--sizes", default=",".join(DEFAULT_SIZES),
                        help=f"comma-separated, from {', '.join(SCENES)} "
                             f"(default {','.join(DEFAULT_SIZES)})")
    parser.add_argument("--loopsfm", type=Path,
                        default=Path(__file__).resolve().parents[2] / "build" / "loopsfm")
    args = parser.parse_args(argv)
    sizes = [s for s in args.sizes.split(",") if s]
    unknown = [s for s in sizes if s not in SCENES]
    if unknown or not args.loopsfm.exists():
        print(f"scale.py: unknown sizes {unknown} (choose from {', '.join(SCENES)}) or no "
              f"{args.loopsfm}", file=sys.stderr)
        return 2
    args.workdir.mkdir(parents=True, exist_ok=True)
    if args.action == "render":
        return render(args, sizes)
    missing = [s for s in sizes if not (args.workdir / s / "video.mp4").exists()]
    if missing and args.action == "run":
        print(f"scale.py: no rendered video for {', '.join(missing)}; run `scale.py render` "
              f"first", file=sys.stderr)
        return 2
    if args.action == "report":
        results = [collect(args, size) for size in sizes
                   if (args.workdir / f"{size}.log").exists() and size not in missing]
    else:
        results = [run_one(args, size, extra) for size in sizes]
    # Sizes run before into the same folder (with the same extra flags) stay in the table, so
    # the sizes can be run one at a time.
    saved = args.workdir / "scale.json"
    if saved.exists():
        before = json.loads(saved.read_text())
        if before.get("extra_flags") == extra:
            results += [r for r in before["runs"] if r["size"] not in sizes]
    results.sort(key=lambda r: r["video_frames"])
    text, fits = report(results)
    (args.workdir / "scale.json").write_text(json.dumps({"runs": results, "exponents": fits,
                                                         "extra_flags": extra}, indent=2))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

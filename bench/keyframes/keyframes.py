#!/usr/bin/env python3
"""Adaptive keyframes against fixed windows on one video with ground truth (issue 38).

Runs `loopsfm reconstruct` on VIDEO four ways, each from scratch in its own folder, one after
the other (never side by side): the default (adaptive keyframes), `--every 1` (every frame),
`--every N` with N chosen so that it keeps as many frames as the default did (the same
budget, spread uniformly), and the default with `--all-frames` (a pose for every frame).
Each is scored with `loopsfm eval` against GROUNDTRUTH: the mapped frames (sparse/0), and
for --all-frames also every frame (trajectory.txt) and the localised frames alone
(localized.txt). Prints a Markdown table and writes WORKDIR/keyframes.json.

    bench/keyframes/keyframes.py VIDEO GROUNDTRUTH --workdir DIR [--loopsfm build/loopsfm]
        [--intrinsics FILE] [--only default,every1,everyN,allframes] [--rounds R]

With --rounds R > 1 every run is repeated R times (alternating the runs) and the medians
are reported. Standard library only.
"""

import argparse
import json
import shutil
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "vs_colmap"))
from vsc_tools import (LOOPSFM_TIME, LOOPSFM_TOTAL, eval_trajectory, fmt, log,  # noqa: E402
                       num_models, run_measured)

RUNS = ("default", "every1", "everyN", "allframes")


def one_run(args, name, every_n, round_index):
    out = args.workdir / f"{name}_r{round_index}"
    shutil.rmtree(out, ignore_errors=True)
    cmd = [args.loopsfm, "reconstruct", args.video, "-o", out, "--export", "colmap,tum"]
    if args.intrinsics:
        cmd += ["--intrinsics", args.intrinsics]
    if name == "every1":
        cmd += ["--every", "1"]
    elif name == "everyN":
        cmd += ["--every", str(every_n)]
    elif name == "allframes":
        cmd += ["--all-frames"]
    log(f"{name} (round {round_index}): {' '.join(str(c) for c in cmd)}")
    args.workdir.mkdir(parents=True, exist_ok=True)
    proc = run_measured(cmd, args.workdir / f"{name}_r{round_index}.log")
    text = Path(proc["log"]).read_text()
    result = {"rc": proc["rc"], "wall_s": proc["wall_s"], "peak_mib": proc["peak_mib"],
              "stages": {k: float(v) for k, v in LOOPSFM_TIME.findall(text)}}
    total = LOOPSFM_TOTAL.search(text)
    if total:
        result["total_s"] = float(total.group(1))
    frames = [l for l in text.splitlines() if l.startswith("frames ")]
    result["kept"] = int(frames[-1].split()[1]) if frames else None
    result["models"] = num_models(out / "sparse")
    result["mapped"] = eval_trajectory(args.loopsfm, out / "sparse" / "0", args.groundtruth)
    if name == "allframes":
        result["all"] = eval_trajectory(args.loopsfm, out / "trajectory.txt", args.groundtruth)
        result["localized"] = eval_trajectory(args.loopsfm, out / "localized.txt", args.groundtruth)
    log(f"{name}: {result.get('total_s')} s, kept {result['kept']}, {result['mapped']}")
    return result


def median_run(runs):
    """Medians of the times over the rounds; accuracy from the first round (runs are
    deterministic with one seed, up to the thread schedule)."""
    first = dict(runs[0])
    for key in ("wall_s", "peak_mib", "total_s"):
        values = [r[key] for r in runs if r.get(key) is not None]
        first[key] = statistics.median(values) if values else None
    stages = {}
    for r in runs:
        for k, v in r["stages"].items():
            stages.setdefault(k, []).append(v)
    first["stages"] = {k: statistics.median(v) for k, v in stages.items()}
    first["rounds"] = len(runs)
    return first


def table(results):
    rows = ["| run | frames kept | models | mapped frames | extract s | match s | map s | "
            "localise s | total s | peak MiB | ATE % path | rot. deg | loop gap max |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in results.items():
        s = r["stages"]
        m = r["mapped"] or {}
        mapping = sum(v for k, v in s.items() if k not in ("extract", "match", "localise", "export",
                                                             "report"))
        rows.append(f"| {r['label']} | {r['kept']} | {r['models']} | {m.get('frames')}/"
                    f"{m.get('gt_frames')} | {fmt(s.get('extract'))} | {fmt(s.get('match'))} | "
                    f"{fmt(mapping)} | {fmt(s.get('localise'))} | {fmt(r.get('total_s'))} | "
                    f"{fmt(r['peak_mib'], 0)} | {fmt(m.get('ate_pct'), 4)} | "
                    f"{fmt(m.get('rot_deg'), 3)} | {fmt(m.get('gap_max'), 4)} |")
        for part in ("all", "localized"):
            if r.get(part):
                p = r[part]
                rows.append(f"| {r['label']}: {part} frames | | | {p['frames']}/{p['gt_frames']} "
                            f"| | | | | | | {fmt(p['ate_pct'], 4)} | {fmt(p['rot_deg'], 3)} | "
                            f"{fmt(p['gap_max'], 4)} |")
    return "\n".join(rows)


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("video", type=Path)
    parser.add_argument("groundtruth", type=Path)
    parser.add_argument("--workdir", type=Path, required=True)
    parser.add_argument("--loopsfm", type=Path,
                        default=Path(__file__).resolve().parents[2] / "build" / "loopsfm")
    parser.add_argument("--intrinsics", type=Path)
    parser.add_argument("--only", default=",".join(RUNS))
    parser.add_argument("--rounds", type=int, default=1)
    args = parser.parse_args(argv)
    for path in (args.video, args.groundtruth, args.loopsfm):
        if not path.exists():
            print(f"keyframes.py: {path} does not exist", file=sys.stderr)
            return 2
    wanted = [r for r in args.only.split(",") if r]
    unknown = [r for r in wanted if r not in RUNS]
    if unknown or args.rounds < 1:
        print(f"keyframes.py: unknown runs {unknown} (choose from {', '.join(RUNS)}) or rounds "
              f"< 1", file=sys.stderr)
        return 2
    runs = {name: [] for name in wanted}
    every_n = None
    for round_index in range(args.rounds):
        for name in wanted:
            if name == "everyN" and every_n is None:
                # The default's budget: as many frames as adaptive selection kept.
                kept = (runs.get("default") or [{}])[0].get("kept")
                if not kept:
                    log("everyN needs the default run first (its frame count); skipped")
                    continue
                frames_read = sum(1 for l in args.groundtruth.read_text().splitlines()
                                  if l.strip() and not l.startswith("#"))
                every_n = max(1, round(frames_read / kept))
            runs[name].append(one_run(args, name, every_n, round_index))
    results = {}
    for name, rs in runs.items():
        if not rs:
            continue
        results[name] = median_run(rs)
        results[name]["label"] = {"default": "default (adaptive)", "every1": "--every 1",
                                  "everyN": f"--every {every_n}",
                                  "allframes": "default --all-frames"}[name]
    (args.workdir / "keyframes.json").write_text(json.dumps(results, indent=2))
    print(table(results))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

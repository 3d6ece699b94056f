#!/usr/bin/env python3
"""loopsfm against COLMAP 3.8, side by side in one run, on the same input.

Four columns per set:
- loopsfm: `loopsfm reconstruct` at its defaults (pairing: vocabtree), the set's intrinsics;
- loopsfm global mapper on its DB: `loopsfm map --mapper global` on a copy of loopsfm's
  database (the same matches, the global mapper instead of the incremental one);
- COLMAP full: COLMAP's own pipeline at its defaults (feature_extractor, sequential matcher with
  quadratic overlap and vocabulary-tree loop detection, or exhaustive for templeRing; mapper);
- COLMAP mapper on loopsfm's DB: COLMAP's mapper, with the flags of the COLMAP column, on a copy
  of loopsfm's database, so that pairing problems show apart from mapper problems.

For each: models, frames in the largest model, trajectory error of the largest model (ATE RMSE,
ATE as % of the ground-truth path length, mean rotation error; all scored by `loopsfm eval`),
the camera the largest model ended with (focal length and k1 against the set's intrinsics.txt),
per-stage wall times, peak memory, pairs tried and verified, and the largest connected component
of the verified-pair graph. With --runs N every number is the median of N runs. Standard library
only; see README.md beside this file.
"""

import argparse
import json
import os
import shlex
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from vsc_camera import read_intrinsics_file  # noqa: E402
from vsc_sets import (ALL_SETS, DEFAULT_SETS, colmap_images, known_sets,  # noqa: E402
                      make_set)
from vsc_tools import (MIN_INLIERS, load_average, log, run_colmap,  # noqa: E402
                       run_colmap_on_loopsfm_db, run_loopsfm, run_loopsfm_global_on_db)

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_DATA = REPO_ROOT.parent / "shared" / "data"
DEFAULT_LOOPSFM = REPO_ROOT / "build" / "loopsfm"

# Result keys and column titles, in table order.
TOOLS = ["loopsfm", "loopsfm_global", "colmap", "colmap_on_loopsfm_db"]
TITLES = {"loopsfm": "loopsfm", "loopsfm_global": "loopsfm global mapper on its DB",
          "colmap": "COLMAP full", "colmap_on_loopsfm_db": "COLMAP mapper on loopsfm's DB"}

NUMERIC_KEYS = ["extraction_s", "matching_s", "mapping_s", "total_s", "vocab_tree_s", "peak_mib",
                "registered", "models", "gt_frames", "ate_rmse", "ate_pct", "rot_mean_deg",
                "pairs_tried", "pairs_verified", "component_largest", "components",
                "features_per_image", "db_images", "load_1min", "focal_est", "focal_true",
                "focal_err_pct", "k1_est", "k1_true", "k1_abs_err"]


# ----------------------------------------------------------------------------------------------
# One set, N runs, medians


def median_of(runs):
    """Median of each numeric field over the runs (None where no run has a value)."""
    merged = {}
    for key in NUMERIC_KEYS:
        values = [r.get(key) for r in runs if r.get(key) is not None]
        merged[key] = statistics.median(values) if values else None
    merged["failed_runs"] = sum(1 for r in runs if r.get("rc", 0) != 0)
    notes = sorted({r.get("eval_note", "") for r in runs} - {""})
    merged["eval_note"] = "; ".join(notes)
    merged["loop_detection"] = any(r.get("loop_detection") for r in runs) if runs else None
    models = sorted({r["camera_model"] for r in runs if r.get("camera_model")})
    merged["camera_model"] = ", ".join(models) or None
    return merged


def run_order(run_index, tools):
    """Tools of one run in the order they run. The first tool alternates from run to run, so a
    slow drift of the machine's load hits loopsfm and COLMAP alike; COLMAP's mapper on
    loopsfm's database always follows loopsfm, whose database it reads."""
    order = (["loopsfm", "loopsfm_global", "colmap_on_loopsfm_db", "colmap"]
             if run_index % 2 == 0
             else ["colmap", "loopsfm", "loopsfm_global", "colmap_on_loopsfm_db"])
    return [t for t in order if t in tools]


def bench_one_set(args, bench_set, workdir):
    set_dir = workdir / bench_set.name
    set_dir.mkdir(parents=True, exist_ok=True)
    image_dir, frame_extraction_s = colmap_images(args, bench_set, set_dir)
    runs = {tool: [] for tool in TOOLS}
    for r in range(args.runs):
        run_dir = set_dir / f"run{r}"
        loopsfm_result = None
        for tool in run_order(r, args.tools):
            if tool == "loopsfm":
                loopsfm_result = run_loopsfm(args, bench_set, run_dir)
                runs[tool].append(loopsfm_result)
            elif tool == "colmap":
                runs[tool].append(run_colmap(args, bench_set, image_dir, run_dir))
            elif tool == "loopsfm_global":
                runs[tool].append(run_loopsfm_global_on_db(args, bench_set, run_dir,
                                                           loopsfm_result))
            else:
                runs[tool].append(run_colmap_on_loopsfm_db(args, bench_set, image_dir, run_dir,
                                                           loopsfm_result))
    colmap_matcher = bench_set.colmap_matcher
    if not runs["colmap"]:
        colmap_matcher += " (not run)"
    elif colmap_matcher == "sequential":
        colmap_matcher += (" + loop detection" if median_of(runs["colmap"])["loop_detection"]
                           else " (no loop detection)")
    try:
        true_camera_model = read_intrinsics_file(bench_set.intrinsics)[0]
    except (OSError, ValueError):
        true_camera_model = None
    result = dict(bench_set.describe(), runs=args.runs, colmap_matcher=colmap_matcher,
                  true_camera_model=true_camera_model,
                  intrinsics_mode="estimated" if args.no_intrinsics else "given",
                  frame_extraction_s=frame_extraction_s, per_run=runs)
    for tool in TOOLS:
        result[tool] = median_of(runs[tool])
    return result


# ----------------------------------------------------------------------------------------------
# Output


def fmt_num(value, digits=1):
    if value is None:
        return "-"
    return f"{value:.{digits}f}"


def fmt_of(part, whole):
    """'part / whole' with whole numbers, '-' when part is missing."""
    if part is None:
        return "-"
    return f"{part:g} / {whole:g}" if whole is not None else f"{part:g}"


def fmt_focal(s):
    """'1523.1 (+0.2 %)': estimated focal length [px] and its signed error against the truth."""
    if s["focal_est"] is None:
        return "-"
    if s["focal_err_pct"] is None:
        return f"{s['focal_est']:.1f}"
    return f"{s['focal_est']:.1f} ({s['focal_err_pct']:+.1f} %)"


def fmt_k1(s):
    """'-0.0412 (0.0088)': estimated k1 and its absolute error against the truth."""
    if s["k1_est"] is None:
        return "-"
    if s["k1_abs_err"] is None:
        return f"{s['k1_est']:.4f}"
    return f"{s['k1_est']:.4f} ({s['k1_abs_err']:.4f})"


def fmt_truth(result):
    """The set's true camera for the caption: model, focal length, k1."""
    true = next((result[t] for t in TOOLS if result[t].get("focal_true") is not None), None)
    if true is None:
        return "true camera: unknown"
    text = (f"true camera: {result.get('true_camera_model') or '?'}, "
            f"focal {true['focal_true']:.1f} px")
    if true.get("k1_true") is not None:
        text += f", k1 {true['k1_true']:.4f}"
    return text


def table_rows():
    """(label, formatter of one column's medians) per row: first the comparison (models to
    largest connected component), then context."""
    return [
        ("models", lambda s: fmt_num(s["models"], 0)),
        ("frames in the largest model / ground-truth frames",
         lambda s: fmt_of(s["registered"], s["gt_frames"])),
        ("ATE [% of path length]", lambda s: fmt_num(s["ate_pct"], 3)),
        ("rotation error, mean [deg]", lambda s: fmt_num(s["rot_mean_deg"], 3)),
        ("camera model (largest model)", lambda s: s["camera_model"] or "-"),
        ("focal [px] (error %)", fmt_focal),
        ("k1 (abs. error)", fmt_k1),
        ("map [s]", lambda s: fmt_num(s["mapping_s"])),
        ("total [s]", lambda s: fmt_num(s["total_s"])),
        ("pairs tried", lambda s: fmt_num(s["pairs_tried"], 0)),
        ("pairs verified", lambda s: fmt_num(s["pairs_verified"], 0)),
        (f"largest connected component (verified, >= {MIN_INLIERS} inliers) / frames in DB",
         lambda s: fmt_of(s["component_largest"], s["db_images"])),
        ("ATE RMSE [gt units]", lambda s: fmt_num(s["ate_rmse"], 4)),
        ("feature extraction [s]", lambda s: fmt_num(s["extraction_s"])),
        ("matching [s]", lambda s: fmt_num(s["matching_s"])),
        ("COLMAP vocabulary tree training [s] (not in total)",
         lambda s: fmt_num(s["vocab_tree_s"])),
        ("peak memory [MiB]", lambda s: fmt_num(s["peak_mib"], 0)),
        ("features per image", lambda s: fmt_num(s["features_per_image"], 0)),
        ("load average at start (1 min)", lambda s: fmt_num(s["load_1min"], 2)),
    ]


def format_table(result, tools):
    """One markdown table: a row per measure, a column per tool."""
    runs = result["runs"]
    lines = [f"### {result['set']}", "",
             f"{result['origin']}; intrinsics {result['intrinsics_mode']}; COLMAP matcher: "
             f"{result['colmap_matcher']}; {'median of ' + str(runs) + ' runs' if runs > 1 else '1 run'}; "
             f"{fmt_truth(result)}.",
             ""]
    columns = [t for t in TOOLS if t in tools]
    lines.append("| | " + " | ".join(TITLES[t] for t in columns) + " |")
    lines.append("|---|" + "---:|" * len(columns))
    for label, cell in table_rows():
        lines.append(f"| {label} | " + " | ".join(cell(result[t]) for t in columns) + " |")
    lines.append("")
    if "colmap_on_loopsfm_db" in columns:
        lines.append("COLMAP mapper on loopsfm's DB: extraction and matching are loopsfm's (its "
                     "database); total = loopsfm's extraction + matching + COLMAP's mapper.")
    if "loopsfm_global" in columns:
        lines.append("loopsfm global mapper on its DB: `loopsfm map --mapper global` on loopsfm's "
                     "database; extraction and matching are loopsfm's.")
    if result["frame_extraction_s"] is not None:
        lines.append(f"Video to PNG frames for COLMAP (ffmpeg, in no total): "
                     f"{result['frame_extraction_s']:.1f} s.")
    for tool in columns:
        side = result[tool]
        if side["failed_runs"]:
            lines.append(f"{TITLES[tool]}: {side['failed_runs']} of {runs} runs failed "
                         f"(see the logs).")
        if side["eval_note"]:
            lines.append(f"{TITLES[tool]}: {side['eval_note']}.")
    return "\n".join(lines) + "\n"


def tool_versions(args):
    versions = {}
    try:
        head = subprocess.run([args.colmap, "-h"], capture_output=True, text=True).stdout
        versions["colmap"] = head.strip().splitlines()[0] if head.strip() else "?"
    except OSError:
        versions["colmap"] = None
    try:
        commit = subprocess.run(["git", "-C", str(REPO_ROOT), "rev-parse", "--short", "HEAD"],
                                capture_output=True, text=True).stdout.strip()
        versions["loopsfm_commit"] = commit or None
    except OSError:
        versions["loopsfm_commit"] = None
    stat = args.loopsfm.stat()
    versions["loopsfm_binary"] = {"path": str(args.loopsfm), "size": stat.st_size,
                                  "modified": time.strftime("%Y-%m-%d %H:%M:%S",
                                                            time.localtime(stat.st_mtime))}
    return versions


# ----------------------------------------------------------------------------------------------


def parse_args(argv):
    parser = argparse.ArgumentParser(
        description="loopsfm against COLMAP 3.8 (CPU) on the same input, side by side.")
    parser.add_argument("--sets", default=",".join(DEFAULT_SETS),
                        help=f"comma-separated sets, from {', '.join(ALL_SETS)} (and "
                             f"--synth-set names), or 'all' (default: {','.join(DEFAULT_SETS)})")
    parser.add_argument("--runs", type=int, default=1,
                        help="runs per set and tool; the table shows medians (default 1)")
    parser.add_argument("--threads", type=int, default=0,
                        help="threads for both tools (default 0: all cores)")
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/loopsfm_vs_colmap"),
                        help="scratch folder for databases, models, frames and logs "
                             "(default /tmp/loopsfm_vs_colmap)")
    parser.add_argument("--json", type=Path, metavar="FILE",
                        help="also write all results (medians and every run) as JSON to FILE")
    parser.add_argument("--markdown", type=Path, metavar="FILE",
                        help="also write the tables to FILE")
    parser.add_argument("--tools", default=",".join(TOOLS),
                        help=f"columns to run, from {','.join(TOOLS)} (default: all four; "
                             f"loopsfm_global and colmap_on_loopsfm_db need loopsfm)")
    parser.add_argument("--no-intrinsics", action="store_true",
                        help="uncalibrated: loopsfm without --intrinsics, COLMAP with its "
                             "SIMPLE_RADIAL camera and focal/distortion refined by its mapper")
    parser.add_argument("--loopsfm-args", default="",
                        help="extra flags for `loopsfm reconstruct`, e.g. '--pairs sequential'")
    parser.add_argument("--colmap-matcher", choices=["set", "exhaustive", "sequential"],
                        default="set", help="COLMAP's matcher (default: the set's, see README)")
    parser.add_argument("--no-colmap-loop-detection", dest="colmap_loop_detection",
                        action="store_false",
                        help="COLMAP's sequential matcher without loop detection (no tree)")
    parser.add_argument("--colmap-vocab-words", type=int, default=4096,
                        help="COLMAP vocabulary tree: visual words (default 4096)")
    parser.add_argument("--colmap-vocab-branching", type=int, default=64,
                        help="COLMAP vocabulary tree: branching factor (default 64)")
    parser.add_argument("--colmap-vocab-images", type=int, default=100,
                        help="COLMAP vocabulary tree: trained on the descriptors of at most this "
                             "many images, a random subset (default 100; -1: all)")
    parser.add_argument("--synth-set", action="append", default=[], metavar="NAME=ARGS",
                        help="add (or replace) a synthetic set: NAME rendered by "
                             "`loopsfm synth ARGS`, e.g. 'turns=street --frames 300 "
                             "--look-ahead 25 --abrupt-turns' (repeatable)")
    parser.add_argument("--timeout", type=float, default=None,
                        help="kill any one process after this many seconds")
    parser.add_argument("--data", type=Path,
                        default=Path(os.environ.get("LOOPSFM_DATA", DEFAULT_DATA)),
                        help=f"shared data folder (default $LOOPSFM_DATA or {DEFAULT_DATA})")
    parser.add_argument("--loopsfm", type=Path, default=DEFAULT_LOOPSFM,
                        help=f"loopsfm binary (default {DEFAULT_LOOPSFM})")
    parser.add_argument("--colmap", default="colmap", help="COLMAP binary (default colmap)")
    parser.add_argument("--ffmpeg", default="ffmpeg", help="ffmpeg binary (default ffmpeg)")
    args = parser.parse_args(argv)
    for entry in args.synth_set:
        if "=" not in entry or not entry.split("=", 1)[0].strip():
            parser.error(f"--synth-set takes NAME=ARGS, not '{entry}'")
    known = known_sets(args)
    args.sets = known if args.sets == "all" else [s for s in args.sets.split(",") if s]
    for name in args.sets:
        if name not in known:
            parser.error(f"unknown set '{name}' (known: {', '.join(known)})")
    args.tools = [t for t in args.tools.split(",") if t]
    if not args.tools or any(t not in TOOLS for t in args.tools):
        parser.error(f"--tools takes a comma-separated list from {','.join(TOOLS)}")
    for tool in ("loopsfm_global", "colmap_on_loopsfm_db"):
        if tool in args.tools and "loopsfm" not in args.tools:
            parser.error(f"{tool} maps loopsfm's database: add loopsfm to --tools")
    if args.runs < 1:
        parser.error("--runs must be at least 1")
    if args.threads < 0:
        parser.error("--threads must be 0 (all cores) or more")
    args.loopsfm_args = shlex.split(args.loopsfm_args)
    if not args.loopsfm.exists():
        parser.error(f"{args.loopsfm} not found: build it (cmake --build build --target loopsfm) "
                     f"or pass --loopsfm")
    for tool in (args.colmap, args.ffmpeg):
        if shutil.which(tool) is None:
            parser.error(f"'{tool}' is not on PATH")
    args.loopsfm = args.loopsfm.resolve()
    return args


def main(argv):
    args = parse_args(argv)
    workdir = args.workdir.resolve()
    workdir.mkdir(parents=True, exist_ok=True)
    report = {"machine": {"cpus": os.cpu_count(), "load_1min_at_start": load_average()},
              "versions": tool_versions(args), "threads": args.threads or "all",
              "runs": args.runs, "intrinsics": "estimated" if args.no_intrinsics else "given",
              "loopsfm_args": args.loopsfm_args, "colmap_vocab_tree": {
                  "num_visual_words": args.colmap_vocab_words,
                  "branching": args.colmap_vocab_branching,
                  "max_num_images": args.colmap_vocab_images,
                  "loop_detection": args.colmap_loop_detection},
              "min_inliers_for_components": MIN_INLIERS, "sets": []}
    tables = []
    for name in args.sets:
        try:
            bench_set, reason = make_set(name, args, workdir)
        except (RuntimeError, OSError, ValueError) as error:
            bench_set, reason = None, str(error)
        if bench_set is None:
            log(f"{name}: skipped: {reason}")
            report["sets"].append({"set": name, "skipped": reason})
            tables.append(f"### {name}\n\nskipped: {reason}\n")
            continue
        try:
            result = bench_one_set(args, bench_set, workdir)
        except (RuntimeError, OSError, ValueError) as error:
            log(f"{name}: failed: {error}")
            report["sets"].append({"set": name, "failed": str(error)})
            tables.append(f"### {name}\n\nfailed: {error}\n")
            continue
        report["sets"].append(result)
        tables.append(format_table(result, args.tools))
        print(tables[-1], flush=True)
        if args.json:  # after every set, so a long run's finished sets are kept
            args.json.write_text(json.dumps(report, indent=2) + "\n")
    footer = (f"Machine: {os.cpu_count()} CPUs, threads: {args.threads or 'all'}, "
              f"{report['versions'].get('colmap')}, loopsfm "
              f"{report['versions'].get('loopsfm_commit')}; times are wall-clock seconds of "
              f"each process; work folder {workdir}.")
    print(footer)
    if args.markdown:
        args.markdown.write_text("\n".join(tables) + "\n" + footer + "\n")
        log(f"tables written to {args.markdown}")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n")
        log(f"results written to {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

#!/usr/bin/env python3
"""loopsfm against COLMAP 3.8, side by side in one run, on the same input.

Both tools get the same frames, the same fixed intrinsics and the same kind of pairing
(exhaustive, or sequential with the same overlap). For each set the script reports per-stage
wall times (feature extraction, matching, mapping, total), peak resident memory, frames
registered, and the trajectory error of the largest model (ATE RMSE, ATE as % of the
ground-truth path length, mean rotation error), scored for both tools by the same
`loopsfm eval` (which reads COLMAP binary models). With --runs N every number is the median
of N runs. Standard library only; see README.md beside this file.
"""

import argparse
import json
import os
import re
import shutil
import sqlite3
import statistics
import struct
import subprocess
import sys
import time
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_DATA = REPO_ROOT.parent / "shared" / "data"
DEFAULT_LOOPSFM = REPO_ROOT / "build" / "loopsfm"
ALL_SETS = ["templeRing", "kitti07_160", "cylinder", "block"]
DEFAULT_SETS = ["templeRing", "kitti07_160", "cylinder"]


# ----------------------------------------------------------------------------------------------
# Sets


class BenchSet:
    """One input: images folder or video, intrinsics, ground truth, pairing."""

    def __init__(self, name, source, intrinsics, groundtruth, pairs, overlap, is_video):
        self.name = name
        self.source = source  # folder of images, or a video file
        self.intrinsics = intrinsics
        self.groundtruth = groundtruth
        self.pairs = pairs  # "exhaustive" | "sequential"
        self.overlap = overlap
        self.is_video = is_video


def make_set(name, args, workdir):
    """Returns (BenchSet, None), or (None, reason) when the set cannot be run here."""
    overlap = args.overlap
    if name == "templeRing":
        root = args.data / "templeRing"
        bench_set = BenchSet(name, root / "images", root / "intrinsics.txt",
                             root / "groundtruth.txt", "exhaustive", overlap, False)
    elif name == "kitti07_160":
        root = args.data / "kitti07_160"
        bench_set = BenchSet(name, root / "images", root / "intrinsics.txt",
                             root / "groundtruth.txt", "sequential", overlap, False)
    elif name == "block":
        root = args.data / "block"
        bench_set = BenchSet(name, root / "block.mp4", root / "intrinsics.txt",
                             root / "groundtruth.txt", "sequential", overlap, True)
    elif name == "cylinder":
        synth_dir = workdir / "cylinder" / "synth"
        render_cylinder(args, synth_dir)
        bench_set = BenchSet(name, synth_dir / "video.mp4", synth_dir / "intrinsics.txt",
                             synth_dir / "groundtruth.txt", "sequential", overlap, True)
    else:
        return None, f"unknown set '{name}' (known: {', '.join(ALL_SETS)})"
    if args.pairs:
        bench_set.pairs = args.pairs
    for path in (bench_set.source, bench_set.intrinsics, bench_set.groundtruth):
        if not path.exists():
            return None, f"{path} is missing (shared data not here? pass --data DIR)"
    return bench_set, None


def render_cylinder(args, synth_dir):
    """Renders the synthetic cylinder video once per workdir and frame count (not timed)."""
    stamp = synth_dir / "frames.txt"
    if stamp.exists() and stamp.read_text().strip() == str(args.cylinder_frames):
        return
    shutil.rmtree(synth_dir, ignore_errors=True)
    synth_dir.parent.mkdir(parents=True, exist_ok=True)
    log(f"cylinder: rendering {args.cylinder_frames} frames to {synth_dir} (not timed)")
    cmd = [str(args.loopsfm), "synth", "cylinder", "--video", "--frames",
           str(args.cylinder_frames), "-o", str(synth_dir)]
    with open(synth_dir.parent / "synth.log", "w") as out:
        subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, check=True)
    stamp.write_text(f"{args.cylinder_frames}\n")


def read_intrinsics(path):
    """Returns (model, [params]) from 'PINHOLE w h fx fy cx cy' or 'OPENCV w h fx fy cx cy k1..p2'."""
    for line in path.read_text().splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.replace(",", " ").split()
        model, values = fields[0].upper(), fields[3:]
        expected = {"PINHOLE": 4, "OPENCV": 8}.get(model)
        if expected is None or len(values) != expected:
            raise ValueError(f"{path}: cannot read camera line '{line}'")
        return model, values
    raise ValueError(f"{path}: no camera line")


# ----------------------------------------------------------------------------------------------
# Measuring one process


def run_measured(cmd, log_path, timeout=None):
    """Runs cmd with stdout and stderr to log_path; returns wall time, peak RSS and exit code.

    The peak is the child's ru_maxrss from wait4(), the number `/usr/bin/time -v` prints as
    "Maximum resident set size", measured per process.
    """
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    with open(log_path, "w") as out:
        out.write("$ " + " ".join(cmd) + "\n")
        out.flush()
        start = time.monotonic()
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env)
        deadline = None if timeout is None else start + timeout
        status, rusage = 0, None
        while True:
            pid, status, rusage = os.wait4(proc.pid, os.WNOHANG if deadline else 0)
            if pid == proc.pid:
                break
            if deadline and time.monotonic() > deadline:
                proc.kill()
                pid, status, rusage = os.wait4(proc.pid, 0)
                status = -1
                break
            time.sleep(0.05)
        wall = time.monotonic() - start
    proc.returncode = os.waitstatus_to_exitcode(status) if status != -1 else -9
    return {"wall_s": wall, "peak_mib": rusage.ru_maxrss / 1024.0, "rc": proc.returncode,
            "timed_out": status == -1, "log": str(log_path)}


def load_average():
    try:
        return os.getloadavg()[0]
    except OSError:
        return None


# ----------------------------------------------------------------------------------------------
# Reading results


def num_registered_images(model_dir):
    images_bin = model_dir / "images.bin"
    if images_bin.exists():
        with open(images_bin, "rb") as f:
            data = f.read(8)
        return struct.unpack("<Q", data)[0] if len(data) == 8 else 0
    images_txt = model_dir / "images.txt"
    if images_txt.exists():
        lines = [l for l in images_txt.read_text().splitlines() if l and not l.startswith("#")]
        return len(lines) // 2
    return 0


def largest_model(sparse_dir):
    """Returns (path of the model with the most registered images or None, number of models)."""
    if not sparse_dir.is_dir():
        return None, 0
    models = [(num_registered_images(d), d) for d in sorted(sparse_dir.iterdir()) if d.is_dir()]
    models = [(n, d) for n, d in models if n > 0]
    if not models:
        return None, 0
    return max(models, key=lambda m: m[0])[1], len(models)


def database_stats(db_path):
    """Images, mean features per image, pairs matched and pairs verified, from a COLMAP database."""
    stats = {"db_images": None, "features_per_image": None, "pairs_matched": None,
             "pairs_verified": None}
    if not db_path.exists():
        return stats
    conn = sqlite3.connect(f"file:{db_path}?mode=ro", uri=True)
    try:
        num_images, num_keypoints = conn.execute(
            "SELECT COUNT(*), SUM(rows) FROM keypoints").fetchone()
        stats["db_images"] = num_images
        if num_images:
            stats["features_per_image"] = (num_keypoints or 0) / num_images
        stats["pairs_matched"] = conn.execute("SELECT COUNT(*) FROM matches").fetchone()[0]
        stats["pairs_verified"] = conn.execute(
            "SELECT COUNT(*) FROM two_view_geometries WHERE rows > 0").fetchone()[0]
    except sqlite3.Error as error:
        log(f"warning: cannot read {db_path}: {error}")
    finally:
        conn.close()
    return stats


def evaluate(args, sparse_dir, groundtruth, log_path):
    """Scores the largest model in sparse_dir with `loopsfm eval --json`."""
    result = {"registered": 0, "models": 0, "gt_frames": None, "ate_rmse": None,
              "ate_pct": None, "rot_mean_deg": None, "eval_note": ""}
    gt_frames = sum(1 for l in groundtruth.read_text().splitlines()
                    if l.strip() and not l.startswith("#"))
    result["gt_frames"] = gt_frames
    model, num_models = largest_model(sparse_dir)
    result["models"] = num_models
    if model is None:
        result["eval_note"] = "no model"
        return result
    proc = subprocess.run([str(args.loopsfm), "eval", str(model), str(groundtruth), "--json"],
                          capture_output=True, text=True)
    log_path.write_text(proc.stdout + proc.stderr)
    if proc.returncode != 0:
        result["eval_note"] = f"eval failed (rc {proc.returncode}), see {log_path}"
        return result
    metrics = json.loads(proc.stdout)
    result["model"] = str(model)
    result["registered"] = metrics["num_matched"]
    result["gt_frames"] = metrics["num_gt_frames"]
    if metrics.get("aligned"):
        result["ate_rmse"] = metrics["ate_rmse"]
        result["ate_pct"] = 100.0 * metrics["ate_fraction_of_path"]
        result["rot_mean_deg"] = metrics["rotation_error_mean_deg"]
    else:
        result["eval_note"] = "not aligned: " + metrics.get("explanation", "")
    return result


# ----------------------------------------------------------------------------------------------
# The two tools


LOOPSFM_TIME = re.compile(r"^time (\S+)\s+([0-9.]+) s", re.M)
LOOPSFM_TOTAL = re.compile(r"^total\s+([0-9.]+) s, peak memory ([0-9.]+) MiB", re.M)


def run_loopsfm(args, bench_set, run_dir):
    out_dir = run_dir / "loopsfm"
    shutil.rmtree(out_dir, ignore_errors=True)  # loopsfm resumes from what OUT holds
    out_dir.mkdir(parents=True)
    cmd = [str(args.loopsfm)]
    if args.threads:
        cmd += ["--threads", str(args.threads)]
    cmd += ["reconstruct", str(bench_set.source), "-o", str(out_dir / "out"),
            "--intrinsics", str(bench_set.intrinsics), "--pairs", bench_set.pairs]
    if bench_set.pairs == "sequential":
        cmd += ["--overlap", str(bench_set.overlap)]
    load = load_average()
    log(f"{bench_set.name}: loopsfm reconstruct ...")
    proc = run_measured(cmd, out_dir / "reconstruct.log", args.timeout)
    result = {"load_1min": load, "rc": proc["rc"], "peak_mib": proc["peak_mib"],
              "total_s": proc["wall_s"], "extraction_s": None, "matching_s": None,
              "mapping_s": None, "stage_times": {}}
    text = Path(proc["log"]).read_text()
    stage_times = {name: float(s) for name, s in LOOPSFM_TIME.findall(text)}
    result["stage_times"] = stage_times
    if stage_times:
        result["extraction_s"] = stage_times.get("extract")
        result["matching_s"] = stage_times.get("match")
        # Everything after matching: tracks, incremental mapping, export. COLMAP's mapper
        # also builds its correspondence graph and writes the model inside its own wall time.
        result["mapping_s"] = sum(t for name, t in stage_times.items()
                                  if name not in ("extract", "match"))
    total = LOOPSFM_TOTAL.search(text)
    if total:
        result["reported_total_s"] = float(total.group(1))
        result["reported_peak_mib"] = float(total.group(2))
    if proc["rc"] != 0:
        log(f"{bench_set.name}: loopsfm failed (rc {proc['rc']}), see {proc['log']}")
    result.update(database_stats(out_dir / "out" / "database.db"))
    result.update(evaluate(args, out_dir / "out" / "sparse", bench_set.groundtruth,
                           out_dir / "eval.json"))
    log(f"{bench_set.name}: loopsfm {result['total_s']:.1f} s, "
        f"{result['registered']}/{result['gt_frames']} registered")
    return result


def extract_video_frames(args, bench_set, set_dir):
    """Decodes the video to PNG frames for COLMAP; returns the wall time (reported apart)."""
    frames_dir = set_dir / "frames"
    shutil.rmtree(frames_dir, ignore_errors=True)
    frames_dir.mkdir(parents=True)
    cmd = [args.ffmpeg, "-nostdin", "-loglevel", "error", "-i", str(bench_set.source),
           "-start_number", "0", str(frames_dir / "frame_%06d.png")]
    log(f"{bench_set.name}: ffmpeg frames for COLMAP ...")
    proc = run_measured(cmd, set_dir / "ffmpeg.log", args.timeout)
    if proc["rc"] != 0:
        raise RuntimeError(f"ffmpeg failed (rc {proc['rc']}), see {proc['log']}")
    return frames_dir, proc["wall_s"], len(list(frames_dir.glob("*.png")))


def run_colmap(args, bench_set, image_dir, run_dir):
    out_dir = run_dir / "colmap"
    shutil.rmtree(out_dir, ignore_errors=True)
    (out_dir / "sparse").mkdir(parents=True)
    db = out_dir / "database.db"
    model, params = read_intrinsics(bench_set.intrinsics)
    threads = str(args.threads) if args.threads else "-1"
    colmap = args.colmap
    extract = [colmap, "feature_extractor", "--database_path", str(db),
               "--image_path", str(image_dir), "--ImageReader.single_camera", "1",
               "--ImageReader.camera_model", model,
               "--ImageReader.camera_params", ",".join(params),
               "--SiftExtraction.use_gpu", "0", "--SiftExtraction.num_threads", threads]
    if bench_set.pairs == "exhaustive":
        match = [colmap, "exhaustive_matcher"]
    else:
        # Plain window of `overlap` following frames, as loopsfm's sequential pairing. COLMAP
        # 3.8 pairs image i with i + 0 .. i + overlap - 1 (the self pair is dropped), so it
        # needs overlap + 1 for `overlap` following frames; its default also adds i + 2^k
        # pairs, which loopsfm does not.
        match = [colmap, "sequential_matcher", "--SequentialMatching.overlap",
                 str(bench_set.overlap + 1), "--SequentialMatching.quadratic_overlap", "0"]
    match += ["--database_path", str(db), "--SiftMatching.use_gpu", "0",
              "--SiftMatching.num_threads", threads]
    mapper = [colmap, "mapper", "--database_path", str(db), "--image_path", str(image_dir),
              "--output_path", str(out_dir / "sparse"),
              # Intrinsics are given and stay fixed, as in loopsfm.
              "--Mapper.ba_refine_focal_length", "0", "--Mapper.ba_refine_principal_point", "0",
              "--Mapper.ba_refine_extra_params", "0", "--Mapper.num_threads", threads]
    result = {"load_1min": load_average(), "rc": 0, "stage_peak_mib": {}}
    for key, stage, cmd in (("extraction_s", "feature_extractor", extract),
                            ("matching_s", "matcher", match), ("mapping_s", "mapper", mapper)):
        log(f"{bench_set.name}: colmap {stage} ...")
        proc = run_measured(cmd, out_dir / f"{stage}.log", args.timeout)
        result[key] = proc["wall_s"]
        result["stage_peak_mib"][stage] = proc["peak_mib"]
        if proc["rc"] != 0:
            result["rc"] = proc["rc"]
            log(f"{bench_set.name}: colmap {stage} failed (rc {proc['rc']}), see {proc['log']}")
            break
    stage_s = [result.get(k) for k in ("extraction_s", "matching_s", "mapping_s")]
    result["total_s"] = sum(s for s in stage_s if s is not None)
    result["peak_mib"] = max(result["stage_peak_mib"].values())
    result.update(database_stats(db))
    result.update(evaluate(args, out_dir / "sparse", bench_set.groundtruth, out_dir / "eval.json"))
    log(f"{bench_set.name}: colmap {result['total_s']:.1f} s, "
        f"{result['registered']}/{result['gt_frames']} registered")
    return result


# ----------------------------------------------------------------------------------------------
# One set, N runs, medians


NUMERIC_KEYS = ["extraction_s", "matching_s", "mapping_s", "total_s", "peak_mib", "registered",
                "models", "gt_frames", "ate_rmse", "ate_pct", "rot_mean_deg", "pairs_matched",
                "pairs_verified", "features_per_image", "db_images", "load_1min"]


def median_of(runs):
    """Median of each numeric field over the runs (None where no run has a value)."""
    merged = {}
    for key in NUMERIC_KEYS:
        values = [r.get(key) for r in runs if r.get(key) is not None]
        merged[key] = statistics.median(values) if values else None
    merged["failed_runs"] = sum(1 for r in runs if r.get("rc", 0) != 0)
    notes = sorted({r.get("eval_note", "") for r in runs} - {""})
    merged["eval_note"] = "; ".join(notes)
    return merged


def bench_one_set(args, bench_set, workdir):
    set_dir = workdir / bench_set.name
    set_dir.mkdir(parents=True, exist_ok=True)
    frame_extraction_s, image_dir = None, bench_set.source
    if bench_set.is_video:
        image_dir, frame_extraction_s, num_frames = extract_video_frames(args, bench_set, set_dir)
        log(f"{bench_set.name}: {num_frames} frames in {frame_extraction_s:.1f} s")
    runs = {"loopsfm": [], "colmap": []}
    for r in range(args.runs):
        run_dir = set_dir / f"run{r}"
        # Alternate which tool goes first, so slow drift of the machine load hits both alike.
        order = ["loopsfm", "colmap"] if r % 2 == 0 else ["colmap", "loopsfm"]
        for tool in order:
            if tool not in args.tools:
                continue
            if tool == "loopsfm":
                runs["loopsfm"].append(run_loopsfm(args, bench_set, run_dir))
            else:
                runs["colmap"].append(run_colmap(args, bench_set, image_dir, run_dir))
    return {
        "set": bench_set.name,
        "input": str(bench_set.source),
        "pairs": bench_set.pairs,
        "overlap": bench_set.overlap if bench_set.pairs == "sequential" else None,
        "runs": args.runs,
        "frame_extraction_s": frame_extraction_s,
        "loopsfm": median_of(runs["loopsfm"]),
        "colmap": median_of(runs["colmap"]),
        "per_run": runs,
    }


# ----------------------------------------------------------------------------------------------
# Output


def fmt_num(value, digits=1):
    if value is None:
        return "-"
    return f"{value:.{digits}f}"


def fmt_ratio(colmap, loopsfm):
    if colmap is None or loopsfm is None or loopsfm <= 0:
        return "-"
    return f"{colmap / loopsfm:.2f}x"


def format_table(result):
    lo, co = result["loopsfm"], result["colmap"]
    pairing = result["pairs"] + (f", overlap {result['overlap']}" if result["overlap"] else "")
    runs = result["runs"]
    title = (f"{result['set']}: {pairing}; "
             f"{'median of ' + str(runs) + ' runs' if runs > 1 else '1 run'}")
    rows = [("", "loopsfm", "COLMAP", "COLMAP/loopsfm")]
    for label, key in (("feature extraction [s]", "extraction_s"), ("matching [s]", "matching_s"),
                       ("mapping [s]", "mapping_s"), ("total [s]", "total_s")):
        rows.append((label, fmt_num(lo[key]), fmt_num(co[key]), fmt_ratio(co[key], lo[key])))
    rows.append(("peak memory [MiB]", fmt_num(lo["peak_mib"], 0), fmt_num(co["peak_mib"], 0),
                 fmt_ratio(co["peak_mib"], lo["peak_mib"])))

    def registered(side):
        if side["gt_frames"] is None:
            return "-"
        reg = "-" if side["registered"] is None else f"{side['registered']:g}"
        return f"{reg} / {side['gt_frames']:g}"

    rows.append(("frames registered (largest model)", registered(lo), registered(co), ""))
    rows.append(("models", fmt_num(lo["models"], 0), fmt_num(co["models"], 0), ""))
    rows.append(("ATE RMSE [gt units]", fmt_num(lo["ate_rmse"], 4), fmt_num(co["ate_rmse"], 4),
                 ""))
    rows.append(("ATE [% of path length]", fmt_num(lo["ate_pct"], 3), fmt_num(co["ate_pct"], 3),
                 ""))
    rows.append(("rotation error, mean [deg]", fmt_num(lo["rot_mean_deg"], 3),
                 fmt_num(co["rot_mean_deg"], 3), ""))
    rows.append(("pairs matched / verified",
                 f"{fmt_num(lo['pairs_matched'], 0)} / {fmt_num(lo['pairs_verified'], 0)}",
                 f"{fmt_num(co['pairs_matched'], 0)} / {fmt_num(co['pairs_verified'], 0)}", ""))
    rows.append(("features per image", fmt_num(lo["features_per_image"], 0),
                 fmt_num(co["features_per_image"], 0), ""))
    rows.append(("load average at start (1 min)", fmt_num(lo["load_1min"], 2),
                 fmt_num(co["load_1min"], 2), ""))
    widths = [max(len(row[i]) for row in rows) for i in range(4)]
    lines = [title]
    for row in rows:
        lines.append(f"  {row[0]:<{widths[0]}}  {row[1]:>{widths[1]}}  {row[2]:>{widths[2]}}  "
                     f"{row[3]:>{widths[3]}}".rstrip())
    if result["frame_extraction_s"] is not None:
        lines.append(f"  video to PNG frames for COLMAP (ffmpeg, not in COLMAP's total): "
                     f"{result['frame_extraction_s']:.1f} s")
    for name, side in (("loopsfm", lo), ("COLMAP", co)):
        if side["failed_runs"]:
            lines.append(f"  {name}: {side['failed_runs']} of {runs} runs failed (see logs)")
        if side["eval_note"]:
            lines.append(f"  {name}: {side['eval_note']}")
    return "\n".join(lines)


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
    return versions


def log(message):
    print(f"[vs_colmap {time.strftime('%H:%M:%S')}] {message}", file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------------------------


def parse_args(argv):
    parser = argparse.ArgumentParser(
        description="loopsfm against COLMAP 3.8 (CPU) on the same input, side by side.")
    parser.add_argument("--sets", default=",".join(DEFAULT_SETS),
                        help=f"comma-separated sets, from {', '.join(ALL_SETS)}, or 'all' "
                             f"(default: {','.join(DEFAULT_SETS)})")
    parser.add_argument("--runs", type=int, default=1,
                        help="runs per set and tool; the table shows medians (default 1)")
    parser.add_argument("--threads", type=int, default=0,
                        help="threads for both tools (default 0: all cores)")
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/loopsfm_vs_colmap"),
                        help="scratch folder for databases, models, frames and logs "
                             "(default /tmp/loopsfm_vs_colmap)")
    parser.add_argument("--json", type=Path, metavar="FILE",
                        help="also write all results (medians and every run) as JSON to FILE")
    parser.add_argument("--tools", default="loopsfm,colmap",
                        help="which tools to run (default loopsfm,colmap)")
    parser.add_argument("--pairs", choices=["exhaustive", "sequential"],
                        help="override every set's pairing")
    parser.add_argument("--overlap", type=int, default=10,
                        help="sequential pairing: frames matched after each frame (default 10)")
    parser.add_argument("--cylinder-frames", type=int, default=150,
                        help="frames of the synthetic cylinder video (default 150)")
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
    args.sets = ALL_SETS if args.sets == "all" else [s for s in args.sets.split(",") if s]
    args.tools = [t for t in args.tools.split(",") if t]
    if not args.tools or any(t not in ("loopsfm", "colmap") for t in args.tools):
        parser.error("--tools takes loopsfm, colmap or loopsfm,colmap")
    if args.runs < 1:
        parser.error("--runs must be at least 1")
    if args.threads < 0:
        parser.error("--threads must be 0 (all cores) or more")
    if args.overlap < 1:
        parser.error("--overlap must be at least 1")
    for name in args.sets:
        if name not in ALL_SETS:
            parser.error(f"unknown set '{name}' (known: {', '.join(ALL_SETS)})")
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
              "runs": args.runs, "sets": []}
    tables = []
    for name in args.sets:
        try:
            bench_set, reason = make_set(name, args, workdir)
        except (subprocess.CalledProcessError, OSError, ValueError) as error:
            bench_set, reason = None, str(error)
        if bench_set is None:
            log(f"{name}: skipped: {reason}")
            report["sets"].append({"set": name, "skipped": reason})
            tables.append(f"{name}: skipped: {reason}")
            continue
        try:
            result = bench_one_set(args, bench_set, workdir)
        except (RuntimeError, OSError, ValueError) as error:
            log(f"{name}: failed: {error}")
            report["sets"].append({"set": name, "failed": str(error)})
            tables.append(f"{name}: failed: {error}")
            continue
        report["sets"].append(result)
        tables.append(format_table(result))
        print(tables[-1] + "\n", flush=True)
    print(f"machine: {os.cpu_count()} CPUs, threads: {args.threads or 'all'}, "
          f"{report['versions'].get('colmap')}, loopsfm {report['versions'].get('loopsfm_commit')}; "
          f"times are wall-clock seconds of each process (COLMAP: sum of its three commands); "
          f"work folder {workdir}")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n")
        log(f"results written to {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

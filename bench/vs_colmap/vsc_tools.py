"""Running and reading the three columns of vs_colmap.py: loopsfm, COLMAP's whole pipeline, and
COLMAP's mapper on loopsfm's database. Standard library only; see README.md beside this file."""

import json
import math
import os
import re
import shutil
import sqlite3
import struct
import subprocess
import sys
import time
from pathlib import Path

from vsc_camera import camera_vs_truth, read_intrinsics_file

# COLMAP's pair ids: pair_id = image_id1 * PAIR_ID_BASE + image_id2 with image_id1 < image_id2.
PAIR_ID_BASE = 2147483647
# Fewest inliers for a verified pair to join frames in the view graph (both tools' minimum,
# loopsfm's --min-inliers and COLMAP's SiftMatching.min_num_inliers).
MIN_INLIERS = 15
# two_view_geometries.config values that mean "not verified": UNDEFINED and DEGENERATE.
UNVERIFIED_CONFIGS = (0, 1)


def log(message):
    print(f"[vs_colmap {time.strftime('%H:%M:%S')}] {message}", file=sys.stderr, flush=True)


def load_average():
    try:
        return os.getloadavg()[0]
    except OSError:
        return None


# ----------------------------------------------------------------------------------------------
# Measuring one process


def run_measured(cmd, log_path, timeout=None):
    """Runs cmd with stdout and stderr to log_path; returns wall time, peak RSS and exit code.

    The peak is the child's ru_maxrss from wait4(), the number `/usr/bin/time -v` prints as
    "Maximum resident set size", measured per process.
    """
    cmd = [str(c) for c in cmd]
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    with open(log_path, "w") as out:
        out.write("$ " + " ".join(cmd) + "\n")
        out.flush()
        start = time.monotonic()
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env)
        deadline = None if timeout is None else start + timeout
        timed_out = False
        while True:
            pid, status, rusage = os.wait4(proc.pid, os.WNOHANG if deadline else 0)
            if pid == proc.pid:
                break
            if deadline is not None and time.monotonic() > deadline:
                proc.kill()
                pid, status, rusage = os.wait4(proc.pid, 0)
                timed_out = True
                break
            time.sleep(0.05)
        wall = time.monotonic() - start
    proc.returncode = -9 if timed_out else os.waitstatus_to_exitcode(status)
    return {"wall_s": wall, "peak_mib": rusage.ru_maxrss / 1024.0, "rc": proc.returncode,
            "timed_out": timed_out, "log": str(log_path)}


# ----------------------------------------------------------------------------------------------
# Models and scoring


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


def num_models(sparse_dir):
    """Model folders under sparse_dir (0 when it does not exist)."""
    return sum(1 for p in sparse_dir.iterdir() if p.is_dir()) if sparse_dir.is_dir() else 0


def eval_trajectory(loopsfm, estimate, groundtruth):
    """`loopsfm eval --json` of a model folder or trajectory file, as frames scored, ATE (% of
    the path), mean rotation error and largest loop gap; None when it fails."""
    proc = subprocess.run([str(loopsfm), "eval", str(estimate), str(groundtruth), "--json"],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        log(f"eval of {estimate} failed: {proc.stderr.strip()}")
        return None
    m = json.loads(proc.stdout)
    gaps = m.get("loop_gaps") or {}
    return {"frames": m["num_matched"], "gt_frames": m["num_gt_frames"],
            "ate_pct": 100.0 * m["ate_fraction_of_path"] if m.get("aligned") else None,
            "rot_deg": m.get("rotation_error_mean_deg"),
            "gap_max": gaps.get("max") if gaps.get("num_revisits") else None}


def fit_exponent(xs, ys):
    """k of y ~ x^k: least-squares slope of log y against log x; None with fewer than two
    usable points."""
    pts = [(math.log(x), math.log(y)) for x, y in zip(xs, ys) if x and y and x > 0 and y > 0]
    if len(pts) < 2:
        return None
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    return sum((p[0] - mx) * (p[1] - my) for p in pts) / sxx if sxx > 0 else None


def fmt(value, digits=1):
    """A number for a Markdown table; "-" for None."""
    return "-" if value is None else f"{value:.{digits}f}"


def evaluate(args, sparse_dir, bench_set, log_path):
    """Scores the largest model in sparse_dir: its trajectory with `loopsfm eval --json`, its
    camera against the set's intrinsics.txt (vsc_camera.camera_vs_truth)."""
    groundtruth = bench_set.groundtruth
    result = {"registered": 0, "models": 0, "gt_frames": None, "ate_rmse": None,
              "ate_pct": None, "rot_mean_deg": None, "eval_note": ""}
    result["gt_frames"] = sum(1 for l in groundtruth.read_text().splitlines()
                              if l.strip() and not l.startswith("#"))
    model, num_models = largest_model(sparse_dir)
    result["models"] = num_models
    try:
        result.update(camera_vs_truth(model, bench_set.intrinsics))
    except (OSError, ValueError, struct.error) as error:
        log(f"warning: cannot read the camera of {model}: {error}")
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
# Databases (both tools write COLMAP 3.8's schema)


def decode_pair_id(pair_id):
    """COLMAP's pair id to (image_id1, image_id2)."""
    image_id2 = pair_id % PAIR_ID_BASE
    return (pair_id - image_id2) // PAIR_ID_BASE, image_id2


def largest_component(image_ids, pairs):
    """Frames in the largest connected component of the graph (image_ids, pairs), and the number
    of components (isolated frames count as one each). Union-find with path halving."""
    parent = {i: i for i in image_ids}

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in pairs:
        parent.setdefault(a, a)
        parent.setdefault(b, b)
        root_a, root_b = find(a), find(b)
        if root_a != root_b:
            parent[root_a] = root_b
    sizes = {}
    for i in parent:
        root = find(i)
        sizes[root] = sizes.get(root, 0) + 1
    return (max(sizes.values()) if sizes else 0), len(sizes)


def database_stats(db_path):
    """What a database says about matching: images, mean features per image, pairs tried (rows
    of `matches`: every pair either tool matched, verified or not), pairs verified (a two-view
    geometry with inliers and a config other than UNDEFINED/DEGENERATE), and the largest
    connected component of the graph of verified pairs with at least MIN_INLIERS inliers."""
    stats = {"db_images": None, "features_per_image": None, "pairs_tried": None,
             "pairs_verified": None, "component_largest": None, "components": None}
    if not db_path.exists():
        return stats
    conn = sqlite3.connect(f"file:{db_path}?mode=ro", uri=True)
    try:
        image_ids = [row[0] for row in conn.execute("SELECT image_id FROM images")]
        num_keypoints = conn.execute("SELECT SUM(rows) FROM keypoints").fetchone()[0]
        stats["db_images"] = len(image_ids)
        if image_ids:
            stats["features_per_image"] = (num_keypoints or 0) / len(image_ids)
        stats["pairs_tried"] = conn.execute("SELECT COUNT(*) FROM matches").fetchone()[0]
        unverified = ",".join(str(c) for c in UNVERIFIED_CONFIGS)
        geometries = conn.execute(
            f"SELECT pair_id, rows FROM two_view_geometries "
            f"WHERE rows > 0 AND config NOT IN ({unverified})").fetchall()
    except sqlite3.Error as error:
        log(f"warning: cannot read {db_path}: {error}")
        return stats
    finally:
        conn.close()
    stats["pairs_verified"] = len(geometries)
    edges = [decode_pair_id(pair_id) for pair_id, rows in geometries if rows >= MIN_INLIERS]
    stats["component_largest"], stats["components"] = largest_component(image_ids, edges)
    return stats


# ----------------------------------------------------------------------------------------------
# loopsfm


LOOPSFM_TIME = re.compile(r"^time (\S.*?)\s+([0-9.]+) s$", re.M)
LOOPSFM_TOTAL = re.compile(r"^total\s+([0-9.]+) s, peak memory ([0-9.]+) MiB", re.M)


def loopsfm_command(args, bench_set, out_dir):
    """`loopsfm reconstruct` at its defaults (pairing: vocabtree), with the set's intrinsics
    unless --no-intrinsics, plus --loopsfm-args."""
    cmd = [args.loopsfm] + (["--threads", args.threads] if args.threads else [])
    cmd += ["reconstruct", bench_set.source, "-o", out_dir]
    if not args.no_intrinsics:
        cmd += ["--intrinsics", bench_set.intrinsics]
    return cmd + args.loopsfm_args


def run_loopsfm(args, bench_set, run_dir):
    """One loopsfm run; stage times from its summary (extract, match, and map = everything
    after matching: tracks, mapping, export)."""
    out_dir = run_dir / "loopsfm"
    shutil.rmtree(out_dir, ignore_errors=True)  # loopsfm resumes from what OUT holds
    out_dir.mkdir(parents=True)
    load = load_average()
    log(f"{bench_set.name}: loopsfm reconstruct ...")
    proc = run_measured(loopsfm_command(args, bench_set, out_dir / "out"),
                        out_dir / "reconstruct.log", args.timeout)
    result = {"load_1min": load, "rc": proc["rc"], "peak_mib": proc["peak_mib"],
              "total_s": proc["wall_s"], "extraction_s": None, "matching_s": None,
              "mapping_s": None, "stage_times": {}, "database": str(out_dir / "out" / "database.db")}
    text = Path(proc["log"]).read_text()
    stage_times = {name: float(s) for name, s in LOOPSFM_TIME.findall(text)}
    result["stage_times"] = stage_times
    if stage_times:
        result["extraction_s"] = stage_times.get("extract")
        result["matching_s"] = stage_times.get("match")
        # COLMAP's mapper also builds its correspondence graph and writes the model inside
        # its own wall time, so tracks and export count as mapping.
        result["mapping_s"] = sum(t for name, t in stage_times.items()
                                  if name not in ("extract", "match"))
    total = LOOPSFM_TOTAL.search(text)
    if total:
        result["reported_total_s"] = float(total.group(1))
        result["reported_peak_mib"] = float(total.group(2))
    if proc["rc"] != 0:
        log(f"{bench_set.name}: loopsfm failed (rc {proc['rc']}), see {proc['log']}")
    result.update(database_stats(out_dir / "out" / "database.db"))
    result.update(evaluate(args, out_dir / "out" / "sparse", bench_set,
                           out_dir / "eval.json"))
    log(f"{bench_set.name}: loopsfm {result['total_s']:.1f} s, "
        f"{result['registered']}/{result['gt_frames']} registered")
    return result


def copy_loopsfm_db(bench_set, loopsfm_result, db, what):
    """The result a column mapping a copy of loopsfm's database starts from (loopsfm's
    extraction and matching times), with the copy made at `db`; rc 1 and a note where loopsfm
    left no database. `what` ends the log line that says so."""
    source_db = Path(loopsfm_result["database"])
    result = {"load_1min": load_average(), "rc": 0, "database": str(db),
              "extraction_s": loopsfm_result.get("extraction_s"),
              "matching_s": loopsfm_result.get("matching_s")}
    if not source_db.exists():
        log(f"{bench_set.name}: no loopsfm database {what} ({source_db})")
        result.update(rc=1, eval_note="no loopsfm database")
        return result
    db.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(source_db, db)
    return result


def run_loopsfm_global_on_db(args, bench_set, run_dir, loopsfm_result):
    """`loopsfm map --mapper global` on a copy of loopsfm's database: the same matches as the
    loopsfm column, the global mapper. Extraction and matching times are loopsfm's; mapping
    is everything `map` does (tracks, self-calibration, the global mapper's stages, export),
    as the loopsfm column counts everything after matching."""
    out_dir = run_dir / "loopsfm_global"
    shutil.rmtree(out_dir, ignore_errors=True)
    db = out_dir / "out" / "database.db"
    result = copy_loopsfm_db(bench_set, loopsfm_result, db, "for the global mapper")
    if result["rc"] != 0:
        return result
    log(f"{bench_set.name}: loopsfm global mapper on loopsfm's database ...")
    cmd = [args.loopsfm] + (["--threads", args.threads] if args.threads else [])
    cmd += ["map", "-d", db, "-o", out_dir / "out", "--mapper", "global", "--input",
            bench_set.source]
    proc = run_measured(cmd, out_dir / "map.log", args.timeout)
    result.update(rc=proc["rc"], peak_mib=proc["peak_mib"])
    stage_times = {name: float(t) for name, t in
                   LOOPSFM_TIME.findall(Path(proc["log"]).read_text())}
    result["stage_times"] = stage_times
    result["mapping_s"] = sum(stage_times.values()) if stage_times else None
    if proc["rc"] != 0:
        log(f"{bench_set.name}: loopsfm global mapper failed (rc {proc['rc']}), see {proc['log']}")
    front = [result["extraction_s"], result["matching_s"], result["mapping_s"]]
    result["total_s"] = sum(front) if None not in front else None
    result.update(database_stats(db))
    result.update(evaluate(args, out_dir / "out" / "sparse", bench_set, out_dir / "eval.json"))
    if "map: incremental" in stage_times:
        # The global mapper found its path likely bent or broken: the model is the
        # incremental mapper's, and the time both mappers'.
        handed = "its path likely bent or broken, handed to the incremental mapper (both times)"
        result["eval_note"] = "; ".join(n for n in (result.get("eval_note"), handed) if n)
    log(f"{bench_set.name}: loopsfm global mapper {proc['wall_s']:.1f} s, "
        f"{result['registered']}/{result['gt_frames']} registered")
    return result


# ----------------------------------------------------------------------------------------------
# COLMAP


def colmap_threads(args):
    return str(args.threads) if args.threads else "-1"


def read_intrinsics(path):
    """Returns (model, [params as text]) from the set's intrinsics.txt line 'MODEL w h params...'
    (any COLMAP model, its parameter order), for COLMAP's --ImageReader.camera_params."""
    model, _, _, params = read_intrinsics_file(path)
    return model, [repr(p) for p in params]


def mapper_command(args, db, image_dir, sparse_dir):
    """`colmap mapper`, the same for both COLMAP columns. With intrinsics they stay fixed (as in
    loopsfm); with --no-intrinsics COLMAP refines focal length and distortion, principal point
    fixed (its defaults, spelled out)."""
    cmd = [args.colmap, "mapper", "--database_path", db, "--image_path", image_dir,
           "--output_path", sparse_dir, "--Mapper.num_threads", colmap_threads(args)]
    refine = "1" if args.no_intrinsics else "0"
    cmd += ["--Mapper.ba_refine_focal_length", refine, "--Mapper.ba_refine_principal_point", "0",
            "--Mapper.ba_refine_extra_params", refine]
    return cmd


def extractor_command(args, bench_set, db, image_dir):
    """`colmap feature_extractor`: one camera for the set; the set's model and intrinsics, or
    with --no-intrinsics COLMAP's default SIMPLE_RADIAL with no parameters given."""
    cmd = [args.colmap, "feature_extractor", "--database_path", db, "--image_path", image_dir,
           "--ImageReader.single_camera", "1", "--SiftExtraction.use_gpu", "0",
           "--SiftExtraction.num_threads", colmap_threads(args)]
    if args.no_intrinsics:
        # COLMAP's default for unknown intrinsics, spelled out; no parameters: its focal guess
        # (from EXIF, else 1.2 x max(width, height)), principal point at the centre, k = 0.
        cmd += ["--ImageReader.camera_model", "SIMPLE_RADIAL"]
    else:
        model, params = read_intrinsics(bench_set.intrinsics)
        cmd += ["--ImageReader.camera_model", model, "--ImageReader.camera_params",
                ",".join(params)]
    return cmd


def matcher_command(args, bench_set, db, tree):
    """COLMAP's matcher at its defaults: exhaustive, or sequential (overlap 10, quadratic
    overlap on) with loop detection when a vocabulary tree is given."""
    if bench_set.colmap_matcher == "exhaustive":
        cmd = [args.colmap, "exhaustive_matcher"]
    else:
        cmd = [args.colmap, "sequential_matcher"]
        if tree is not None:
            cmd += ["--SequentialMatching.loop_detection", "1",
                    "--SequentialMatching.vocab_tree_path", tree]
    return cmd + ["--database_path", db, "--SiftMatching.use_gpu", "0",
                  "--SiftMatching.num_threads", colmap_threads(args)]


def colmap_vocab_tree(args, db, set_dir):
    """A vocabulary tree for COLMAP's loop detection, trained by `colmap vocab_tree_builder` on
    COLMAP's own database of the set, once per set and work folder (the features are the same
    in every run). Returns (tree path or None, {seconds, cached, ...})."""
    tree = set_dir / "colmap_vocab_tree.bin"
    stamp = set_dir / "colmap_vocab_tree.json"
    settings = {"num_visual_words": args.colmap_vocab_words, "branching": args.colmap_vocab_branching,
                "max_num_images": args.colmap_vocab_images}
    if tree.exists() and stamp.exists():
        info = json.loads(stamp.read_text())
        if info.get("settings") == settings:
            return tree, dict(info, cached=True)
    # The builder aborts when max_num_images exceeds the images in the database; -1 is all.
    max_images = args.colmap_vocab_images
    if max_images >= (database_stats(db)["db_images"] or 0):
        max_images = -1
    cmd = [args.colmap, "vocab_tree_builder", "--database_path", db, "--vocab_tree_path", tree,
           "--num_visual_words", args.colmap_vocab_words, "--branching",
           args.colmap_vocab_branching, "--max_num_images", max_images]
    log(f"{set_dir.name}: colmap vocab_tree_builder (not timed as matching) ...")
    proc = run_measured(cmd, set_dir / "colmap_vocab_tree_builder.log", args.timeout)
    if proc["rc"] != 0 or not tree.exists():
        log(f"{set_dir.name}: vocab_tree_builder failed (rc {proc['rc']}), see {proc['log']}; "
            f"COLMAP matches without loop detection")
        return None, {"seconds": proc["wall_s"], "failed": True, "settings": settings}
    info = {"seconds": proc["wall_s"], "peak_mib": proc["peak_mib"], "settings": settings,
            "trained_on": str(db), "when": time.strftime("%Y-%m-%d %H:%M:%S")}
    stamp.write_text(json.dumps(info, indent=1) + "\n")
    return tree, dict(info, cached=False)


def run_colmap(args, bench_set, image_dir, run_dir):
    """COLMAP's own pipeline: feature_extractor, [vocab_tree_builder,] matcher, mapper. Stage
    times are the wall times of the processes; the tree is reported apart."""
    out_dir = run_dir / "colmap"
    shutil.rmtree(out_dir, ignore_errors=True)
    (out_dir / "sparse").mkdir(parents=True)
    db = out_dir / "database.db"
    result = {"load_1min": load_average(), "rc": 0, "stage_peak_mib": {}, "vocab_tree": None,
              "vocab_tree_s": None, "database": str(db)}

    def stage(key, name, cmd):
        log(f"{bench_set.name}: colmap {name} ...")
        proc = run_measured(cmd, out_dir / f"{name}.log", args.timeout)
        result[key] = proc["wall_s"]
        result["stage_peak_mib"][name] = proc["peak_mib"]
        if proc["rc"] != 0:
            result["rc"] = proc["rc"]
            log(f"{bench_set.name}: colmap {name} failed (rc {proc['rc']}), see {proc['log']}")
        return proc["rc"] == 0

    ok = stage("extraction_s", "feature_extractor",
               extractor_command(args, bench_set, db, image_dir))
    tree = None
    if ok and bench_set.colmap_matcher == "sequential" and args.colmap_loop_detection:
        tree, info = colmap_vocab_tree(args, db, run_dir.parent)
        result["vocab_tree"] = info
        result["vocab_tree_s"] = info["seconds"]
    result["loop_detection"] = tree is not None
    ok = ok and stage("matching_s", "matcher", matcher_command(args, bench_set, db, tree))
    ok = ok and stage("mapping_s", "mapper",
                      mapper_command(args, db, image_dir, out_dir / "sparse"))
    stage_s = [result.get(k) for k in ("extraction_s", "matching_s", "mapping_s")]
    result["total_s"] = sum(s for s in stage_s if s is not None)
    result["peak_mib"] = max(result["stage_peak_mib"].values())
    result.update(database_stats(db))
    result.update(evaluate(args, out_dir / "sparse", bench_set, out_dir / "eval.json"))
    log(f"{bench_set.name}: colmap {result['total_s']:.1f} s, "
        f"{result['registered']}/{result['gt_frames']} registered")
    return result


def run_colmap_on_loopsfm_db(args, bench_set, image_dir, run_dir, loopsfm_result):
    """COLMAP's mapper on a copy of loopsfm's database (the mapper writes to the database), with
    the mapper flags of the COLMAP column: same matches as loopsfm, COLMAP's mapper.

    Extraction and matching times are loopsfm's (its database), the total is theirs plus the
    mapper's wall time; peak memory is the mapper's."""
    out_dir = run_dir / "colmap_on_loopsfm_db"
    shutil.rmtree(out_dir, ignore_errors=True)
    (out_dir / "sparse").mkdir(parents=True)
    db = out_dir / "database.db"
    result = copy_loopsfm_db(bench_set, loopsfm_result, db, "to map with COLMAP")
    if result["rc"] != 0:
        return result
    log(f"{bench_set.name}: colmap mapper on loopsfm's database ...")
    proc = run_measured(mapper_command(args, db, image_dir, out_dir / "sparse"),
                        out_dir / "mapper.log", args.timeout)
    result.update(rc=proc["rc"], mapping_s=proc["wall_s"], peak_mib=proc["peak_mib"])
    if proc["rc"] != 0:
        log(f"{bench_set.name}: colmap mapper on loopsfm's database failed (rc {proc['rc']}), "
            f"see {proc['log']}")
    front = [result["extraction_s"], result["matching_s"]]
    result["total_s"] = (sum(front) + proc["wall_s"]) if None not in front else None
    result.update(database_stats(db))
    result.update(evaluate(args, out_dir / "sparse", bench_set, out_dir / "eval.json"))
    log(f"{bench_set.name}: colmap mapper on loopsfm's db {proc['wall_s']:.1f} s, "
        f"{result['registered']}/{result['gt_frames']} registered")
    return result

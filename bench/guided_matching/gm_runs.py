"""Sets, variant databases, matching runs and the exhaustive ground truth for guided_matching.py.

A *base sequence* is one set's frames in capture order, features extracted once. A *variant*
is a list of indices into the base sequence (frames may repeat); its database holds those
frames' rows renamed frame_%06d.png in variant order, so loopsfm sees them in that order.
Every strategy runs on a fresh copy of a variant database. Standard library only.
"""

import json
import os
import shutil
import sqlite3
import statistics
import subprocess
import sys
import time
from pathlib import Path

PAIR_ID_BASE = 2147483647


def log(message):
    print(message, file=sys.stderr, flush=True)


def busy_cpus(seconds=3.0):
    """Mean number of other runnable tasks over a few seconds (/proc/loadavg's running count,
    less this process), or None where /proc is not there."""
    samples = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            running = int(Path("/proc/loadavg").read_text().split()[3].split("/")[0])
        except (OSError, ValueError, IndexError):
            return None
        samples.append(max(0, running - 1))
        time.sleep(0.2)
    return sum(samples) / len(samples)


def wait_until_idle(max_busy, timeout):
    """Waits (at most timeout seconds) until fewer than max_busy other tasks are runnable."""
    start = time.monotonic()
    busy = busy_cpus()
    while busy is not None and busy >= max_busy and time.monotonic() - start < timeout:
        log(f"    waiting: {busy:.1f} other tasks running")
        time.sleep(20)
        busy = busy_cpus()
    return busy


def load_average():
    try:
        return round(os.getloadavg()[0], 2)
    except OSError:
        return None


# ----------------------------------------------------------------------------------------------
# Sets


class BenchSet:
    """One input and how its base sequence is made."""

    def __init__(self, name, source, intrinsics, every, loop, synth_frames=None):
        self.name = name
        self.source = source          # video file or images folder (street: rendered folder)
        self.intrinsics = intrinsics
        self.every = every            # `loopsfm extract --every`
        self.loop = loop              # whether the end revisits the start
        self.synth_frames = synth_frames  # street only: frames rendered


def make_set(name, args, workdir):
    """Returns (BenchSet, None) or (None, reason it cannot run here)."""
    data = args.data
    if name == "street":
        out = workdir / "street" / f"synth{args.street_frames}"
        bench_set = BenchSet(name, out / "images", out / "intrinsics.txt", 1, True,
                             args.street_frames)
        return bench_set, None
    table = {
        "block": (data / "block" / "block.mp4", data / "block" / "intrinsics.txt", True),
        "templeRing": (data / "templeRing" / "images", data / "templeRing" / "intrinsics.txt", True),
        "kitti07_160": (data / "kitti07_160" / "images", data / "kitti07_160" / "intrinsics.txt",
                        False),
        "fox": (data / "fox" / "images", data / "fox" / "intrinsics.txt", True),
    }
    if name not in table:
        return None, f"unknown set '{name}'"
    source, intrinsics, loop = table[name]
    for path in (source, intrinsics):
        if not path.exists():
            return None, f"{path} is missing (shared data not here? pass --data DIR)"
    return BenchSet(name, source, intrinsics, args.every.get(name, 1), loop), None


def run_logged(cmd, log_path):
    """Runs cmd, output to log_path; returns (exit code, wall seconds)."""
    with open(log_path, "w") as out:
        out.write("$ " + " ".join(str(c) for c in cmd) + "\n")
        out.flush()
        start = time.monotonic()
        rc = subprocess.run([str(c) for c in cmd], stdout=out, stderr=subprocess.STDOUT).returncode
    return rc, time.monotonic() - start


def ensure_base(bench_set, args, workdir):
    """Renders (street) and extracts features once; returns the base database path."""
    set_dir = workdir / bench_set.name
    set_dir.mkdir(parents=True, exist_ok=True)
    if bench_set.synth_frames:
        synth_dir = bench_set.source.parent
        if not (synth_dir / "groundtruth.txt").exists():
            log(f"{bench_set.name}: rendering {bench_set.synth_frames} frames (not timed)")
            rc, _ = run_logged([args.loopsfm, "synth", "street", "--frames",
                                bench_set.synth_frames, "-o", synth_dir],
                               set_dir / f"synth{bench_set.synth_frames}.log")
            if rc != 0:
                raise RuntimeError(f"synth street failed, see {set_dir}")
    tag = f"synth{bench_set.synth_frames}" if bench_set.synth_frames else f"every{bench_set.every}"
    db = set_dir / f"base_{tag}.db"
    done = set_dir / f"base_{tag}.done"
    if not done.exists():
        if db.exists():
            db.unlink()
        log(f"{bench_set.name}: extracting features into {db} (not timed)")
        rc, wall = run_logged([args.loopsfm, "extract", bench_set.source, "-d", db,
                               "--intrinsics", bench_set.intrinsics, "--every", bench_set.every],
                              set_dir / f"base_{tag}_extract.log")
        if rc != 0:
            raise RuntimeError(f"extract failed, see {set_dir}/base_{tag}_extract.log")
        done.write_text(f"{wall:.1f}\n")
    return db


def base_frames(base_db):
    """[(image_id, name, camera_id, num_features)] in capture (name) order."""
    conn = sqlite3.connect(f"file:{base_db}?mode=ro", uri=True)
    try:
        rows = conn.execute("SELECT images.image_id, name, camera_id, keypoints.rows FROM images "
                            "JOIN keypoints ON keypoints.image_id = images.image_id").fetchall()
    finally:
        conn.close()
    return sorted(rows, key=lambda r: r[1])


# ----------------------------------------------------------------------------------------------
# Variants


class Variant:
    """Frames of the base sequence, in order, possibly repeated."""

    def __init__(self, name, indices, **info):
        self.name = name
        self.indices = list(indices)
        self.info = info  # r (repeats), s (stride), span (base frames covered), kind

    @property
    def num_frames(self):
        return len(self.indices)

    @property
    def num_pairs(self):
        n = len(self.indices)
        return n * (n - 1) // 2


def stride_variant(length, stride):
    """Every `stride`-th frame of the whole base sequence: same path, fewer frames."""
    indices = list(range(0, length, stride))
    return Variant(f"all_s{stride}", indices, kind="frames", r=1, s=stride, span=length)


def density_variant(length, num_frames, repeats, stride):
    """num_frames frames whose match matrix is denser (repeats > 1) or sparser (stride > 1).

    Covers span = num_frames * stride / repeats base frames: the first half of the span from
    the start of the sequence and the second half from its end (the stretch in between is
    dropped), so the loop closure (the end revisits the start) stays in every variant. Each
    kept frame is taken every `stride` frames and repeated `repeats` times in a row.
    Returns None when the span does not fit in the base sequence.
    """
    span = -(-num_frames * stride // repeats)
    if span > length:
        return None
    head = (span + 1) // 2
    window = list(range(head)) + list(range(length - (span - head), length))
    indices = [i for i in window[::stride] for _ in range(repeats)][:num_frames]
    if len(indices) < num_frames:
        return None
    return Variant(f"n{num_frames}_r{repeats}_s{stride}", indices, kind="density", r=repeats,
                   s=stride, span=span)


def copy_schema(src, dst):
    """Creates dst with src's tables (no rows)."""
    conn = sqlite3.connect(dst)
    try:
        src_conn = sqlite3.connect(f"file:{src}?mode=ro", uri=True)
        statements = [sql for (name, sql) in src_conn.execute(
            "SELECT name, sql FROM sqlite_master WHERE sql IS NOT NULL ORDER BY rowid")
            if not name.startswith("sqlite_")]
        src_conn.close()
        for sql in statements:
            conn.execute(sql)
        conn.commit()
    finally:
        conn.close()


def build_variant_db(base_db, frames, variant, path):
    """Writes the variant's database (cameras, images, keypoints, descriptors) once."""
    if path.exists():
        return path
    tmp = path.with_suffix(".tmp")
    if tmp.exists():
        tmp.unlink()
    copy_schema(base_db, tmp)
    conn = sqlite3.connect(tmp)
    try:
        conn.execute("ATTACH DATABASE ? AS base", (f"file:{base_db}?mode=ro",))
        conn.execute("INSERT INTO cameras SELECT * FROM base.cameras")
        conn.execute("INSERT INTO loopsfm_meta SELECT * FROM base.loopsfm_meta")
        for k, index in enumerate(variant.indices):
            image_id, _, camera_id, _ = frames[index]
            new_id = k + 1
            conn.execute("INSERT INTO images(image_id, name, camera_id) VALUES (?, ?, ?)",
                         (new_id, f"frame_{k:06d}.png", camera_id))
            for table in ("keypoints", "descriptors"):
                conn.execute(f"INSERT INTO {table}(image_id, rows, cols, data) "
                             f"SELECT ?, rows, cols, data FROM base.{table} WHERE image_id = ?",
                             (new_id, image_id))
            conn.execute("INSERT INTO loopsfm_frames(image_id, source_index, sharpness) "
                         "SELECT ?, ?, sharpness FROM base.loopsfm_frames WHERE image_id = ?",
                         (new_id, k, image_id))
        conn.commit()
        conn.execute("DETACH DATABASE base")
    finally:
        conn.close()
    tmp.rename(path)
    return path


def read_verified(db):
    """{(k, l): inliers} over verified pairs, k < l variant indices (image_id - 1)."""
    conn = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        rows = conn.execute("SELECT pair_id, rows FROM two_view_geometries "
                            "WHERE rows > 0 AND config NOT IN (0, 1)").fetchall()
    finally:
        conn.close()
    verified = {}
    for pair_id, inliers in rows:
        id1, id2 = divmod(pair_id, PAIR_ID_BASE)
        verified[(min(id1, id2) - 1, max(id1, id2) - 1)] = inliers
    return verified


# ----------------------------------------------------------------------------------------------
# Matching runs


def binary_stamp(path):
    """Identifies a build of loopsfm: size and modification time of the binary."""
    st = Path(path).stat()
    return {"size": st.st_size, "mtime": st.st_mtime}


def same_build(cached, stamp):
    """Whether a cached run came from the binary described by stamp. Runs cached before the
    stamp was recorded count when they started after the binary was last written."""
    if "binary" in cached:
        return cached["binary"] == stamp
    started = time.mktime(time.strptime(cached["when"], "%Y-%m-%d %H:%M:%S")) - cached["wall_s"]
    return started > stamp["mtime"]


def mark_pairs_matched(db, pairs):
    """Stores empty matches for the given (k, l) variant pairs, so loopsfm skips them (resume)."""
    conn = sqlite3.connect(db)
    try:
        conn.executemany("INSERT INTO matches(pair_id, rows, cols, data) VALUES (?, 0, 2, NULL)",
                         (((k + 1) * PAIR_ID_BASE + (l + 1),) for k, l in pairs))
        conn.commit()
    finally:
        conn.close()


def match_run(args, set_dir, variant_db, variant, strategy, extra, run_index, tag="",
              skip_pairs=None):
    """One `loopsfm match` on a fresh copy of the variant database; cached in the workdir.

    skip_pairs: (k, l) pairs stored as already matched before the run, which loopsfm then
    skips (used to time exhaustive matching of exhaustive's verified pairs only).
    Returns {report, verified, load_before, wall_s, cmd}; report is loopsfm's --json-report.
    """
    label = f"{strategy}{'-' + tag if tag else ''}-{run_index}"
    run_dir = set_dir / "runs" / variant.name / label
    result_path = run_dir / "result.json"
    cmd_tail = ["match", "--pairs", strategy] + list(extra)
    if result_path.exists() and not args.fresh:
        cached = json.loads(result_path.read_text())
        if (cached.get("cmd_tail") == cmd_tail and cached.get("threads") == args.threads
                and (strategy in args.reuse_across_builds or same_build(cached, args.stamp))):
            cached["verified"] = {tuple(map(int, k.split(","))): v
                                  for k, v in cached["verified"].items()}
            cached["cached"] = True
            return cached
    shutil.rmtree(run_dir, ignore_errors=True)
    run_dir.mkdir(parents=True)
    db = run_dir / "run.db"
    shutil.copyfile(variant_db, db)
    if skip_pairs:
        mark_pairs_matched(db, skip_pairs)
    report_path = run_dir / "report.json"
    cmd = [args.loopsfm] + (["--threads", args.threads] if args.threads else [])
    cmd += ["match", "-d", db, "--pairs", strategy, "--json-report", report_path] + list(extra)
    busy_before = wait_until_idle(args.max_busy, args.wait_idle) if args.wait_idle else None
    load_before = load_average()
    log(f"  {variant.name}: {strategy}{' ' + ' '.join(extra) if extra else ''} "
        f"[{variant.num_frames} frames, {variant.num_pairs} pairs, load {load_before}] ...")
    rc, wall = run_logged(cmd, run_dir / "log.txt")
    if rc != 0:
        raise RuntimeError(f"loopsfm match failed (exit {rc}), see {run_dir / 'log.txt'}")
    report = json.loads(report_path.read_text())
    verified = read_verified(db)
    log(f"    {report['seconds']:.1f} s, {report['num_pairs_matched']} pairs matched, "
        f"{report['num_pairs_verified']} verified")
    result = {"cmd_tail": cmd_tail, "threads": args.threads, "binary": args.stamp,
              "report": report,
              "load_before": load_before, "load_after": load_average(), "wall_s": wall,
              "busy_before": busy_before,
              "when": time.strftime("%Y-%m-%d %H:%M:%S"),
              "verified": {f"{k},{l}": v for (k, l), v in verified.items()}}
    result_path.write_text(json.dumps(result))
    if not args.keep_dbs:
        db.unlink()
    result["verified"] = verified
    return result


def median_runs(results):
    """The run with the median `seconds` (lower median), plus all the times."""
    ordered = sorted(results, key=lambda r: r["report"]["seconds"])
    chosen = dict(ordered[(len(ordered) - 1) // 2])
    chosen["all_seconds"] = [r["report"]["seconds"] for r in results]
    return chosen


# ----------------------------------------------------------------------------------------------
# Ground truth and recall


# Fewest inliers for a verified pair to join two frames in the view graph (loopsfm's
# --min-inliers default, COLMAP's SiftMatching.min_num_inliers).
COMPONENT_MIN_INLIERS = 15


def largest_component(num_frames, verified, min_inliers=COMPONENT_MIN_INLIERS):
    """Frames in the largest connected component of the graph whose nodes are the variant's
    frames 0..num_frames-1 and whose edges are the verified pairs {(k, l): inliers} with at
    least min_inliers inliers (union-find with path halving)."""
    parent = list(range(num_frames))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for (k, l), inliers in verified.items():
        if inliers >= min_inliers:
            root_k, root_l = find(k), find(l)
            if root_k != root_l:
                parent[root_k] = root_l
    sizes = {}
    for i in range(num_frames):
        root = find(i)
        sizes[root] = sizes.get(root, 0) + 1
    return max(sizes.values(), default=0)


def variant_truth(variant, base_truth, frames):
    """Exhaustive's verified pairs of a variant, {(k, l): inliers}, from the base sequence's.

    A pair of two copies of one frame is verified with every feature an inlier (what loopsfm
    gives identical images: all matches fit, config 'panoramic').
    """
    truth = {}
    idx = variant.indices
    for k in range(len(idx)):
        a = idx[k]
        for l in range(k + 1, len(idx)):
            b = idx[l]
            if a == b:
                truth[(k, l)] = frames[a][3]
            else:
                inliers = base_truth.get((a, b) if a < b else (b, a))
                if inliers is not None:
                    truth[(k, l)] = inliers
    return truth


def recall(truth, found, overlap, variant=None):
    """Recall of `found` against `truth` (both {(k, l): inliers})."""
    total_inliers = sum(truth.values())
    both = [p for p in truth if p in found]
    far = [p for p in truth if p[1] - p[0] > overlap]
    n = max((p[1] for p in truth), default=0) + 1
    if variant is not None:
        n = variant.num_frames
    loop = [p for p in truth if p[1] - p[0] > n // 2]
    return {
        "pairs_truth": len(truth),
        "pairs_found": len(found),
        "pairs_both": len(both),
        "pairs_extra": sum(1 for p in found if p not in truth),
        "pair_recall": len(both) / len(truth) if truth else None,
        "weighted_recall": (sum(truth[p] for p in both) / total_inliers) if total_inliers else None,
        "inlier_recall": (sum(min(truth[p], found[p]) for p in both) / total_inliers)
        if total_inliers else None,
        "far_pairs": len(far),
        "far_recall": (sum(1 for p in far if p in found) / len(far)) if far else None,
        "loop_pairs": len(loop),
        "loop_found": sum(1 for p in loop if p in found),
    }


def median(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None

#!/usr/bin/env python3
"""Vocabulary-tree guided matching against exhaustive and low-resolution matching (issue 4).

One run produces four tables (and figures):
1. density sweep: fixed number of frames, density of the true match matrix varied;
2. frame-count sweep at constant density;
3. vocabtree time broken down into tree building, scoring, pair proposal, feature matching;
4. recall against exhaustive matching (pairs, inlier-weighted, inlier matches).
Times of exhaustive, lowres and vocabtree and the theoretical optimum (exhaustive time x
density). Standard library only (gnuplot for the figures); see README.md beside this file.
"""

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import gm_report  # noqa: E402
from gm_runs import (base_frames, binary_stamp, build_variant_db,  # noqa: E402
                     density_variant, ensure_base, largest_component, load_average, log,
                     make_set, match_run, median_runs, recall, stride_variant, variant_truth)

REPO_ROOT = Path(__file__).resolve().parents[2]
ALL_SETS = ["street", "block", "templeRing", "kitti07_160", "fox"]
SWEEP_SETS = ["street", "block"]
DENSITY_LEVELS = [(3, 1), (2, 1), (1, 1), (1, 2), (1, 3)]  # (repeats, stride)
MODES = {
    # street frames, density-sweep frames, frame-count strides, sets, extract --every per set
    "full": dict(street_frames=400, density_frames=120, strides=[4, 3, 2, 1], sets=ALL_SETS,
                 every={}),
    "quick": dict(street_frames=120, density_frames=36, strides=[4, 2, 1],
                  sets=["street", "block", "templeRing"], every={"block": 4, "kitti07_160": 4,
                                                                 "fox": 3}),
}


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="small sizes (minutes, not an hour)")
    p.add_argument("--sets", help=f"comma-separated, from {','.join(ALL_SETS)}")
    p.add_argument("--sweep-sets", help="sets for tables 1-2 (default: street,block)")
    p.add_argument("--tables", default="1,2,3,4", help="tables to run (default 1,2,3,4)")
    p.add_argument("--runs", type=int, default=1, help="lowres and vocabtree runs per variant "
                   "(median time); exhaustive runs once")
    p.add_argument("--measure-exhaustive", choices=["some", "all"], default="some",
                   help="some: measure exhaustive on each set's whole sequence, the density "
                   "sweep's middle variant and the frame-count sweep's smallest, estimate the "
                   "others as pairs x seconds per pair; all: measure every variant")
    p.add_argument("--street-frames", type=int, help="frames of the synthetic street")
    p.add_argument("--density-frames", type=int, help="frames of every density-sweep variant")
    p.add_argument("--strides", help="frame-count sweep strides, e.g. 4,3,2,1")
    p.add_argument("--vocab-args", default="--loop-partners 0",
                   help="extra flags for every vocabtree run (default '--loop-partners 0': "
                        "every loop pair region growing reaches, so that recall against "
                        "exhaustive matching measures the search, not the thinning of wide "
                        "loop bands that the default of 5 partners per frame does)")
    p.add_argument("--vocab-settings", default="", help="';'-separated flag sets: table 5 runs "
                   "vocabtree with each on every set's whole sequence, e.g. "
                   "'--proposals 100;--stop-failure-ratio 0.9' (sets: --settings-sets)")
    p.add_argument("--settings-sets", default="street,block",
                   help="sets of table 5 (default street,block)")
    p.add_argument("--overlap", type=int, default=10, help="vocabtree sequential overlap "
                   "(loopsfm's default 10; used for the 'pairs > overlap apart' recall)")
    p.add_argument("--no-measured-optimum", dest="measured_optimum", action="store_false",
                   help="skip timing exhaustive on its verified pairs only (tables 4 and 5)")
    p.add_argument("--target-frames", type=int, default=300,
                   help="targets apply to sequences of at least this many frames")
    p.add_argument("--wait-idle", type=float, default=0, metavar="S",
                   help="before each run wait up to S seconds until fewer than --max-busy "
                   "other tasks are runnable (for shared machines)")
    p.add_argument("--max-busy", type=float, default=0.5)
    p.add_argument("--retime-slow", action="store_true",
                   help="run again every cached run whose median matching time per pair is "
                   f"more than {gm_report.SLOW} x its set's fastest (slowed by other jobs)")
    p.add_argument("--threads", type=int, default=0, help="loopsfm --threads (0: all cores)")
    p.add_argument("--workdir", type=Path, default=Path("/tmp/loopsfm_guided_matching"))
    p.add_argument("--out", type=Path, help="tables, JSON, figures (default WORKDIR/results)")
    p.add_argument("--data", type=Path, default=Path(os.environ.get(
        "LOOPSFM_DATA", REPO_ROOT.parent / "shared" / "data")))
    p.add_argument("--loopsfm", type=Path, default=REPO_ROOT / "build" / "loopsfm")
    p.add_argument("--fresh", action="store_true", help="ignore cached runs in the workdir")
    p.add_argument("--reuse-across-builds", default="exhaustive",
                   help="strategies whose cached runs are reused after loopsfm is rebuilt "
                   "(default: exhaustive, the ground truth; the others run again)")
    p.add_argument("--keep-dbs", action="store_true", help="keep every run's database")
    args = p.parse_args()
    mode = MODES["quick" if args.quick else "full"]
    args.mode = "quick" if args.quick else "full"
    args.street_frames = args.street_frames or mode["street_frames"]
    args.density_frames = args.density_frames or mode["density_frames"]
    args.strides = [int(s) for s in args.strides.split(",")] if args.strides else mode["strides"]
    args.sets = args.sets.split(",") if args.sets else mode["sets"]
    args.sweep_sets = args.sweep_sets.split(",") if args.sweep_sets else SWEEP_SETS
    args.tables = {int(t) for t in args.tables.split(",")}
    args.every = mode["every"]
    args.vocab_args = args.vocab_args.split()
    args.vocab_settings = [s.strip() for s in args.vocab_settings.split(";") if s.strip()]
    args.out = args.out or args.workdir / "results"
    if not args.loopsfm.exists():
        sys.exit(f"{args.loopsfm} not found: build it first (scripts/build) or pass --loopsfm")
    args.stamp = binary_stamp(args.loopsfm)
    args.reuse_across_builds = [s for s in args.reuse_across_builds.split(",") if s]
    return args


def drop_slow_runs(workdir):
    """Renames result.json of cached runs slowed by other jobs so that they run again."""
    for variant_dir in sorted(workdir.glob("*/variants_*")):
        results = []
        for path in variant_dir.glob("runs/*/*/result.json"):
            ms = json.loads(path.read_text())["report"].get("median_match_ms")
            if ms:
                results.append((ms, path))
        if not results:
            continue
        fastest = min(ms for ms, _ in results)
        for ms, path in results:
            if ms > gm_report.SLOW * fastest:
                log(f"retime: {path.parent} ({ms:.1f} ms per pair, fastest {fastest:.1f})")
                path.rename(path.with_name("result.slow.json"))


class SetBench:
    """Runs of one set: base sequence, its exhaustive truth, variants."""

    def __init__(self, args, bench_set):
        self.args = args
        self.set = bench_set
        self.dir = args.workdir / bench_set.name
        self.base_db = ensure_base(bench_set, args, args.workdir)
        self.frames = base_frames(self.base_db)
        self.length = len(self.frames)
        tag = self.base_db.stem
        self.variant_dir = self.dir / f"variants_{tag}"
        self.variant_dir.mkdir(parents=True, exist_ok=True)
        self.full = stride_variant(self.length, 1)
        self.full.name = f"{tag}_all"
        log(f"{bench_set.name}: {self.length} frames, "
            f"{sum(f[3] for f in self.frames) / max(1, self.length):.0f} features per frame")
        truth_run = self.run(self.full, "exhaustive", [], 0)
        self.truth = truth_run["verified"]
        self.seconds_per_pair = truth_run["report"]["seconds"] / max(1, self.full.num_pairs)

    def run(self, variant, strategy, extra, index, tag="", skip_pairs=None):
        variant_db = build_variant_db(self.base_db, self.frames, variant,
                                      self.variant_dir / f"{variant.name}.db")
        return match_run(self.args, self.variant_dir, variant_db, variant, strategy, extra, index,
                         tag, skip_pairs)

    def measured_optimum(self):
        """Seconds to match and verify exhaustive's verified pairs and nothing else: exhaustive
        on the whole sequence with every other pair stored beforehand as already matched."""
        if not hasattr(self, "_measured_optimum"):
            n = self.full.num_frames
            others = [(k, l) for k in range(n) for l in range(k + 1, n) if (k, l) not in self.truth]
            run = self.run(self.full, "exhaustive", [], 0, "truth-pairs-only", others)
            self._measured_optimum = run["report"]["seconds"]
        return self._measured_optimum

    def evaluate(self, variant, measure_exhaustive, vocab_extra=None, tag="", strategies=None,
                 seconds_per_pair=None):
        """One row: times of the strategies on the variant and recall against exhaustive."""
        args = self.args
        strategies = strategies or ["lowres", "vocabtree"]
        vocab_extra = args.vocab_args if vocab_extra is None else vocab_extra
        if variant is self.full:
            truth = self.truth
        else:
            truth = variant_truth(variant, self.truth, self.frames)
        density = len(truth) / max(1, variant.num_pairs)
        row = {"set": self.set.name, "variant": variant.name, "frames": variant.num_frames,
               "repeats": variant.info.get("r", 1), "stride": variant.info.get("s", 1),
               "span": variant.info.get("span", variant.num_frames), "pairs": variant.num_pairs,
               "density": density, "truth_pairs": len(truth)}
        if measure_exhaustive or variant is self.full:
            ex = self.run(variant, "exhaustive", [], 0)
            row["exhaustive_s"] = ex["report"]["seconds"]
            row["exhaustive_measured"] = True
            row["exhaustive_estimate_s"] = variant.num_pairs * self.seconds_per_pair
            if variant is not self.full:
                row["exhaustive_truth_check"] = recall(truth, ex["verified"], args.overlap, variant)
            row["exhaustive_load"] = ex["load_before"]
            row["exhaustive_match_ms"] = ex["report"]["median_match_ms"]
        else:
            row["exhaustive_s"] = variant.num_pairs * (seconds_per_pair or self.seconds_per_pair)
            row["exhaustive_measured"] = False
        row["optimum_s"] = row["exhaustive_s"] * density
        row["optimum_measured_s"] = None
        if variant is self.full and args.measured_optimum:
            row["optimum_measured_s"] = self.measured_optimum()
        # Frames in the largest connected component of each strategy's verified pairs.
        row["components"] = {"frames": variant.num_frames,
                             "exhaustive": largest_component(variant.num_frames, truth),
                             "lowres": None, "vocab": None}
        if "lowres" in strategies:
            lo = median_runs([self.run(variant, "lowres", [], k) for k in range(args.runs)])
            row["components"]["lowres"] = largest_component(variant.num_frames, lo["verified"])
            row["lowres_s"] = lo["report"]["seconds"]
            row["lowres_all_s"] = lo["all_seconds"]
            row["lowres"] = recall(truth, lo["verified"], args.overlap, variant)
            row["lowres_report"] = lo["report"]
            row["lowres_match_ms"] = lo["report"]["median_match_ms"]
            row["lowres_over_vocab"] = None
        vo = median_runs([self.run(variant, "vocabtree", vocab_extra, k, tag)
                          for k in range(args.runs)])
        rep = vo["report"]
        row["vocab_s"] = rep["seconds"]
        row["vocab_all_s"] = vo["all_seconds"]
        row["vocab_load"] = vo["load_before"]
        row["vocab"] = recall(truth, vo["verified"], args.overlap, variant)
        row["components"]["vocab"] = largest_component(variant.num_frames, vo["verified"])
        row["vocab_report"] = rep
        row["vocab_match_ms"] = rep["median_match_ms"]
        row["flags"] = " ".join(vocab_extra)
        row["vocab_over_optimum"] = rep["seconds"] / row["optimum_s"] if row["optimum_s"] else None
        row["exhaustive_over_vocab"] = row["exhaustive_s"] / rep["seconds"]
        row["vocab_over_measured_optimum"] = (rep["seconds"] / row["optimum_measured_s"]
                                              if row["optimum_measured_s"] else None)
        if "lowres" in strategies:
            row["lowres_over_vocab"] = row["lowres_s"] / rep["seconds"]
        v = rep["vocab"]
        rounds = v["rounds"]
        by_score = sum(r["from_scores"] for r in rounds)
        by_growing = sum(r["from_growing"] for r in rounds)
        accounted = v["build_seconds"] + v["score_seconds"] + v["propose_seconds"] + v["match_seconds"]
        row["breakdown"] = {
            "build_s": v["build_seconds"], "score_s": v["score_seconds"],
            "propose_s": v["propose_seconds"], "match_s": v["match_seconds"],
            "other_s": rep["seconds"] - accounted, "rounds": len(rounds),
            "pairs_matched": rep["num_pairs_matched"],
            "pairs_sequential": rep["num_pairs"] - by_score - by_growing,
            "pairs_by_score": by_score, "pairs_by_growing": by_growing,
            "verified_in_rounds": sum(r["verified"] for r in rounds),
            "matched_over_truth": rep["num_pairs_matched"] / max(1, len(truth)),
            # Matching time split between the sequential pairs and the rounds' pairs in
            # proportion to their numbers (the report times them together).
            "match_sequential_s": v["match_seconds"] * (rep["num_pairs"] - by_score - by_growing)
            / max(1, rep["num_pairs"]),
            "round_list": rounds}
        row["breakdown"]["row_label"] = f"{self.set.name} {variant.name}"
        return row


def mark_slowdowns(results):
    """Median descriptor-matching time per pair is the same work in every run of a set, so
    its ratio to the set's fastest run flags runs slowed down by other jobs (`*_slowdown`)."""
    rows = [r for key in ("density_sweep", "frames_sweep", "recall", "settings", "breakdown")
            for r in results[key]]
    fastest = {}
    for r in rows:
        for kind in ("exhaustive", "lowres", "vocab"):
            ms = r.get(f"{kind}_match_ms")
            if ms:
                fastest[r["set"]] = min(ms, fastest.get(r["set"], ms))
    for r in rows:
        for kind in ("exhaustive", "lowres", "vocab"):
            ms = r.get(f"{kind}_match_ms")
            r[f"{kind}_slowdown"] = ms / fastest[r["set"]] if ms else None


def write_outputs(args, results, started):
    mark_slowdowns(results)
    args.out.mkdir(parents=True, exist_ok=True)
    sections = [f"# Guided matching benchmark ({args.mode})\n",
                f"Run {time.strftime('%Y-%m-%d %H:%M', time.localtime(started))}, "
                f"{os.cpu_count()} CPUs, loopsfm `--threads {args.threads or 'all'}`, "
                f"{args.runs} run(s) per lowres/vocabtree timing (median). "
                f"1-minute load average at each run's start is in results.json. † marks a time whose "
                f"run's median matching time per pair was over {gm_report.SLOW}x the truth run's "
                f"(slowed by other jobs, or a different mix of pairs).\n"]
    if results["density_sweep"]:
        sections += ["## 1. Density sweep (fixed frames)\n",
                     gm_report.sweep_table(results["density_sweep"]), ""]
    if results["frames_sweep"]:
        sections += ["## 2. Frame-count sweep (constant density)\n",
                     gm_report.sweep_table(results["frames_sweep"]), ""]
    if results["breakdown"]:
        sections += ["## 3. Vocabtree time breakdown\n",
                     gm_report.breakdown_table(results["breakdown"]), ""]
    if results["recall"]:
        sections += ["## 4. Recall against exhaustive\n",
                     gm_report.recall_table(results["recall"], args.target_frames), ""]
    if results["settings"]:
        sections += ["## 5. Vocabtree settings (whole sequences)\n",
                     gm_report.settings_table(results["settings"]), ""]
    text = "\n".join(sections) + "\n"
    (args.out / "results.md").write_text(text)
    (args.out / "results.json").write_text(json.dumps(results, indent=1, default=str))
    return text


def git_describe():
    try:
        return subprocess.run(["git", "-C", str(REPO_ROOT), "describe", "--always", "--dirty"],
                              capture_output=True, text=True).stdout.strip() or None
    except OSError:
        return None


def main():
    args = parse_args()
    started = time.time()
    args.workdir.mkdir(parents=True, exist_ok=True)
    if args.retime_slow:
        drop_slow_runs(args.workdir)
    results = {"meta": {"mode": args.mode, "started": time.ctime(started), "cpus": os.cpu_count(),
                        "load_at_start": load_average(), "runs": args.runs,
                        "street_frames": args.street_frames,
                        "density_frames": args.density_frames, "strides": args.strides,
                        "vocab_args": args.vocab_args, "overlap": args.overlap,
                        "loopsfm": str(args.loopsfm), "loopsfm_build": args.stamp,
                        "git": git_describe()},
               "density_sweep": [], "frames_sweep": [], "breakdown": [], "recall": [],
               "settings": [], "skipped": {}}
    sets = [s for s in ALL_SETS if s in args.sets] + [s for s in args.sets if s not in ALL_SETS]
    for name in sets:
        bench_set, reason = make_set(name, args, args.workdir)
        if bench_set is None:
            log(f"{name}: skipped: {reason}")
            results["skipped"][name] = reason
            continue
        bench = SetBench(args, bench_set)
        sweep = name in args.sweep_sets
        if 4 in args.tables or (sweep and 2 in args.tables and 1 in args.strides):
            row = bench.evaluate(bench.full, True)
            if 4 in args.tables:
                results["recall"].append(row)
            results["breakdown"].append(row)
        if sweep and 2 in args.tables:
            strides = sorted(args.strides, reverse=True)
            for stride in strides:
                variant = bench.full if stride == 1 else stride_variant(bench.length, stride)
                measure = args.measure_exhaustive == "all" or stride == strides[0]
                row = bench.evaluate(variant, measure)
                results["frames_sweep"].append(row)
                if stride != 1:
                    results["breakdown"].append(row)
        if sweep and 1 in args.tables:
            # Every variant has the same number of frames, so exhaustive costs the same on
            # each: it is measured on the (1, 1) variant, which goes first, and the others
            # are estimated at that run's seconds per pair (unless --measure-exhaustive all).
            rate, rows = None, []
            for repeats, stride in sorted(DENSITY_LEVELS, key=lambda level: level != (1, 1)):
                variant = density_variant(bench.length, args.density_frames, repeats, stride)
                if variant is None:
                    log(f"{name}: density level r={repeats} s={stride} does not fit "
                        f"{args.density_frames} frames in {bench.length}; skipped")
                    continue
                measure = args.measure_exhaustive == "all" or (repeats, stride) == (1, 1)
                row = bench.evaluate(variant, measure, seconds_per_pair=rate)
                if (repeats, stride) == (1, 1):
                    rate = row["exhaustive_s"] / variant.num_pairs
                rows.append(row)
            rows.sort(key=lambda r: r["density"])
            results["density_sweep"] += rows
            results["breakdown"] += rows
        for flags in args.vocab_settings if name in args.settings_sets.split(",") else []:
            tag = "".join(c if c.isalnum() or c in ".-" else "_" for c in flags)[:60]
            row = bench.evaluate(bench.full, True, flags.split(), tag, strategies=["vocabtree"])
            results["settings"].append(row)
        write_outputs(args, results, started)
    # The recall table's whole-sequence rows double as breakdown rows; keep each once.
    seen, unique = set(), []
    for row in results["breakdown"]:
        key = (row["set"], row["variant"])
        if key not in seen:
            seen.add(key)
            unique.append(row)
    results["breakdown"] = unique
    results["meta"]["seconds"] = time.time() - started
    text = write_outputs(args, results, started)
    gm_report.plot_all(results, args.out)
    print(text)
    log(f"done in {(time.time() - started) / 60:.1f} min; results in {args.out}")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Matching time against the number of views at constant density, per pairing strategy (the
thesis' Figure 6.2, issue 39).

    bench/scale/views.py --database DIR/10k_out/database.db --workdir DIR/views \
        [--views 125,250,500,1000,2451] [--strategies exhaustive:500,lowres:1000,vocabtree]
        [--loopsfm build/loopsfm]

For the thesis' 4,500 views: `scale.py render --sizes 21k-avenue`, then `loopsfm extract
DIR/21k-avenue/video.mp4 -d DB` (about 4,500 keyframes) and this script with `--database DB
--views 125,250,500,1000,2000,4508`.

The views are the first N frames of one extracted database (a `bench/scale/scale.py` walk:
adaptive keyframes, so the frames stand at the same spacing whatever N is). For each N the
script writes a database of those frames alone, without any matches, runs
`loopsfm match --pairs STRATEGY` on it, and reads the stage's JSON report: pairs matched and
verified, and the stage's time (loading the features included). `STRATEGY:MAX` runs that
strategy up to MAX views only (exhaustive matching grows with the square of the views).
Prints a Markdown table, the fitted exponents (seconds ~ views^k, least squares on log-log)
and writes WORKDIR/views.json. Standard library only.
"""

import argparse
import json
import sqlite3
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "vs_colmap"))
from vsc_tools import fit_exponent, fmt, log, run_measured  # noqa: E402


def subset_database(source, views, target):
    """A database holding the first `views` frames of `source` (lowest image ids), with its
    cameras and extraction records and no matches: built table by table, so a small subset of
    a large database costs what the subset holds."""
    if target.exists():
        target.unlink()
    db = sqlite3.connect(target)
    db.execute("ATTACH DATABASE ? AS src", (str(source),))
    ids = [row[0] for row in db.execute("SELECT image_id FROM src.images ORDER BY image_id")]
    if len(ids) < views:
        db.close()
        raise SystemExit(f"{source} holds {len(ids)} frames, fewer than the {views} asked for")
    last = ids[views - 1]
    schema = db.execute("SELECT type, name, sql FROM src.sqlite_master WHERE sql IS NOT NULL "
                        "AND name NOT LIKE 'sqlite_%' ORDER BY type = 'index'").fetchall()
    for kind, name, sql in schema:
        db.execute(sql)
        if kind != "table" or name in ("matches", "two_view_geometries"):
            continue
        columns = [row[1] for row in db.execute(f"PRAGMA src.table_info({name})")]
        where = " WHERE image_id <= ?" if "image_id" in columns else ""
        db.execute(f"INSERT INTO main.{name} SELECT * FROM src.{name}{where}",
                   (last,) if where else ())
    db.execute("DELETE FROM main.loopsfm_meta WHERE key = 'match_fingerprint'")
    db.commit()
    db.close()


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--database", type=Path, required=True)
    parser.add_argument("--workdir", type=Path, required=True)
    parser.add_argument("--views", default="125,250,500,1000,2451")
    parser.add_argument("--strategies", default="exhaustive:500,lowres:1000,vocabtree")
    parser.add_argument("--loopsfm", type=Path,
                        default=Path(__file__).resolve().parents[2] / "build" / "loopsfm")
    args = parser.parse_args()
    args.workdir.mkdir(parents=True, exist_ok=True)
    views = sorted(int(v) for v in args.views.split(","))
    strategies = []
    for item in args.strategies.split(","):
        name, _, most = item.partition(":")
        strategies.append((name, int(most) if most else max(views)))

    results_path = args.workdir / "views.json"
    results = json.loads(results_path.read_text()) if results_path.exists() else []
    for n in views:
        for name, most in strategies:
            if n > most:
                continue
            db = args.workdir / f"{name}_{n}.db"
            subset_database(args.database, n, db)
            report = args.workdir / f"{name}_{n}.json"
            cmd = [args.loopsfm, "match", "-d", db, "--pairs", name, "--json-report", report]
            log(f"{name} {n}: {' '.join(str(c) for c in cmd)}")
            proc = run_measured(cmd, args.workdir / f"{name}_{n}.log")
            db.unlink()
            if proc["rc"] != 0:
                log(f"{name} {n}: exit {proc['rc']}, see {args.workdir / f'{name}_{n}.log'}")
                continue
            r = json.loads(report.read_text())
            row = {"strategy": name, "views": n, "seconds": r["seconds"],
                   "pairs": r["num_pairs_matched"], "verified": r["num_pairs_verified"],
                   "kernel": r.get("kernel"), "peak_mib": proc["peak_mib"]}
            results = [x for x in results if (x["strategy"], x["views"]) != (name, n)] + [row]
            results_path.write_text(json.dumps(results, indent=1))
            log(f"{name} {n}: {row['seconds']:.1f} s, {row['pairs']} pairs, "
                f"{row['verified']} verified")

    print("| strategy | views | pairs matched | verified | match s | ms per pair | peak MiB |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for row in sorted(results, key=lambda x: (x["strategy"], x["views"])):
        per_pair = 1000.0 * row["seconds"] / row["pairs"] if row["pairs"] else None
        print(f"| {row['strategy']} | {row['views']} | {row['pairs']} | {row['verified']} | "
              f"{fmt(row['seconds'])} | {fmt(per_pair, 2)} | {fmt(row['peak_mib'], 0)} |")
    print()
    print("| strategy | exponent (s ~ views^k) | views fitted |")
    print("|---|---:|---|")
    for name in sorted({x["strategy"] for x in results}):
        rows = sorted((x for x in results if x["strategy"] == name), key=lambda x: x["views"])
        k = fit_exponent([x["views"] for x in rows], [x["seconds"] for x in rows])
        print(f"| {name} | {fmt(k, 2)} | {', '.join(str(x['views']) for x in rows)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

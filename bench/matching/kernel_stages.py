#!/usr/bin/env python3
"""The match stage with every matching kernel this CPU runs, on the same frames (issue 39).

Extracts INPUT once (`loopsfm extract`), then runs `loopsfm match --match-kernel K` on a copy
of that database for each kernel (those the CPU lacks are skipped), one after the other (alternating the kernels when --rounds
R > 1, medians reported), and checks that every kernel stored the same matches and two-view
geometries (a hash of the tables). Prints a Markdown table: match-stage seconds, median ms of
descriptor matching and of verification per pair, and the speed-up over the float kernel.

    bench/matching/kernel_stages.py INPUT --workdir DIR [--intrinsics FILE] [--rounds R]
        [--kernels avx512-vnni,avx2,neon-dotprod,neon,float] [--loopsfm build/loopsfm]

Standard library only.
"""

import argparse
import hashlib
import re
import shutil
import sqlite3
import statistics
import subprocess
import sys
import time
from pathlib import Path

MATCH_LINE = re.compile(r"median ([0-9.]+) ms matching \+ ([0-9.]+) ms verification per pair; "
                        r"([0-9.]+) s")
ALL_KERNELS = ("avx512-vnni", "avx2", "neon-dotprod", "neon", "float")


def table_hash(db):
    h = hashlib.sha1()
    with sqlite3.connect(db) as con:
        for table in ("matches", "two_view_geometries"):
            for row in con.execute(f"SELECT * FROM {table} ORDER BY pair_id"):
                h.update(repr(row).encode())
    return h.hexdigest()[:16]


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("input", type=Path)
    parser.add_argument("--workdir", type=Path, required=True)
    parser.add_argument("--intrinsics", type=Path)
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--kernels", default="")
    parser.add_argument("--loopsfm", type=Path,
                        default=Path(__file__).resolve().parents[2] / "build" / "loopsfm")
    args = parser.parse_args(argv)
    if not args.input.exists() or not args.loopsfm.exists() or args.rounds < 1:
        print("kernel_stages.py: input or loopsfm missing, or rounds < 1", file=sys.stderr)
        return 2
    args.workdir.mkdir(parents=True, exist_ok=True)
    base = args.workdir / "extracted.db"
    if not base.exists():
        cmd = [str(args.loopsfm), "extract", str(args.input), "-d", str(base), "-q"]
        if args.intrinsics:
            cmd += ["--intrinsics", str(args.intrinsics)]
        start = time.monotonic()
        if subprocess.run(cmd).returncode != 0:
            return 1
        print(f"extract: {time.monotonic() - start:.1f} s", file=sys.stderr)
    kernels = [k for k in args.kernels.split(",") if k] or list(ALL_KERNELS)
    results = {k: [] for k in kernels}
    hashes = {}
    for r in range(args.rounds):
        for kernel in [k for k in kernels if k in results]:
            db = args.workdir / f"{kernel}.db"
            for suffix in ("", "-wal", "-shm"):
                Path(str(db) + suffix).unlink(missing_ok=True)
            shutil.copy(base, db)
            proc = subprocess.run([str(args.loopsfm), "match", "-d", str(db), "--match-kernel",
                                   kernel], capture_output=True, text=True)
            m = MATCH_LINE.search(proc.stdout + proc.stderr)
            if proc.returncode == 2 and "does not run on this CPU" in proc.stderr:
                print(f"{kernel}: not on this CPU; skipped", file=sys.stderr)
                results.pop(kernel, None)
                continue
            if proc.returncode != 0 or not m:
                print(f"{kernel}: match failed:\n{proc.stderr[-2000:]}", file=sys.stderr)
                return 1
            results[kernel].append(tuple(float(v) for v in m.groups()))
            hashes[kernel] = table_hash(db)
            print(f"round {r + 1} {kernel}: {m.group(3)} s", file=sys.stderr)
    med = {k: tuple(statistics.median(v[i] for v in runs) for i in range(3))
           for k, runs in results.items() if runs}
    same = len(set(hashes.values())) == 1
    print(f"| kernel | match stage s | ms matching / pair | ms verification / pair | "
          f"speed-up of the stage over float | matches |")
    print("|---|---:|---:|---:|---:|---|")
    for k, (match_ms, verify_ms, seconds) in med.items():
        speedup = med["float"][2] / seconds if "float" in med else None
        print(f"| {k} | {seconds:.1f} | {match_ms:.1f} | {verify_ms:.1f} | "
              f"{'-' if speedup is None else f'{speedup:.2f}x'} | "
              f"{'identical' if same else hashes[k]} |")
    print(f"\n{args.rounds} round(s), medians; kernels run one after the other.")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

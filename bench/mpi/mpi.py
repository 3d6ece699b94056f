#!/usr/bin/env python3
"""Extraction and matching shared between MPI ranks (mpirun -np R loopsfm extract|match),
side by side with one process, on one machine.

For each rank count R (1 is one process, without mpirun) the stages run --runs times into a
fresh database; the table gives the median times, the frames and pairs each rank computed,
and whether the database is the same as the one-process database (every frame, keypoint,
descriptor, raw match and two-view geometry, compared byte for byte).

On one machine the speed-up is bounded by its cores: R ranks of T threads each share them.
So the script also reports what the stages cost per frame and per pair, the part rank 0
does alone (decoding and keyframe choice; pairing, reading features, writing results), the
bytes that travel per frame and per pair, and from those a model of the time on a cluster
of M machines like this one (M = 8, 32): T(M) = serial + max(parallel / M, bytes / link),
with the link speed of --link-gbps.

  bench/mpi/mpi.py INPUT [--ranks 1,2,4] [--threads 0] [--runs 3] [--out DIR]
      [--loopsfm build/loopsfm] [--link-gbps 10] [-- EXTRA EXTRACT FLAGS]
"""
import argparse
import hashlib
import json
import os
import shutil
import sqlite3
import statistics
import subprocess
import sys
import time

MPIRUN_ENV = {'OMPI_ALLOW_RUN_AS_ROOT': '1', 'OMPI_ALLOW_RUN_AS_ROOT_CONFIRM': '1',
              'OMPI_MCA_btl_vader_single_copy_mechanism': 'none'}


def launcher(ranks):
    return [] if ranks == 1 else ['mpirun', '-np', str(ranks), '--oversubscribe']


def run(cmd):
    start = time.monotonic()
    result = subprocess.run(cmd, capture_output=True, text=True,
                            env={**os.environ, **MPIRUN_ENV})
    if result.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({result.returncode}):\n{result.stderr[-3000:]}")
    return time.monotonic() - start


def digest(database):
    """A hash of what the stages stored (not of the file: SQLite's pages may differ)."""
    h = hashlib.sha256()
    con = sqlite3.connect(database)
    for table, key in (('cameras', 'camera_id'), ('images', 'image_id'),
                       ('keypoints', 'image_id'), ('descriptors', 'image_id'),
                       ('matches', 'pair_id'), ('two_view_geometries', 'pair_id')):
        for row in con.execute(f'SELECT * FROM {table} ORDER BY {key}'):
            h.update(repr(row).encode())
    con.close()
    return h.hexdigest()


def model(serial, parallel, bytes_total, machines, link_gbps):
    return serial + max(parallel / machines, bytes_total * 8 / (link_gbps * 1e9))


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('input')
    parser.add_argument('--ranks', default='1,2,4')
    parser.add_argument('--threads', type=int, default=0,
                        help='threads per rank (0: the cores shared between the ranks)')
    parser.add_argument('--runs', type=int, default=3)
    parser.add_argument('--out', default='mpi_out')
    parser.add_argument('--loopsfm', default='build/loopsfm')
    parser.add_argument('--link-gbps', type=float, default=10.0)
    parser.add_argument('extra', nargs='*', help='more extract flags (after --)')
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rows = []
    reference = None
    for ranks in [int(r) for r in args.ranks.split(',')]:
        times = {'extract': [], 'match': []}
        for k in range(args.runs):
            db = os.path.join(args.out, f'ranks{ranks}.db')
            for path in (db, db + '-journal'):
                if os.path.exists(path):
                    os.remove(path)
            ex_json = os.path.join(args.out, f'extract{ranks}.json')
            ma_json = os.path.join(args.out, f'match{ranks}.json')
            base = launcher(ranks) + [args.loopsfm, '--threads', str(args.threads), '-q']
            times['extract'].append(run(base + ['extract', args.input, '-d', db,
                                                '--json-report', ex_json] + args.extra))
            times['match'].append(run(base + ['match', '-d', db, '--json-report', ma_json]))
        ex, ma = json.load(open(ex_json)), json.load(open(ma_json))
        same = digest(db)
        if reference is None:
            reference = same
        rows.append({'ranks': ranks, 'extract_s': statistics.median(times['extract']),
                     'match_s': statistics.median(times['match']), 'extract': ex, 'match': ma,
                     'same_database': same == reference, 'database': db})
        print(json.dumps(rows[-1]), flush=True)

    print('\n| ranks | extract s | match s | frames per rank | pairs per rank | '
          'same database as one process |')
    print('|---:|---:|---:|---|---|---|')
    one = rows[0]
    for r in rows:
        print(f"| {r['ranks']} | {r['extract_s']:.1f} ({one['extract_s'] / r['extract_s']:.2f}x) | "
              f"{r['match_s']:.1f} ({one['match_s'] / r['match_s']:.2f}x) | "
              f"{' / '.join(map(str, r['extract']['frames_per_rank']))} | "
              f"{' / '.join(map(str, r['match']['pairs_per_rank']))} | "
              f"{'yes' if r['same_database'] else 'NO'} |")

    # Costs and the cluster model, from the one-process run.
    ex, ma = one['extract'], one['match']
    frames, pairs = max(ex['frames_extracted'], 1), max(ma['num_pairs_matched'], 1)
    con = sqlite3.connect(one['database'])
    width, height = con.execute('SELECT width, height FROM cameras LIMIT 1').fetchone()
    features = ex['num_features'] / frames
    con.close()
    vocab = ma['vocab']
    match_serial = (vocab['build_seconds'] + vocab['score_seconds'] + vocab['propose_seconds']
                    + ma['load_seconds'] + ma['store_seconds'])
    stages = {
        # SIFT input (grey, at most the frame's size) out, features (24 + 128 bytes each) back.
        'extract': (ex['decode_seconds'], one['extract_s'] - ex['decode_seconds'],
                    frames * (width * height + features * 152)),
        # Each pair's two frames' features out (an upper bound: a rank keeps what it has for
        # the batch), matches and geometry back.
        'match': (match_serial, one['match_s'] - match_serial, pairs * 2 * features * 152),
    }
    print(f"\nper frame: {1000 * one['extract_s'] / frames:.1f} ms extraction "
          f"({features:.0f} features); per pair: {1000 * one['match_s'] / pairs:.2f} ms matching "
          f"({pairs} pairs); {frames} frames of {width}x{height}")
    print(f'\n| stage | rank 0 alone s | shared part s | bytes sent | modelled s on 1 / 8 / 32 '
          f'machines ({args.link_gbps:g} Gb/s) |')
    print('|---|---:|---:|---:|---|')
    for name, (serial, parallel, sent) in stages.items():
        modelled = ' / '.join(f'{model(serial, parallel, sent, m, args.link_gbps):.1f}'
                              for m in (1, 8, 32))
        print(f'| {name} | {serial:.1f} | {parallel:.1f} | {sent / 1e6:.0f} MB | {modelled} |')


if __name__ == '__main__':
    main()

#!/usr/bin/env python3
"""The global mapper against the incremental one, side by side on the same databases.

For each set, the first run (incremental, `reconstruct`) builds the database; every mapping
run after it works on a copy of that database, so both mappers see the same matches. Each
mapper maps --runs times (no checkpoints: every run maps from the start); the table gives
the median mapping time (the incremental mapper's "map" stage, the sum of the global
mapper's "map: ..." stages) and the accuracy of the last run against ground truth: frames
registered, models, ATE as a fraction of the path, rotation error, loop gap.

  bench/global_mapper/global_mapper.py --set NAME INPUT GROUNDTRUTH INTRINSICS|- [--set ...]
      [--runs 3] [--out DIR] [--loopsfm build/loopsfm] [--threads 0]

INTRINSICS '-' maps without intrinsics (self-calibration).
"""
import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys


def report_stages(folder):
    """The stage times written into folder/report.html."""
    html = open(os.path.join(folder, 'report.html')).read()
    match = re.search(r'"stages":(\[[^\]]*\])', html)
    return {s['name']: s['seconds'] for s in json.loads(match.group(1))} if match else {}


def map_seconds(stages, mapper):
    if mapper == 'global':
        return sum(v for k, v in stages.items() if k.startswith('map: '))
    return stages.get('map', 0.0) + stages.get('map-again', 0.0)


def reconstruct(args, name, inp, intrinsics, folder, mapper, database=None):
    if os.path.exists(folder):
        shutil.rmtree(folder)
    os.makedirs(folder)
    if database:
        shutil.copy(database, os.path.join(folder, 'database.db'))
    cmd = [args.loopsfm, '--threads', str(args.threads), '-q', 'reconstruct', inp, '-o', folder,
           '--mapper', mapper, '--export', 'colmap,report']
    if mapper == 'incremental':
        cmd += ['--checkpoint-every', '0']
    if intrinsics != '-':
        cmd += ['--intrinsics', intrinsics]
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit(f'{name} {mapper}: loopsfm failed ({result.returncode}):\n{result.stderr[-2000:]}')
    return map_seconds(report_stages(folder), mapper)


def evaluate(args, folder, groundtruth):
    model = os.path.join(folder, 'sparse', '0')
    if not os.path.isdir(model):
        return None
    out = subprocess.run([args.loopsfm, 'eval', '--json', model, groundtruth],
                         capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f'eval of {model} failed ({out.returncode}):\n{out.stderr[-2000:]}')
    return json.loads(out.stdout)


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--set', nargs=4, action='append', required=True,
                        metavar=('NAME', 'INPUT', 'GROUNDTRUTH', 'INTRINSICS'))
    parser.add_argument('--runs', type=int, default=3)
    parser.add_argument('--out', default='global_mapper_out')
    parser.add_argument('--loopsfm', default='build/loopsfm')
    parser.add_argument('--threads', type=int, default=0)
    args = parser.parse_args()
    rows = []
    for name, inp, groundtruth, intrinsics in args.set:
        base = os.path.join(args.out, name)
        first = os.path.join(base, 'incremental_0')
        times = {'incremental': [reconstruct(args, name, inp, intrinsics, first, 'incremental')]}
        database = os.path.join(base, 'database.db')
        shutil.copy(os.path.join(first, 'database.db'), database)
        times['global'] = []
        for run in range(args.runs):
            for mapper in ('global', 'incremental'):
                if mapper == 'incremental' and run == 0:
                    continue  # the first run built the database
                folder = os.path.join(base, f'{mapper}_{run}')
                times[mapper].append(reconstruct(args, name, inp, intrinsics, folder, mapper,
                                                 database))
        for mapper in ('incremental', 'global'):
            metrics = evaluate(args, os.path.join(base, f'{mapper}_{args.runs - 1}'), groundtruth)
            rows.append((name, mapper, times[mapper], metrics))
            print(json.dumps({'set': name, 'mapper': mapper, 'map_seconds': times[mapper],
                              'metrics': metrics}), flush=True)
    print('\n| set | mapper | registered | map s (median) | ATE % of path | rotation mean / max deg '
          '| loop gap mean |')
    print('|---|---|---:|---:|---:|---:|---:|')
    for name, mapper, seconds, m in rows:
        if not m:
            print(f'| {name} | {mapper} | no model | {statistics.median(seconds):.1f} | | | |')
            continue
        gap = m.get('loop_gaps', {}).get('mean')
        print(f"| {name} | {mapper} | {m['num_estimated']} / {m['num_gt_frames']} | "
              f"{statistics.median(seconds):.1f} | {100 * m['ate_fraction_of_path']:.4f} | "
              f"{m['rotation_error_mean_deg']:.3f} / {m['rotation_error_max_deg']:.3f} | "
              f"{'' if gap is None else f'{gap:.4g}'} |")


if __name__ == '__main__':
    main()

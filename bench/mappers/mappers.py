#!/usr/bin/env python3
"""The mappers side by side on the same databases: the incremental mapper, the global one,
and the incremental mapper on segments of the video.

For each set, the first run (incremental, `reconstruct`) builds the database; every mapping
run after it works on a copy of that database, so every configuration sees the same
matches. Each configuration maps --runs times (no checkpoints: every run maps from the
start); the table gives the median mapping time (the incremental mapper's "map" stage, the
sum of the "map: ..." stages of the global mapper and of segments) and the accuracy of the
last run against ground truth: frames registered, models, ATE as a fraction of the path,
rotation error, loop gap.

  bench/mappers/mappers.py --set NAME INPUT GROUNDTRUTH INTRINSICS|- [--set ...]
      [--configs incremental,global,segments:4] [--runs 3] [--out DIR]
      [--loopsfm build/loopsfm] [--threads 0]

INTRINSICS '-' maps without intrinsics (self-calibration). A configuration is incremental,
global, or segments:N (the incremental mapper on N segments, --segments N); a suffix @R runs
it under `mpirun -np R` (segments:4@2: four segments mapped on two ranks).
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


def map_seconds(stages):
    """The mapping stages: "map" (and "map-again"), or the "map: ..." stages."""
    return sum(v for k, v in stages.items()
               if k in ('map', 'map-again') or k.startswith('map: '))


MPIRUN_ENV = {'OMPI_ALLOW_RUN_AS_ROOT': '1', 'OMPI_ALLOW_RUN_AS_ROOT_CONFIRM': '1',
              'OMPI_MCA_btl_vader_single_copy_mechanism': 'none'}


def config_ranks(config):
    """The configuration without its @R suffix, and R (1 without one)."""
    name, _, ranks = config.partition('@')
    if ranks and not ranks.isdigit():
        sys.exit(f"configuration '{config}': the ranks after @ must be a number")
    return name, int(ranks or 1)


def folder_name(config):
    return config.replace(':', '_').replace('@', '_r')


def config_flags(config):
    """The reconstruct flags of a configuration."""
    config, _ = config_ranks(config)
    if config in ('incremental', 'global'):
        return ['--mapper', config]
    if config.startswith('segments:') and config[len('segments:'):].isdigit():
        return ['--mapper', 'incremental', '--segments', config[len('segments:'):]]
    sys.exit(f"configuration '{config}' is none of incremental, global, segments:N")


def reconstruct(args, name, inp, intrinsics, folder, config, database=None):
    if os.path.exists(folder):
        shutil.rmtree(folder)
    os.makedirs(folder)
    if database:
        shutil.copy(database, os.path.join(folder, 'database.db'))
    _, ranks = config_ranks(config)
    launcher = ['mpirun', '-np', str(ranks), '--oversubscribe'] if ranks > 1 else []
    cmd = launcher + [args.loopsfm, '--threads', str(args.threads), '-q', 'reconstruct', inp,
                      '-o', folder, '--export', 'colmap,report'] + config_flags(config)
    if config == 'incremental':
        cmd += ['--checkpoint-every', '0']
    if intrinsics != '-':
        cmd += ['--intrinsics', intrinsics]
    result = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, **MPIRUN_ENV})
    if result.returncode != 0:
        sys.exit(f'{name} {config}: loopsfm failed ({result.returncode}):\n{result.stderr[-2000:]}')
    return map_seconds(report_stages(folder))


def evaluate(args, folder, groundtruth):
    model = os.path.join(folder, 'sparse', '0')
    if not os.path.isdir(model):
        return None
    models = len([d for d in os.listdir(os.path.join(folder, 'sparse')) if d.isdigit()])
    out = subprocess.run([args.loopsfm, 'eval', '--json', model, groundtruth],
                         capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f'eval of {model} failed ({out.returncode}):\n{out.stderr[-2000:]}')
    metrics = json.loads(out.stdout)
    metrics['num_models'] = models
    return metrics


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--set', nargs=4, action='append', required=True,
                        metavar=('NAME', 'INPUT', 'GROUNDTRUTH', 'INTRINSICS'))
    parser.add_argument('--configs', default='incremental,global')
    parser.add_argument('--runs', type=int, default=3)
    parser.add_argument('--out', default='mappers_out')
    parser.add_argument('--loopsfm', default='build/loopsfm')
    parser.add_argument('--threads', type=int, default=0)
    args = parser.parse_args()
    configs = args.configs.split(',')
    for config in configs:
        config_flags(config)
    rows = []
    for name, inp, groundtruth, intrinsics in args.set:
        base = os.path.join(args.out, name)
        first = os.path.join(base, 'build_database')
        reconstruct(args, name, inp, intrinsics, first, 'incremental')
        database = os.path.join(base, 'database.db')
        shutil.copy(os.path.join(first, 'database.db'), database)
        times = {config: [] for config in configs}
        for run in range(args.runs):
            for config in configs:
                folder = os.path.join(base, f'{folder_name(config)}_{run}')
                times[config].append(reconstruct(args, name, inp, intrinsics, folder, config,
                                                 database))
        for config in configs:
            folder = os.path.join(base, f'{folder_name(config)}_{args.runs - 1}')
            metrics = evaluate(args, folder, groundtruth)
            rows.append((name, config, times[config], metrics))
            print(json.dumps({'set': name, 'config': config, 'map_seconds': times[config],
                              'metrics': metrics}), flush=True)
    print('\n| set | configuration | registered (model 0) | models | map s (median) | '
          'ATE % of path | rotation mean / max deg | loop gap mean |')
    print('|---|---|---:|---:|---:|---:|---:|---:|')
    for name, config, seconds, m in rows:
        if not m:
            print(f'| {name} | {config} | no model | 0 | {statistics.median(seconds):.1f} | | | |')
            continue
        gap = m.get('loop_gaps', {}).get('mean')
        print(f"| {name} | {config} | {m['num_estimated']} / {m['num_gt_frames']} | "
              f"{m['num_models']} | "
              f"{statistics.median(seconds):.1f} | {100 * m['ate_fraction_of_path']:.4f} | "
              f"{m['rotation_error_mean_deg']:.3f} / {m['rotation_error_max_deg']:.3f} | "
              f"{'' if gap is None else f'{gap:.4g}'} |")


if __name__ == '__main__':
    main()

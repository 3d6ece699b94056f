#!/usr/bin/env python3
"""Loop closing on one database: `--loop-closing none` against the other methods, side by side.

For each set the first run builds the database (frames, features, pairs); the other method
maps a copy of it, so all see the same matches. Intrinsics may be made wrong on purpose
(--focal-factor 1.04: focal 4 % too long, held fixed), which makes drift. Prints registered
frames, models, ATE (% of path), rotation error, loop gap (mean / max, ground-truth units),
map time (for COLMAP: its mapper's wall time), the loops closed and their time, and writes a
top view per set and method (OUT/<set>_top.png for posegraph, OUT/<set>_top_<method>.png for the
others: ground truth, the method's path with its loop links, none). Closing time is the pose
graph's and the split tracks' together.

  bench/loop_closing/loop_closing.py --set NAME INPUT GROUNDTRUTH INTRINSICS \\
      [--set ...] [--focal-factor F] [--withhold] [--methods none,posegraph[,split,both]]
      [--out DIR] [--loopsfm build/loopsfm] [--global] [--colmap [BINARY]]

--withhold maps without the pairs 50+ frames apart and adds them at the end
(`reconstruct --withhold-loop-pairs`), so drift grows unchecked until the loops are closed.

--global adds loopsfm's global mapper (`loopsfm map --mapper global`) on a copy of the same
database (same wrong intrinsics, held fixed): it closes loops through the loop pairs in its view
graph, all at once, so compare it with a run without --withhold. Its map time is the sum of its
`map: ...` stages.

--colmap adds COLMAP 3.8's mapper on a copy of the same database (same matches, same wrong
intrinsics held fixed: --Mapper.ba_refine_* 0). COLMAP has no withholding: it always sees the
loop pairs while mapping, so compare it with a run without --withhold. Video input is decoded
to frame_%06d.png (the names loopsfm gives video frames) for it.
"""
import argparse
import json
import os
import re
import shutil
import sqlite3
import struct
import subprocess
import sys
import time


def scaled_intrinsics(src, dst, factor):
    """Writes the intrinsics file with fx, fy (or f) times factor."""
    line = [l for l in open(src) if l.strip() and not l.startswith('#')][0].split()
    model, values = line[0], [float(v) for v in line[3:]]
    n_focal = 2 if model in ('PINHOLE', 'OPENCV', 'FULL_OPENCV', 'OPENCV_FISHEYE') else 1
    for k in range(n_focal):
        values[k] *= factor
    with open(dst, 'w') as f:
        f.write(' '.join(line[:3] + [repr(v) for v in values]) + '\n')
    return values


def set_database_camera(db, params):
    """Resumed runs keep the database's camera: write the (wrong) parameters into it."""
    con = sqlite3.connect(db)
    for camera_id, blob in list(con.execute('select camera_id, params from cameras')):
        old = struct.unpack('%dd' % (len(blob) // 8), blob)
        new = list(params) + list(old[len(params):])
        con.execute('update cameras set params=? where camera_id=?',
                    (struct.pack('%dd' % len(new), *new), camera_id))
    con.commit()
    con.close()


def copy_database(src, dst):
    """A consistent copy, write-ahead log included."""
    source = sqlite3.connect(src)
    target = sqlite3.connect(dst)
    source.backup(target)
    target.close()
    source.close()


def run(cmd, log):
    start = time.time()
    with open(log, 'w') as f:
        rc = subprocess.call(cmd, stdout=f, stderr=subprocess.STDOUT)
    if rc != 0:
        sys.exit(f'failed ({rc}): {" ".join(cmd)}; see {log}')
    return time.time() - start


def summary(log):
    text = open(log).read()
    map_s = re.search(r'time map\s+([\d.]+) s', text)
    loops = re.findall(r'loop closed\s+(.*)', text)
    # The closing time of all loops (those found after mapping are corrected together).
    closing = re.search(r'loop closing\s+detection [\d.]+ s, \d+ closed \(([\d.]+) s\)', text)
    loop_s = float(closing.group(1)) if closing else 0.0
    split = re.search(r'split tracks\s+\d+ pairs tied.*, ([\d.]+) s$', text, re.M)
    loop_s += float(split.group(1)) if split else 0.0
    models = len(re.findall(r'^model \d+ \(', text, re.M))
    return float(map_s.group(1)) if map_s else float('nan'), loops, loop_s, models


def run_global_mapper(loopsfm, media, base):
    """loopsfm's global mapper on a copy of the none run's database. Returns (its model
    folders, the sum of its mapping stages in seconds)."""
    out = f'{base}_global'
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)
    copy_database(f'{base}_none/database.db', os.path.join(out, 'database.db'))
    run([loopsfm, 'map', '-d', os.path.join(out, 'database.db'), '-o', out, '--input', media,
         '--mapper', 'global', '--export', 'colmap'], out + '.log')
    seconds = sum(float(t) for t in
                  re.findall(r'^time map: .*?\s([\d.]+) s$', open(out + '.log').read(), re.M))
    if re.search(r'^time map: incremental', open(out + '.log').read(), re.M):
        print(f'the global mapper found its path likely bent or broken and handed the video to '
              f'the incremental mapper: the global column is that mapper\'s model, in the time '
              f'of both (see {out}.log)', file=sys.stderr)
    sparse = os.path.join(out, 'sparse')
    models = [os.path.join(sparse, d) for d in sorted(os.listdir(sparse))] if os.path.isdir(sparse) else []
    if not models:
        sys.exit(f'the global mapper made no model; see {out}.log')
    return models, seconds


def run_colmap_mapper(colmap, media, base):
    """COLMAP's mapper on a copy of the none run's database. Returns (its model folders, the
    mapper's wall seconds)."""
    out = f'{base}_colmap'
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(os.path.join(out, 'sparse'))
    copy_database(f'{base}_none/database.db', os.path.join(out, 'database.db'))
    images = media
    if not os.path.isdir(media):
        images = os.path.join(out, 'frames')
        os.makedirs(images)
        run(['ffmpeg', '-nostdin', '-loglevel', 'error', '-i', media, '-start_number', '0',
             os.path.join(images, 'frame_%06d.png')], out + '_ffmpeg.log')
    seconds = run([colmap, 'mapper', '--database_path', os.path.join(out, 'database.db'),
                   '--image_path', images, '--output_path', os.path.join(out, 'sparse'),
                   '--Mapper.ba_refine_focal_length', '0', '--Mapper.ba_refine_principal_point', '0',
                   '--Mapper.ba_refine_extra_params', '0'], out + '.log')
    models = [os.path.join(out, 'sparse', d) for d in sorted(os.listdir(os.path.join(out, 'sparse')))]
    if not models:
        sys.exit(f'COLMAP made no model; see {out}.log')
    return models, seconds


def evaluate(loopsfm, model, gt):
    out = subprocess.check_output([loopsfm, 'eval', model, gt, '--json'])
    return json.loads(out)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--set', nargs=4, action='append', required=True,
                        metavar=('NAME', 'INPUT', 'GROUNDTRUTH', 'INTRINSICS'))
    parser.add_argument('--focal-factor', type=float, default=1.0)
    parser.add_argument('--withhold', action='store_true',
                        help='withhold the loop pairs until the end of mapping')
    parser.add_argument('--methods', default='none,posegraph',
                        help='loop-closing methods to map with, comma-separated; none comes '
                             'first (it builds the database the others copy)')
    parser.add_argument('--out', default='loop_closing_out')
    parser.add_argument('--loopsfm', default='build/loopsfm')
    parser.add_argument('--global', dest='global_mapper', action='store_true',
                        help="also run loopsfm's global mapper on the same database")
    parser.add_argument('--colmap', nargs='?', const='colmap', default=None, metavar='BINARY',
                        help="also run COLMAP 3.8's mapper on the same database")
    args = parser.parse_args()
    methods = ['none'] + [m for m in args.methods.split(',') if m and m != 'none']
    for m in methods:
        if m not in ('none', 'posegraph', 'split', 'both'):
            parser.error(f'--methods: unknown loop-closing method {m!r} '
                         '(none, posegraph, split, both)')
    os.makedirs(args.out, exist_ok=True)
    rows = []
    for name, media, gt, intrinsics in args.set:
        base = os.path.join(args.out, name)
        intr = base + '.intrinsics.txt'
        params = scaled_intrinsics(intrinsics, intr, args.focal_factor)
        outputs = {}
        for method in methods:
            out = f'{base}_{method}'
            if method != 'none':
                shutil.rmtree(out, ignore_errors=True)
                os.makedirs(out)
                copy_database(f'{base}_none/database.db', os.path.join(out, 'database.db'))
            elif os.path.exists(os.path.join(out, 'database.db')):
                set_database_camera(os.path.join(out, 'database.db'), params)
                shutil.rmtree(os.path.join(out, 'sparse'), ignore_errors=True)
            run([args.loopsfm, 'reconstruct', media, '-o', out, '--intrinsics', intr,
                 '--loop-closing', method] + (['--withhold-loop-pairs'] if args.withhold else []),
                out + '.log')
            outputs[method] = out
            map_s, loops, loop_s, models = summary(out + '.log')
            m = evaluate(args.loopsfm, os.path.join(out, 'sparse', '0'), gt)
            gaps = m.get('loop_gaps') or {}
            rows.append((name, method, m['num_matched'], m['num_gt_frames'], models,
                         100 * (m['ate_fraction_of_path'] or float('nan')),
                         m['rotation_error_mean_deg'], gaps.get('mean'), gaps.get('max'),
                         map_s, len(loops), loop_s))
        others = []
        if args.global_mapper:
            others.append(('loopsfm global mapper (loop pairs in the view graph)',
                           run_global_mapper(args.loopsfm, media, base)))
        if args.colmap:
            others.append(('COLMAP 3.8 mapper (loop pairs while mapping)',
                           run_colmap_mapper(args.colmap, media, base)))
        for label, (models, seconds) in others:
            m = max((evaluate(args.loopsfm, model, gt) for model in models),
                    key=lambda e: e['num_matched'])
            gaps = m.get('loop_gaps') or {}
            rows.append((name, label, m['num_matched'], m['num_gt_frames'], len(models),
                         100 * (m['ate_fraction_of_path'] or float('nan')),
                         m['rotation_error_mean_deg'], gaps.get('mean'), gaps.get('max'),
                         seconds, None, None))
        for method in methods[1:]:
            suffix = '' if method == 'posegraph' else '_' + method
            subprocess.check_call([args.loopsfm, 'eval', os.path.join(outputs[method], 'sparse', '0'),
                                   gt, '--plot', f'{base}_top{suffix}.png', '--plot-also',
                                   os.path.join(outputs['none'], 'sparse', '0'), '--plot-links',
                                   os.path.join(outputs[method], 'loop_links.txt')],
                                  stdout=subprocess.DEVNULL)
    print(f'focal factor {args.focal_factor}, loop pairs {"withheld until the end" if args.withhold else "used while mapping"}')
    print('| set | loop closing | frames | models | ATE % path | rot. err deg | loop gap mean | '
          'loop gap max | map s | loops closed | closing s |')
    print('|---|---|---|---|---|---|---|---|---|---|---|')
    fmt = lambda v, f: 'n/a' if v is None else format(v, f)
    for r in rows:
        print(f'| {r[0]} | {r[1]} | {r[2]}/{r[3]} | {r[4]} | {r[5]:.4f} | {r[6]:.3f} | '
              f'{fmt(r[7], ".4g")} | {fmt(r[8], ".4g")} | {r[9]:.1f} | {fmt(r[10], "d")} | '
              f'{fmt(r[11], ".1f")} |')


if __name__ == '__main__':
    main()

#!/usr/bin/env python3
"""How many observations of a database's feature tracks are wrong, judged by ground truth.

The tracks are built as the mappers build them before any mapping: the union of every
verified pair's inlier matches. Each track is triangulated from the ground-truth poses, its
point chosen among the midpoints of pairs of its rays as the one most of its rays pass within
--max-angle degrees of; an observation whose ray passes further from that point is wrong (a
match to a look-alike: on a street of identical buildings, the twin of the feature on the
next building). Tracks that hold two keypoints of one frame are counted apart (the mappers
split or drop them). docs/global_mapper gives the figures for the repeated-facades walk.

  bench/mappers/track_errors.py DATABASE GROUNDTRUTH [--max-angle 1.0] [--wrong OUT.txt]

GROUNDTRUTH: 'name tx ty tz qx qy qz qw' per line, camera-to-world, OpenCV camera axes (the
format `loopsfm eval` reads); frames are matched by file name without extension. Pinhole
cameras only (COLMAP models SIMPLE_PINHOLE and PINHOLE), as the rendered sets use. --wrong
writes each wrong observation as 'image_id point2D_idx'.
"""
import argparse
import random
import sqlite3
import sys
from collections import defaultdict

import numpy as np

PAIR_ID_FACTOR = 2147483647  # COLMAP's pair_id = id1 * factor + id2


def rotation_from_quaternion(x, y, z, w):
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def stem(name):
    return name.split('/')[-1].rsplit('.', 1)[0]


def read_groundtruth(path):
    poses = {}
    for line in open(path):
        fields = line.split()
        if len(fields) < 8 or line.startswith('#'):
            continue
        v = [float(x) for x in fields[1:8]]
        poses[stem(fields[0])] = (np.array(v[:3]), rotation_from_quaternion(*v[3:]))
    return poses


def read_cameras(db):
    cameras = {}
    for camera_id, model, params in db.execute('select camera_id, model, params from cameras'):
        p = np.frombuffer(params, dtype=np.float64)
        if model == 0:  # SIMPLE_PINHOLE f, cx, cy
            cameras[camera_id] = (p[0], p[0], p[1], p[2])
        elif model == 1:  # PINHOLE fx, fy, cx, cy
            cameras[camera_id] = tuple(p[:4])
        else:
            sys.exit(f'camera {camera_id} has COLMAP model {model}; only pinhole cameras (0, 1)')
    return cameras


def build_tracks(db):
    parent = {}

    def find(a):
        while parent.setdefault(a, a) != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for pair_id, rows, data in db.execute(
            'select pair_id, rows, data from two_view_geometries where rows > 0'):
        id2 = pair_id % PAIR_ID_FACTOR
        id1 = (pair_id - id2) // PAIR_ID_FACTOR
        for a, b in np.frombuffer(data, dtype=np.uint32).reshape(rows, 2):
            ra, rb = find((id1, int(a))), find((id2, int(b)))
            if ra != rb:
                parent[ra] = rb
    tracks = defaultdict(list)
    for element in list(parent):
        tracks[find(element)].append(element)
    return list(tracks.values())


def best_point(rays, max_angle_deg, rng, max_pairs=60):
    """Angles (deg) of every ray from the midpoint most rays agree with; None without one."""
    n = len(rays)
    pairs = [(a, b) for a in range(n) for b in range(a + 1, n)]
    if len(pairs) > max_pairs:
        pairs = rng.sample(pairs, max_pairs)
    best = None
    for a, b in pairs:
        (c1, d1), (c2, d2) = rays[a], rays[b]
        if d1 @ d2 > np.cos(np.radians(1.0)):  # under 1 deg of parallax
            continue
        lhs = np.array([[d1 @ d1, -d1 @ d2], [d1 @ d2, -d2 @ d2]])
        s1, s2 = np.linalg.solve(lhs, np.array([(c2 - c1) @ d1, (c2 - c1) @ d2]))
        if s1 <= 0 or s2 <= 0:
            continue
        x = (c1 + s1 * d1 + c2 + s2 * d2) / 2
        angles = [np.degrees(np.arccos(np.clip((x - c) @ d / np.linalg.norm(x - c), -1, 1)))
                  for c, d in rays]
        agree = sum(angle < max_angle_deg for angle in angles)
        if best is None or agree > best[0]:
            best = (agree, angles)
    return None if best is None else best[1]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('database')
    parser.add_argument('groundtruth')
    parser.add_argument('--max-angle', type=float, default=1.0,
                        help='degrees a right observation\'s ray may pass from the point')
    parser.add_argument('--wrong', help='write the wrong observations here')
    args = parser.parse_args()

    db = sqlite3.connect(args.database)
    truth = read_groundtruth(args.groundtruth)
    cameras = read_cameras(db)
    images = {i: (stem(n), c) for i, n, c in db.execute('select image_id, name, camera_id from images')}
    keypoints = {i: np.frombuffer(d, dtype=np.float32).reshape(r, c)[:, :2].astype(float)
                 for i, r, c, d in db.execute('select image_id, rows, cols, data from keypoints')}
    missing = sorted(n for n, _ in images.values() if n not in truth)
    if missing:
        sys.exit(f'{len(missing)} frames have no ground-truth pose, e.g. {missing[0]}')

    def ray(observation):
        image_id, point2d = observation
        name, camera_id = images[image_id]
        fx, fy, cx, cy = cameras[camera_id]
        x, y = keypoints[image_id][point2d]
        centre, world_from_cam = truth[name]
        d = world_from_cam @ np.array([(x - cx) / fx, (y - cy) / fy, 1.0])
        return centre, d / np.linalg.norm(d)

    rng = random.Random(1)
    wrong_out = open(args.wrong, 'w') if args.wrong else None
    count = defaultdict(int)
    for track in build_tracks(db):
        if len(track) < 3:
            continue
        if len({image_id for image_id, _ in track}) < len(track):
            count['conflicting tracks'] += 1
            continue
        angles = best_point([ray(o) for o in track], args.max_angle, rng)
        if angles is None:
            count['tracks without parallax'] += 1
            continue
        wrong = [o for o, angle in zip(track, angles) if angle >= args.max_angle]
        count['tracks'] += 1
        count['observations'] += len(track)
        count['wrong observations'] += len(wrong)
        count['tracks with a wrong observation'] += bool(wrong)
        if len(track) >= 10:
            count['tracks of 10+ frames'] += 1
            count['tracks of 10+ frames with a wrong observation'] += bool(wrong)
        if wrong_out:
            wrong_out.writelines(f'{i} {p}\n' for i, p in wrong)
    for key, value in count.items():
        print(f'{key:48s} {value}')
    if count['observations']:
        print(f'{"wrong observations, share":48s} '
              f'{100.0 * count["wrong observations"] / count["observations"]:.1f} %')
        print(f'{"tracks with a wrong observation, share":48s} '
              f'{100.0 * count["tracks with a wrong observation"] / count["tracks"]:.1f} %')
    if count['tracks of 10+ frames']:
        print(f'{"tracks of 10+ frames with a wrong one, share":48s} '
              f'{100.0 * count["tracks of 10+ frames with a wrong observation"] / count["tracks of 10+ frames"]:.1f} %')


if __name__ == '__main__':
    main()

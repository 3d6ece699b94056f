#!/usr/bin/env python3
"""Where does bundle adjustment itself put the path? A model's tracks, bundled from the truth.

Takes a finished model (its tracks and its intrinsics, for example a focal length held wrong on
purpose), replaces every camera's pose with the ground-truth pose, triangulates each track
again from those poses, and runs COLMAP 3.8's bundle adjuster on the result with the
intrinsics held fixed (plain least squares, no robust loss). The same adjuster also runs from
the model's own poses. Both results are scored with `loopsfm eval` beside the model.

If the bundle started from the truth ends with the same loop gap as the model, that gap is
where the least-squares fit of these observations with these intrinsics lies: no loop
closing that ends in a bundle adjustment of these tracks can remove it. If it ends well
below, the model sits in a worse minimum than it needs to.

  bench/loop_closing/ba_from_truth.py MODEL GROUNDTRUTH [--out DIR] [--iterations N]
      [--loopsfm build/loopsfm] [--colmap colmap]

MODEL is a COLMAP model folder (bin or txt); every registered frame must be in GROUNDTRUTH
('name tx ty tz qx qy qz qw' per line, camera-to-world; names joined without folders and
extension). Cameras: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL.
"""
import argparse
import os
import re
import subprocess
import sys

from loop_closing import evaluate as eval_metrics  # the bench script beside this one


def die(message):
    print('ba_from_truth: ' + message, file=sys.stderr)
    sys.exit(2)


def key(name):
    return os.path.splitext(os.path.basename(name))[0]


def rotation_from_quaternion(w, x, y, z):
    n = (w * w + x * x + y * y + z * z) ** 0.5
    w, x, y, z = w / n, x / n, y / n, z / n
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]


def quaternion_from_rotation(m):
    """(w, x, y, z) of a rotation matrix, from its largest diagonal term (Shepperd)."""
    trace = m[0][0] + m[1][1] + m[2][2]
    if trace >= max(m[0][0], m[1][1], m[2][2]):
        s = 2 * (1 + trace) ** 0.5
        return (s / 4, (m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s)
    i = max(range(3), key=lambda k: m[k][k])
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2 * (1 + m[i][i] - m[j][j] - m[k][k]) ** 0.5
    q = [0.0] * 4
    q[0] = (m[k][j] - m[j][k]) / s
    q[1 + i] = s / 4
    q[1 + j] = (m[j][i] + m[i][j]) / s
    q[1 + k] = (m[k][i] + m[i][k]) / s
    return tuple(q)


def mat_vec(m, v):
    return [sum(m[i][k] * v[k] for k in range(3)) for i in range(3)]


def transposed(m):
    return [[m[k][i] for k in range(3)] for i in range(3)]


def solve3(a, b):
    """a x = b for a 3x3 matrix (Cramer's rule); None when singular."""
    def det(m):
        return (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
    d = det(a)
    if abs(d) < 1e-15:
        return None
    out = []
    for c in range(3):
        m = [row[:] for row in a]
        for r in range(3):
            m[r][c] = b[r]
        out.append(det(m) / d)
    return out


def read_groundtruth(path):
    poses = {}
    for line in open(path):
        fields = line.split()
        if not fields or fields[0].startswith('#'):
            continue
        if len(fields) != 8:
            die(f'{path}: expected "name tx ty tz qx qy qz qw", got: {line.strip()}')
        tx, ty, tz, qx, qy, qz, qw = map(float, fields[1:])
        poses[key(fields[0])] = ([tx, ty, tz], rotation_from_quaternion(qw, qx, qy, qz))
    return poses


class Camera:
    def __init__(self, model, params):
        if model == 'SIMPLE_PINHOLE':
            self.fx = self.fy = params[0]
            self.cx, self.cy, self.k = params[1], params[2], []
        elif model == 'PINHOLE':
            self.fx, self.fy, self.cx, self.cy = params[:4]
            self.k = []
        elif model in ('SIMPLE_RADIAL', 'RADIAL'):
            self.fx = self.fy = params[0]
            self.cx, self.cy, self.k = params[1], params[2], params[3:]
        else:
            die(f'camera model {model} is not supported (SIMPLE_PINHOLE, PINHOLE, '
                'SIMPLE_RADIAL, RADIAL)')

    def ray(self, u, v):
        """Undistorted normalised image point of pixel (u, v) (fixed-point iteration)."""
        xd, yd = (u - self.cx) / self.fx, (v - self.cy) / self.fy
        x, y = xd, yd
        for _ in range(20 if self.k else 0):
            r2 = x * x + y * y
            factor = 1 + sum(k * r2 ** (i + 1) for i, k in enumerate(self.k))
            x, y = xd / factor, yd / factor
        return [x, y, 1.0]


def retriangulated_model(src, dst, truth):
    """Writes src (a TXT model) to dst with ground-truth poses and re-triangulated points."""
    cameras = {}
    for line in open(os.path.join(src, 'cameras.txt')):
        if line.startswith('#') or not line.strip():
            continue
        f = line.split()
        cameras[f[0]] = Camera(f[1], [float(p) for p in f[4:]])
    lines = [l.rstrip('\n') for l in open(os.path.join(src, 'images.txt')) if not l.startswith('#')]
    rays = {}  # point id -> [(centre, direction)]
    images_out = []
    missing = []
    for head, points in zip(lines[0::2], lines[1::2]):
        f = head.split()
        if len(f) < 10:
            continue
        name = f[9]
        if key(name) not in truth:
            missing.append(name)
            continue
        centre, world_from_cam = truth[key(name)]
        cam_from_world = transposed(world_from_cam)
        t = [-c for c in mat_vec(cam_from_world, centre)]
        # The quaternion of cam_from_world is the conjugate of world_from_cam's.
        w, x, y, z = quaternion_from_rotation(world_from_cam)
        p = points.split()
        images_out.append((' '.join([f[0]] + ['%.17g' % v for v in (w, -x, -y, -z)] +
                                    ['%.17g' % v for v in t] + f[8:]), p))
        camera = cameras[f[8]]
        for i in range(0, len(p) - 2, 3):
            if p[i + 2] == '-1':
                continue
            direction = mat_vec(world_from_cam, camera.ray(float(p[i]), float(p[i + 1])))
            n = sum(d * d for d in direction) ** 0.5
            rays.setdefault(p[i + 2], []).append((centre, [d / n for d in direction]))
    if missing:
        die(f'{len(missing)} registered frames have no ground truth (first: {missing[0]}): '
            'give the ground truth of every frame in the model')
    os.makedirs(dst, exist_ok=True)
    with open(os.path.join(dst, 'cameras.txt'), 'w') as out:
        out.writelines(l for l in open(os.path.join(src, 'cameras.txt')))
    kept, dropped = 0, set()
    with open(os.path.join(dst, 'points3D.txt'), 'w') as out:
        for line in open(os.path.join(src, 'points3D.txt')):
            if line.startswith('#') or not line.strip():
                continue
            f = line.split()
            track = rays.get(f[0], [])
            # Least squares over the rays: sum_i (I - d_i d_i^T) X = sum_i (I - d_i d_i^T) c_i.
            a = [[0.0] * 3 for _ in range(3)]
            b = [0.0] * 3
            for centre, d in track:
                for r in range(3):
                    for c in range(3):
                        p = (1.0 if r == c else 0.0) - d[r] * d[c]
                        a[r][c] += p
                        b[r] += p * centre[c]
            point = solve3(a, b) if len(track) >= 2 else None
            if point is None:  # parallel rays from the true poses: the point is left out
                dropped.add(f[0])
                continue
            kept += 1
            out.write(' '.join([f[0]] + ['%.17g' % v for v in point] + f[4:]) + '\n')
    with open(os.path.join(dst, 'images.txt'), 'w') as out:
        for head, p in images_out:
            for i in range(2, len(p), 3):
                if p[i] in dropped:
                    p[i] = '-1'
            out.write(head + '\n' + ' '.join(p) + '\n')
    return kept, len(dropped)


def bundle(colmap, src, dst, iterations, log):
    os.makedirs(dst, exist_ok=True)
    cmd = [colmap, 'bundle_adjuster', '--input_path', src, '--output_path', dst,
           '--BundleAdjustment.max_num_iterations', str(iterations),
           '--BundleAdjustment.function_tolerance', '1e-7',
           '--BundleAdjustment.refine_focal_length', '0',
           '--BundleAdjustment.refine_principal_point', '0',
           '--BundleAdjustment.refine_extra_params', '0']
    with open(log, 'w') as out:
        subprocess.check_call(cmd, stdout=out, stderr=subprocess.STDOUT)
    text = open(log).read()
    costs = re.findall(r'(Initial|Final) cost : ([0-9.eE+-]+) \[px\]', text)
    iterations_run = re.findall(r'Iterations : (\d+)', text)
    return {k: float(v) for k, v in costs}, int(iterations_run[-1]) if iterations_run else -1


def evaluate(loopsfm, model, groundtruth):
    metrics = eval_metrics(loopsfm, model, groundtruth)
    gaps = metrics.get('loop_gaps') or {}
    text = f"ATE {metrics['ate_fraction_of_path'] * 100:.4f} % of path"
    if gaps:
        text += (f", loop gap mean {gaps['mean']:.4g} max {gaps['max']:.4g} "
                 f"({gaps['max_first']} + {gaps['max_second']})")
    return text


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('model')
    parser.add_argument('groundtruth')
    parser.add_argument('--out', default='ba_from_truth')
    parser.add_argument('--iterations', type=int, default=60)
    parser.add_argument('--loopsfm', default='build/loopsfm')
    parser.add_argument('--colmap', default='colmap')
    args = parser.parse_args()
    for path in (args.model, args.groundtruth):
        if not os.path.exists(path):
            die(f'{path} does not exist')
    truth = read_groundtruth(args.groundtruth)
    os.makedirs(args.out, exist_ok=True)
    model_txt = os.path.join(args.out, 'model_txt')
    os.makedirs(model_txt, exist_ok=True)
    subprocess.check_call([args.colmap, 'model_converter', '--input_path', args.model,
                           '--output_path', model_txt, '--output_type', 'TXT'],
                          stdout=subprocess.DEVNULL)
    truth_txt = os.path.join(args.out, 'truth_start_txt')
    kept, dropped = retriangulated_model(model_txt, truth_txt, truth)
    print(f'{kept} tracks triangulated from the ground-truth poses ({dropped} could not be)')
    print(f"{'model:':24s} {evaluate(args.loopsfm, args.model, args.groundtruth)}")
    for label, start in (('from the model', model_txt), ('from the truth', truth_txt)):
        out = os.path.join(args.out, 'bundled_' + label.split()[-1])
        costs, iterations = bundle(args.colmap, start, out, args.iterations, out + '.log')
        print(f'bundled {label + ":":16s} {evaluate(args.loopsfm, out, args.groundtruth)}; '
              f"RMS reprojection {costs.get('Initial', float('nan')):.4f} -> "
              f"{costs.get('Final', float('nan')):.4f} px in {iterations} iterations")


if __name__ == '__main__':
    main()

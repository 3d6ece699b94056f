"""The sets of vs_colmap.py: shared data, synthetic scenes rendered by `loopsfm synth`, and the
frames COLMAP reads for videos. Standard library only; see README.md beside this file."""

import shlex
import shutil
import subprocess

from vsc_tools import log, run_measured

# Sets from the shared data: folder, source inside it, ground truth file, COLMAP's matcher.
# templeRing keeps COLMAP's exhaustive matcher: 47 photographs taken around an object are what
# COLMAP's documentation sends to exhaustive matching (up to a few hundred images); the others
# are videos or drives, for which COLMAP users pick its sequential matcher.
DATA_SETS = {
    "templeRing": ("templeRing", "images", "groundtruth.txt", "exhaustive"),
    "fox": ("fox", "images", "reference_poses.txt", "sequential"),
    "kitti07_160": ("kitti07_160", "images", "groundtruth.txt", "sequential"),
    "block": ("block", "block.mp4", "groundtruth.txt", "sequential"),
}

# Synthetic sets: the `loopsfm synth` command line after `synth` (without -o). A set renders
# into WORKDIR/SET/synth once and again only when this line changes; rendering is not timed.
# --synth-set NAME='ARGS' adds a set or replaces one of these.
SYNTH_SETS = {
    "cylinder": "cylinder --video --frames 150",
    "street": "street --frames 400",
    "street_turns": "street --route figure8 --look-ahead 25 --abrupt-turns --frames 400",
    "street_degraded": ("street --frames 400 --shake 0.5 --jitter 2 --noise 4 "
                        "--blur 100-110:15,250-255:30 --low-texture 180-190 --dark 300-301 "
                        "--jpeg-quality 70"),
    # An action camera: 96 degrees across the width, a barrel lens (run with --no-intrinsics to
    # compare self-calibration; the truth is SIMPLE_RADIAL 640 360 288 320 180 -0.07).
    "street_wide": ("street --video --frames 300 --width 640 --height 360 --focal-factor 0.45 "
                    "--look-ahead 30 --shake 1 --noise 1 --camera-model SIMPLE_RADIAL --k1 -0.07"),
    # Everything at once on a hand-held phone-like walk around two blocks: abrupt turns, blur
    # (30 px at frames 300-305, too much for SIFT: no blurred frame verifies with a sharp one,
    # in loopsfm or COLMAP), a washed-out stretch, noise, JPEG, and a barrel lens (truth
    # SIMPLE_RADIAL 640 360 384 320 180 -0.12).
    "street_figure8_hard": ("street --video --frames 500 --width 640 --height 360 "
                            "--route figure8 --look-ahead 30 --abrupt-turns --shake 1 --jitter 2 "
                            "--noise 4 --blur 100-110:20,300-305:30 --low-texture 200-215 "
                            "--jpeg-quality 60 --camera-model SIMPLE_RADIAL --k1 -0.12 "
                            "--focal-factor 0.6"),
    # Two laps past identical buildings: true loops among look-alike places.
    "street_repeated_laps": ("street --video --frames 500 --width 640 --height 360 "
                             "--look-ahead 30 --repeated-facades --laps 2 --noise 3 "
                             "--jpeg-quality 70 --shake 0.5"),
}

ALL_SETS = list(DATA_SETS) + list(SYNTH_SETS)
DEFAULT_SETS = ["templeRing", "fox", "kitti07_160", "cylinder"]


class BenchSet:
    """One input: an image folder or a video, its intrinsics and ground truth, and the matcher
    COLMAP users would pick for it."""

    def __init__(self, name, source, intrinsics, groundtruth, colmap_matcher, origin):
        self.name = name
        self.source = source            # folder of images, or a video file
        self.is_video = source.is_file()
        self.intrinsics = intrinsics
        self.groundtruth = groundtruth
        self.colmap_matcher = colmap_matcher  # "exhaustive" | "sequential"
        self.origin = origin            # where the set comes from, for the report

    def describe(self):
        return {"set": self.name, "input": str(self.source), "video": self.is_video,
                "intrinsics": str(self.intrinsics), "groundtruth": str(self.groundtruth),
                "origin": self.origin}


def synth_sets(args):
    """The synthetic sets' command lines, with --synth-set additions and replacements."""
    sets = dict(SYNTH_SETS)
    for entry in args.synth_set:
        name, _, synth_args = entry.partition("=")
        sets[name.strip()] = synth_args.strip()
    return sets


def known_sets(args):
    return list(DATA_SETS) + [s for s in synth_sets(args) if s not in DATA_SETS]


def make_set(name, args, workdir):
    """Returns (BenchSet, None), or (None, reason) when the set cannot be run here.

    Synthetic sets are rendered here (once per work folder and command line)."""
    synth = synth_sets(args)
    if name in DATA_SETS:
        folder, source, groundtruth, matcher = DATA_SETS[name]
        root = args.data / folder
        paths = [root / source, root / "intrinsics.txt", root / groundtruth]
        for path in paths:
            if not path.exists():
                return None, f"{path} is missing (shared data not here? pass --data DIR)"
        bench_set = BenchSet(name, paths[0], paths[1], paths[2], matcher, str(root))
    elif name in synth:
        synth_dir = workdir / name / "synth"
        render_synth(args, name, synth[name], synth_dir)
        source = synth_dir / "video.mp4"
        if not source.exists():
            source = synth_dir / "images"
        bench_set = BenchSet(name, source, synth_dir / "intrinsics.txt",
                             synth_dir / "groundtruth.txt", "sequential",
                             f"loopsfm synth {synth[name]}")
    else:
        return None, f"unknown set '{name}' (known: {', '.join(known_sets(args))})"
    if args.colmap_matcher != "set":
        bench_set.colmap_matcher = args.colmap_matcher
    return bench_set, None


def render_synth(args, name, synth_args, synth_dir):
    """Renders a synthetic set with `loopsfm synth ARGS -o DIR`, unless DIR already holds the
    rendering of the same command line (not timed)."""
    cmd = [str(args.loopsfm), "synth"] + shlex.split(synth_args) + ["-o", str(synth_dir)]
    stamp = synth_dir / "synth_command.txt"
    line = " ".join(cmd[1:])
    if stamp.exists() and stamp.read_text().strip() == line:
        return
    shutil.rmtree(synth_dir, ignore_errors=True)
    synth_dir.parent.mkdir(parents=True, exist_ok=True)
    log(f"{name}: rendering `loopsfm synth {synth_args}` into {synth_dir} (not timed)")
    log_path = synth_dir.parent / "synth.log"
    with open(log_path, "w") as out:
        done = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT)
    if done.returncode != 0:
        raise RuntimeError(f"loopsfm synth failed (rc {done.returncode}), see {log_path}")
    stamp.write_text(line + "\n")


def colmap_images(args, bench_set, set_dir):
    """The folder COLMAP reads: the set's folder, or the video decoded to frame_%06d.png (the
    names loopsfm gives video frames) once per set. Returns (folder, seconds or None)."""
    if not bench_set.is_video:
        return bench_set.source, None
    frames_dir = set_dir / "frames"
    shutil.rmtree(frames_dir, ignore_errors=True)
    frames_dir.mkdir(parents=True)
    cmd = [args.ffmpeg, "-nostdin", "-loglevel", "error", "-i", str(bench_set.source),
           "-start_number", "0", str(frames_dir / "frame_%06d.png")]
    log(f"{bench_set.name}: ffmpeg frames for COLMAP ...")
    proc = run_measured(cmd, set_dir / "ffmpeg.log", args.timeout)
    if proc["rc"] != 0:
        raise RuntimeError(f"ffmpeg failed (rc {proc['rc']}), see {proc['log']}")
    log(f"{bench_set.name}: {len(list(frames_dir.glob('*.png')))} frames in "
        f"{proc['wall_s']:.1f} s")
    return frames_dir, proc["wall_s"]

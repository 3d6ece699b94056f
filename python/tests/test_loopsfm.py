"""The Python module against the program: same options, messages, models and metrics.

Run by ctest (python_test) with PYTHONPATH at build/python and LOOPSFM_PROGRAM naming the
program built beside it.
"""

import json
import os
import shutil
import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest

import loopsfm

PROGRAM = os.environ.get("LOOPSFM_PROGRAM", "loopsfm")


def run_program(*args):
    return subprocess.run([PROGRAM, *map(str, args)], capture_output=True, text=True)


@pytest.fixture(scope="session")
def scene(tmp_path_factory):
    """A short synthetic video with exact ground truth and intrinsics (36 frames)."""
    folder = tmp_path_factory.mktemp("scene")
    loopsfm.synth("cylinder", folder, video=True, frames=36, width=480, height=360, quiet=True)
    return folder


@pytest.fixture(scope="session")
def program_run(scene, tmp_path_factory):
    """The program's reconstruction of the scene on one thread."""
    out = tmp_path_factory.mktemp("program")
    result = run_program("reconstruct", scene / "video.mp4", "-o", out, "--intrinsics",
                         scene / "intrinsics.txt", "--every", "1", "--threads", "1", "--text",
                         "-q")
    assert result.returncode == 0, result.stderr
    return out


@pytest.fixture(scope="session")
def python_run(scene, tmp_path_factory):
    """The same reconstruction through the module, with its progress calls."""
    out = tmp_path_factory.mktemp("python")
    calls = []
    report = loopsfm.reconstruct(scene / "video.mp4", out, intrinsics=scene / "intrinsics.txt",
                                 every=1, threads=1, text=True, quiet=True,
                                 progress=lambda *call: calls.append(call))
    return out, report, calls


def test_same_poses_and_points_as_the_program_bit_for_bit(program_run, python_run):
    out, report, _ = python_run
    ours, theirs = loopsfm.read_model(out), loopsfm.read_model(program_run)
    assert len(ours) == 36
    assert ours.names == theirs.names
    assert np.array_equal(ours.poses, theirs.poses)
    assert np.array_equal(ours.xyz, theirs.xyz)
    assert np.array_equal(ours.obs_xy, theirs.obs_xy)
    assert report["num_frames"] == 36
    assert report["models"][0]["num_registered"] == 36
    assert report["models"][0]["num_points"] == len(ours.xyz)
    assert report["mapper"] == "incremental"


def test_model_arrays_are_consistent(scene, python_run):
    model = loopsfm.read_model(python_run[0])
    n, m = len(model), len(model.xyz)
    assert model.poses.shape == (n, 4, 4) and model.intrinsics.shape == (n, 3, 3)
    # Rotations are orthonormal; the last row is (0, 0, 0, 1).
    rotations = model.poses[:, :3, :3]
    assert np.allclose(rotations @ rotations.transpose(0, 2, 1), np.eye(3), atol=1e-9)
    assert np.array_equal(model.poses[:, 3], np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
    # Each observation projects near its pixel: K [R | t]^-1 applied to its point.
    cam_from_world = np.linalg.inv(model.poses)[model.obs_frame]
    points = np.c_[model.xyz[model.obs_point], np.ones(len(model.obs_point))]
    in_cam = np.einsum("kij,kj->ki", cam_from_world, points)[:, :3]
    pixels = np.einsum("kij,kj->ki", model.intrinsics[model.obs_frame], in_cam)
    pixels = pixels[:, :2] / pixels[:, 2:]
    # The camera has radial distortion: most observations are within a few pixels.
    assert np.median(np.linalg.norm(pixels - model.obs_xy, axis=1)) < 2.0
    assert np.array_equal(np.bincount(model.obs_point, minlength=m), model.track_length)
    assert model.rgb.dtype == np.uint8 and model.rgb.shape == (m, 3)
    # The text model holds the same frames and poses.
    text = loopsfm.read_model(python_run[0] / "sparse" / "0")
    assert text.names == model.names


@pytest.mark.skipif(shutil.which("colmap") is None, reason="COLMAP 3.8 (Debian's colmap) absent")
def test_reads_a_model_that_colmap_wrote(python_run, tmp_path):
    """COLMAP's model_converter rewrites our model as text: read back, it is the same model
    (to the digits COLMAP's text keeps)."""
    converted = subprocess.run(
        ["colmap", "model_converter", "--input_path", python_run[0] / "sparse" / "0",
         "--output_path", tmp_path, "--output_type", "TXT"], capture_output=True, text=True)
    assert converted.returncode == 0, converted.stderr
    ours, colmaps = loopsfm.read_model(python_run[0]), loopsfm.read_model(tmp_path)
    assert colmaps.names == ours.names
    assert np.allclose(colmaps.poses, ours.poses, atol=1e-9)
    assert np.allclose(colmaps.xyz, ours.xyz, rtol=1e-9)
    assert np.array_equal(colmaps.track_length, ours.track_length)


def test_evaluate_agrees_with_the_program_and_the_path_is_accurate(scene, python_run):
    model = python_run[0] / "sparse" / "0"
    metrics = loopsfm.evaluate(model, scene / "groundtruth.txt")
    printed = run_program("eval", model, scene / "groundtruth.txt", "--json")
    assert printed.returncode == 0, printed.stderr
    expected = json.loads(printed.stdout)
    for key in ("fraction_registered", "ate_rmse", "ate_fraction_of_path"):
        assert metrics[key] == expected[key]
    assert metrics["fraction_registered"] == 1.0
    assert metrics["ate_fraction_of_path"] < 0.005
    assert len(metrics["frames"]) == 36


def test_progress_reports_every_stage_and_ends_at_its_total(python_run):
    calls = python_run[2]
    stages = [stage for stage, _, _ in calls]
    assert {"extract", "match", "map"} <= set(stages)
    last = {stage: (done, total) for stage, done, total in calls}
    # Every frame is registered, every pair matched.
    assert last["map"] == (36, 36)
    assert last["match"][0] == last["match"][1] > 0
    assert last["extract"] == (36, 36)


def test_errors_carry_the_programs_messages(scene, tmp_path):
    with pytest.raises(loopsfm.InvalidArgument) as raised:
        loopsfm.reconstruct(scene / "video.mp4", tmp_path, pairs="everything")
    printed = run_program("reconstruct", scene / "video.mp4", "-o", tmp_path, "--pairs",
                          "everything")
    assert printed.returncode == 2
    assert str(raised.value) in printed.stderr
    with pytest.raises(loopsfm.InputError) as raised:
        loopsfm.reconstruct(tmp_path / "missing.mp4", tmp_path / "out")
    printed = run_program("reconstruct", tmp_path / "missing.mp4", "-o", tmp_path / "out")
    assert printed.returncode == 2
    assert str(raised.value) in printed.stderr
    with pytest.raises(loopsfm.InvalidArgument, match="not-a-flag"):
        loopsfm.reconstruct(scene / "video.mp4", tmp_path, not_a_flag=3)
    with pytest.raises(loopsfm.InputError):
        loopsfm.read_model(tmp_path)
    # Nothing was created by the refused runs.
    assert not (tmp_path / "out").exists()


def test_ctrl_c_stops_the_run_and_a_rerun_resumes(scene, tmp_path, program_run):
    """SIGINT during matching raises KeyboardInterrupt; the frames stay and the rerun resumes
    from them and gives the program's model."""
    sent = []

    def interrupt(stage, done, total):
        if stage == "match" and not sent:
            sent.append(done)
            os.kill(os.getpid(), signal.SIGINT)

    options = dict(intrinsics=scene / "intrinsics.txt", every=1, threads=1, quiet=True)
    with pytest.raises(KeyboardInterrupt):
        loopsfm.reconstruct(scene / "video.mp4", tmp_path, progress=interrupt, **options)
    assert sent and (tmp_path / "database.db").exists()
    assert not (tmp_path / "sparse").exists()
    report = loopsfm.reconstruct(scene / "video.mp4", tmp_path, **options)
    assert report["extract"]["frames_resumed"] == 36
    assert np.array_equal(loopsfm.read_model(tmp_path).poses,
                          loopsfm.read_model(program_run).poses)


def test_a_callback_that_raises_stops_the_run_with_its_error(scene, tmp_path):
    def fail(stage, done, total):
        raise RuntimeError(f"stop at {stage}")

    with pytest.raises(RuntimeError, match="stop at extract"):
        loopsfm.reconstruct(scene / "video.mp4", tmp_path, progress=fail, quiet=True)


def test_stages_one_at_a_time(scene, tmp_path):
    database = tmp_path / "stages.db"
    extracted = loopsfm.extract(scene / "video.mp4", database, every=1, quiet=True,
                                intrinsics=scene / "intrinsics.txt")
    assert extracted["frames_extracted"] == 36
    with pytest.raises(loopsfm.InputError, match="loopsfm match"):
        loopsfm.map(database, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    matched = loopsfm.match(database, pairs="sequential", quiet=True)
    assert matched["num_pairs_verified"] > 36
    mapped = loopsfm.map(database, tmp_path / "out", quiet=True)
    assert mapped["models"][0]["num_registered"] == 36
    metrics = loopsfm.evaluate(tmp_path / "out" / "sparse" / "0", scene / "groundtruth.txt")
    assert metrics["ate_fraction_of_path"] < 0.005
    # The database recorded its source: the frames and coloured points are written.
    assert len(list((tmp_path / "out" / "images").iterdir())) == 36
    assert loopsfm.read_model(tmp_path / "out").rgb.any()
    with pytest.raises(loopsfm.InputError, match="does not exist"):
        loopsfm.match(tmp_path / "none.db")


def test_help_and_version_are_the_programs():
    printed = run_program("reconstruct", "--help")
    assert printed.returncode == 0
    assert loopsfm.help("reconstruct") == printed.stdout
    assert "--intrinsics" in loopsfm.help("reconstruct")
    assert loopsfm.version().startswith("loopsfm " + loopsfm.__version__)
    with pytest.raises(loopsfm.InvalidArgument, match="not a loopsfm command"):
        loopsfm.help("nonsense")


SOURCE_DIR = Path(os.environ.get("LOOPSFM_SOURCE_DIR", Path(__file__).resolve().parents[2]))
BUILD_DIR = Path(loopsfm.__file__).resolve().parents[2]


def test_pip_installs_the_package_offline_into_a_venv(tmp_path):
    """`pip install ./python` as docs/install.md says, with no package index to reach."""
    venv = tmp_path / "venv"
    subprocess.run(["/usr/bin/python3", "-m", "venv", "--system-site-packages", venv],
                   check=True)
    env = dict(os.environ, LOOPSFM_BUILD_DIR=str(BUILD_DIR), PIP_NO_INDEX="1")
    env.pop("PYTHONPATH", None)
    installed = subprocess.run(
        [venv / "bin" / "pip", "install", "--quiet", SOURCE_DIR / "python"], env=env,
        capture_output=True, text=True, cwd=tmp_path)
    assert installed.returncode == 0, installed.stdout + installed.stderr
    imported = subprocess.run(
        [venv / "bin" / "python", "-c",
         "import loopsfm; print(loopsfm.__file__); print(loopsfm.help('map'))"],
        env=env, capture_output=True, text=True, cwd=tmp_path)
    assert imported.returncode == 0, imported.stderr
    assert imported.stdout.startswith(str(venv))
    assert "--database" in imported.stdout


def test_the_example_runs(tmp_path):
    example = SOURCE_DIR / "python" / "examples" / "reconstruct_clip.py"
    result = subprocess.run(["/usr/bin/python3", example, "--out", tmp_path, "--frames", "30"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "30 of 30 frames in the largest model" in result.stdout
    assert (tmp_path / "path.png").stat().st_size > 1000
    assert (tmp_path / "transforms.json").exists()

"""Camera intrinsics for vs_colmap.py: COLMAP's camera models, the set's true camera (an
intrinsics.txt line), the camera a model ended with (cameras.bin / cameras.txt), and the focal
length and k1 of the one against the other. Standard library only; see README.md beside this
file."""

import struct
from pathlib import Path

# COLMAP's camera models: id -> (name, parameter names in COLMAP's order). The ids are those of
# COLMAP's cameras.bin and database `cameras.model`.
CAMERA_MODELS = {
    0: ("SIMPLE_PINHOLE", ["f", "cx", "cy"]),
    1: ("PINHOLE", ["fx", "fy", "cx", "cy"]),
    2: ("SIMPLE_RADIAL", ["f", "cx", "cy", "k"]),
    3: ("RADIAL", ["f", "cx", "cy", "k1", "k2"]),
    4: ("OPENCV", ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"]),
    5: ("OPENCV_FISHEYE", ["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"]),
    6: ("FULL_OPENCV", ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"]),
    7: ("FOV", ["fx", "fy", "cx", "cy", "omega"]),
    8: ("SIMPLE_RADIAL_FISHEYE", ["f", "cx", "cy", "k"]),
    9: ("RADIAL_FISHEYE", ["f", "cx", "cy", "k1", "k2"]),
    10: ("THIN_PRISM_FISHEYE", ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4",
                                "sx1", "sy1"]),
}
MODEL_PARAMS = {name: params for name, params in CAMERA_MODELS.values()}

# What k1 means depends on the family: the first coefficient of the radial polynomial in r^2 of
# the normalized image coordinates (the pinhole models have k1 = 0 in this family), or the first
# coefficient of the fisheye models' polynomial in theta^2. k1 of two models compares only
# within one family; FOV has no k1.
RADIAL_FAMILY = {"SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV", "FULL_OPENCV"}
FISHEYE_FAMILY = {"OPENCV_FISHEYE", "SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE",
                  "THIN_PRISM_FISHEYE"}


def k1_family(model):
    if model in RADIAL_FAMILY:
        return "radial"
    if model in FISHEYE_FAMILY:
        return "fisheye"
    return None


def focal_of(model, params):
    """The focal length in pixels: f, or the mean of fx and fy."""
    names = MODEL_PARAMS[model]
    if "f" in names:
        return params[names.index("f")]
    return 0.5 * (params[names.index("fx")] + params[names.index("fy")])


def k1_of(model, params):
    """k1 (SIMPLE_RADIAL's and SIMPLE_RADIAL_FISHEYE's k), 0 for the pinhole models, None for
    FOV."""
    names = MODEL_PARAMS[model]
    for name in ("k1", "k"):
        if name in names:
            return params[names.index(name)]
    return 0.0 if model in ("SIMPLE_PINHOLE", "PINHOLE") else None


def parse_camera_line(line, where="camera line"):
    """'MODEL width height params...' (COLMAP's parameter order; commas allowed) to
    (model, width, height, [params as float])."""
    fields = line.replace(",", " ").split()
    if len(fields) < 3:
        raise ValueError(f"{where}: cannot read camera line '{line}'")
    model = fields[0].upper()
    if model not in MODEL_PARAMS:
        raise ValueError(f"{where}: unknown camera model '{fields[0]}'")
    params = [float(v) for v in fields[3:]]
    if len(params) != len(MODEL_PARAMS[model]):
        raise ValueError(f"{where}: {model} takes {len(MODEL_PARAMS[model])} parameters "
                         f"({', '.join(MODEL_PARAMS[model])}), not {len(params)}: '{line}'")
    return model, int(float(fields[1])), int(float(fields[2])), params


def read_intrinsics_file(path):
    """The first camera line of an intrinsics.txt: (model, width, height, [params])."""
    path = Path(path)
    for line in path.read_text().splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            return parse_camera_line(line, str(path))
    raise ValueError(f"{path}: no camera line")


# ----------------------------------------------------------------------------------------------
# A COLMAP model's cameras


def read_cameras(model_dir):
    """{camera_id: (model, width, height, [params])} from cameras.bin, or cameras.txt."""
    model_dir = Path(model_dir)
    cameras = {}
    binary = model_dir / "cameras.bin"
    if binary.exists():
        data = binary.read_bytes()
        (count,), offset = struct.unpack_from("<Q", data, 0), 8
        for _ in range(count):
            camera_id, model_id, width, height = struct.unpack_from("<iiQQ", data, offset)
            offset += 24
            if model_id not in CAMERA_MODELS:
                raise ValueError(f"{binary}: unknown camera model id {model_id}")
            model, names = CAMERA_MODELS[model_id]
            params = list(struct.unpack_from(f"<{len(names)}d", data, offset))
            offset += 8 * len(names)
            cameras[camera_id] = (model, width, height, params)
        return cameras
    text = model_dir / "cameras.txt"
    if text.exists():
        for line in text.read_text().splitlines():
            line = line.strip()
            if line and not line.startswith("#"):
                camera_id, rest = line.split(None, 1)
                cameras[int(camera_id)] = parse_camera_line(rest, str(text))
    return cameras


def image_camera_ids(model_dir):
    """Camera id of every registered image, from images.bin or images.txt."""
    model_dir = Path(model_dir)
    binary = model_dir / "images.bin"
    ids = []
    if binary.exists():
        data = binary.read_bytes()
        (count,), offset = struct.unpack_from("<Q", data, 0), 8
        for _ in range(count):
            # image_id, qvec (4 doubles), tvec (3 doubles), camera_id
            (camera_id,) = struct.unpack_from("<i", data, offset + 4 + 56)
            ids.append(camera_id)
            offset = data.index(b"\0", offset + 64) + 1  # after the name
            (num_points,) = struct.unpack_from("<Q", data, offset)
            offset += 8 + 24 * num_points  # x, y (doubles), point3D_id (int64) each
        return ids
    text = model_dir / "images.txt"
    if text.exists():
        lines = [l for l in text.read_text().splitlines() if l.strip() and not l.startswith("#")]
        ids = [int(l.split()[8]) for l in lines[0::2]]
    return ids


def model_camera(model_dir):
    """The camera most registered images of the model use: (model, width, height, params,
    number of cameras in the model), or None when the model has none."""
    cameras = read_cameras(model_dir)
    if not cameras:
        return None
    uses = {}
    for camera_id in image_camera_ids(model_dir):
        uses[camera_id] = uses.get(camera_id, 0) + 1
    main_id = max(cameras, key=lambda c: (uses.get(c, 0), -c))
    return cameras[main_id] + (len(cameras),)


def camera_vs_truth(model_dir, intrinsics_path):
    """The largest model's camera against the set's intrinsics.txt.

    focal_est: f, or the mean of fx and fy; focal_true: the same of the true camera, scaled by
    the width ratio when the model's images are not the true camera's size; focal_err_pct:
    100 (focal_est - focal_true) / focal_true (signed). k1_est, k1_true (0 for a pinhole camera)
    and k1_abs_err = |k1_est - k1_true| when both are of one family (see k1_family)."""
    result = {"camera_model": None, "cameras_in_model": None, "focal_est": None,
              "focal_true": None, "focal_err_pct": None, "k1_est": None, "k1_true": None,
              "k1_abs_err": None}
    try:
        true_model, true_w, _, true_params = read_intrinsics_file(intrinsics_path)
    except (OSError, ValueError):
        true_model = None
    camera = model_camera(model_dir) if model_dir is not None else None
    if true_model is not None:
        result["focal_true"] = focal_of(true_model, true_params)
        result["k1_true"] = k1_of(true_model, true_params)
    if camera is None:
        return result
    model, width, _, params, count = camera
    result.update(camera_model=model, cameras_in_model=count, camera_params=params,
                  focal_est=focal_of(model, params), k1_est=k1_of(model, params))
    if true_model is None:
        return result
    if width and true_w and width != true_w:
        result["focal_true"] *= width / true_w
    result["focal_err_pct"] = 100.0 * (result["focal_est"] - result["focal_true"]) \
        / result["focal_true"]
    if (result["k1_est"] is not None and result["k1_true"] is not None
            and k1_family(model) == k1_family(true_model)):
        result["k1_abs_err"] = abs(result["k1_est"] - result["k1_true"])
    return result

// _loopsfm: the C++ side of `import loopsfm`. A thin layer: commands run through the
// program's own command line (cli/app.h), models are read by storage/, and the results come
// back as JSON text and NumPy arrays. loopsfm/__init__.py is the Python face of it.

#include <atomic>
#include <exception>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <glog/logging.h>
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "loopsfm/cli/app.h"
#include "loopsfm/storage/colmap_model.h"
#include "loopsfm/util/errors.h"

namespace py = pybind11;

namespace loopsfm {
namespace {

// The hooks of one command run from Python: the progress callback, and a stop when Ctrl-C
// (KeyboardInterrupt) arrives or the callback raises. The Python error is kept and raised
// again once the run has unwound.
class PythonHooks {
 public:
  explicit PythonHooks(py::object progress)
      : progress_(std::move(progress)), caller_(std::this_thread::get_id()) {
    hooks_.progress = [this](const std::string& stage, size_t done, size_t total) {
      if (progress_.is_none() || stop_.load()) return;
      py::gil_scoped_acquire gil;
      try {
        progress_(stage, done, total);
      } catch (py::error_already_set& e) {
        Keep(e);
      }
    };
    hooks_.stop_requested = [this] {
      // Signal handlers run on Python's main thread only: the caller's thread checks them.
      if (!stop_.load() && std::this_thread::get_id() == caller_) {
        py::gil_scoped_acquire gil;
        if (PyErr_CheckSignals() != 0) Keep(py::error_already_set());
      }
      return stop_.load();
    };
  }
  ~PythonHooks() {
    // The kept error holds Python objects.
    py::gil_scoped_acquire gil;
    error_.reset();
    progress_ = py::object();
  }

  const RunHooks* hooks() const { return &hooks_; }
  // Raises the kept Python error, if any (with the GIL held).
  void RaiseKeptError() {
    if (error_) {
      py::error_already_set error = std::move(*error_);
      error_.reset();
      throw error;
    }
  }

 private:
  void Keep(py::error_already_set error) {  // GIL held
    if (!error_) error_.emplace(std::move(error));
    stop_ = true;
  }

  py::object progress_;
  std::thread::id caller_;
  RunHooks hooks_;
  std::atomic<bool> stop_{false};
  std::optional<py::error_already_set> error_;
};

// Runs a command line; returns its report as JSON text ("null" for commands without one).
std::string RunCommandFromPython(const std::vector<std::string>& args, py::object progress) {
  PythonHooks hooks(std::move(progress));
  std::string report;
  try {
    py::gil_scoped_release released;
    report = cli::RunCommand(args, hooks.hooks()).dump();
  } catch (const Cancelled&) {
    // Stopped for a KeyboardInterrupt or an error in the callback: raise that instead.
    hooks.RaiseKeptError();
    throw;
  }
  return report;
}

template <typename T>
py::array_t<T> Array(std::vector<T> values, std::vector<py::ssize_t> shape) {
  py::array_t<T> array(shape);
  std::copy(values.begin(), values.end(), array.mutable_data());
  return array;
}

// A COLMAP model folder (binary or text) as a dict of NumPy arrays; registered frames in
// image-id order, points in point-id order.
py::dict ReadModel(const std::string& path) {
  Reconstruction model;
  {
    py::gil_scoped_release released;
    model = ReadColmapModel(path);
  }
  std::vector<image_t> image_ids = model.RegImageIds();
  std::sort(image_ids.begin(), image_ids.end());
  std::vector<point3D_t> point_ids = model.Point3DIds();
  std::sort(point_ids.begin(), point_ids.end());
  std::unordered_map<point3D_t, int64_t> point_index;
  for (size_t k = 0; k < point_ids.size(); ++k) point_index[point_ids[k]] = int64_t(k);

  const size_t n = image_ids.size(), m = point_ids.size();
  py::list names;
  std::vector<int64_t> ids, camera_ids;
  std::vector<double> poses, intrinsics;
  std::vector<int64_t> obs_frame, obs_point;
  std::vector<double> obs_xy;
  for (size_t i = 0; i < n; ++i) {
    const Image& image = model.GetImage(image_ids[i]);
    names.append(image.name);
    ids.push_back(image.image_id);
    camera_ids.push_back(image.camera_id);
    const Rigid3d world_from_cam = image.cam_from_world.Inverse();
    const Eigen::Matrix3d r = world_from_cam.rotation.toRotationMatrix();
    for (int row = 0; row < 4; ++row) {
      for (int col = 0; col < 4; ++col) {
        double value = row == 3 ? (col == 3 ? 1.0 : 0.0)
                       : col < 3 ? r(row, col)
                                 : world_from_cam.translation(row);
        poses.push_back(value);
      }
    }
    const OpenCvIntrinsics k = model.GetCamera(image.camera_id).ToOpenCv();
    intrinsics.insert(intrinsics.end(), {k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0});
    for (const Point2D& point : image.points2D) {
      if (!point.HasPoint3D()) continue;
      obs_frame.push_back(int64_t(i));
      obs_point.push_back(point_index.at(point.point3D_id));
      obs_xy.insert(obs_xy.end(), {point.xy.x(), point.xy.y()});
    }
  }
  std::vector<double> xyz, error;
  std::vector<uint8_t> rgb;
  std::vector<int64_t> track_length, point_ids64;
  for (point3D_t id : point_ids) {
    const Point3D& point = model.GetPoint3D(id);
    xyz.insert(xyz.end(), {point.xyz.x(), point.xyz.y(), point.xyz.z()});
    rgb.insert(rgb.end(), {point.color(0), point.color(1), point.color(2)});
    error.push_back(point.error);
    track_length.push_back(int64_t(point.track.Length()));
    point_ids64.push_back(int64_t(id));
  }
  py::dict cameras;
  for (const auto& [id, camera] : model.Cameras()) {
    py::dict c;
    c["model"] = camera.ModelName();
    c["width"] = camera.width;
    c["height"] = camera.height;
    c["params"] = camera.params;
    cameras[py::int_(id)] = c;
  }
  const py::ssize_t num_obs = py::ssize_t(obs_frame.size());
  py::dict out;
  out["names"] = names;
  out["image_ids"] = Array(ids, {py::ssize_t(n)});
  out["camera_ids"] = Array(camera_ids, {py::ssize_t(n)});
  out["poses"] = Array(poses, {py::ssize_t(n), 4, 4});
  out["intrinsics"] = Array(intrinsics, {py::ssize_t(n), 3, 3});
  out["cameras"] = cameras;
  out["point_ids"] = Array(point_ids64, {py::ssize_t(m)});
  out["xyz"] = Array(xyz, {py::ssize_t(m), 3});
  out["rgb"] = Array(rgb, {py::ssize_t(m), 3});
  out["error"] = Array(error, {py::ssize_t(m)});
  out["track_length"] = Array(track_length, {py::ssize_t(m)});
  out["obs_frame"] = Array(obs_frame, {num_obs});
  out["obs_point"] = Array(obs_point, {num_obs});
  out["obs_xy"] = Array(obs_xy, {num_obs, 2});
  return out;
}

}  // namespace
}  // namespace loopsfm

PYBIND11_MODULE(_loopsfm, m) {
  using namespace loopsfm;
  m.doc() = "C++ core of the loopsfm Python module; use `import loopsfm`.";
  if (!google::IsGoogleLoggingInitialized()) {
    FLAGS_logtostderr = true;
    FLAGS_minloglevel = google::GLOG_ERROR;
    google::InitGoogleLogging("loopsfm");
  }
  // loopsfm.Error and its kinds; loopsfm/__init__.py documents them.
  static py::exception<Error> error(m, "Error", PyExc_RuntimeError);
  static py::exception<InvalidArgument> invalid_argument(m, "InvalidArgument", error.ptr());
  static py::exception<InputError> input_error(m, "InputError", error.ptr());
  static py::exception<StorageError> storage_error(m, "StorageError", error.ptr());
  static py::exception<Cancelled> cancelled(m, "Cancelled", error.ptr());
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const InvalidArgument& e) {
      invalid_argument(e.what());
    } catch (const InputError& e) {
      input_error(e.what());
    } catch (const StorageError& e) {
      storage_error(e.what());
    } catch (const Cancelled& e) {
      cancelled(e.what());
    } catch (const Error& e) {
      error(e.what());
    }
  });
  m.def("run_command", &RunCommandFromPython, py::arg("args"), py::arg("progress") = py::none(),
        "Runs a loopsfm command line in this process; its report as JSON text.");
  m.def("help_text", &cli::HelpText, py::arg("command") = "",
        "The --help text of a command ('' for the program's).");
  m.def("version_text", [] { return cli::VersionText("the C library's malloc"); });
  m.def("read_model", &ReadModel, py::arg("path"),
        "A COLMAP model folder (bin or txt) as a dict of NumPy arrays.");
}

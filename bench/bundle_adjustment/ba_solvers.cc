// Global bundle adjustment of a real model with each linear solver, side by side: the
// mapper's global bundle (all registered frames, gauge fixed by the lowest-id frame and the
// one farthest from it, cameras held fixed as with known intrinsics) on a COLMAP model whose
// 3D points are disturbed by `--noise` pixels (a Gaussian step of noise x depth / focal
// length, the same draw for every solver). Rounds alternate the solvers, so a loaded machine
// slows them alike.
//
//   ba_solvers OUT/sparse/0 [--rounds 3] [--noise 2] [--threads 0] [--only sparse_schur]
//
// Prints, per solver, the median wall time, iterations, and the final RMS reprojection error.
// `--only NAME` runs one solver (dense_schur, sparse_schur, sparse_schur_3, iterative_schur),
// for a profiler.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <vector>

#include "loopsfm/estimators/bundle_adjustment.h"
#include "loopsfm/math/random.h"
#include "loopsfm/storage/colmap_model.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {
namespace {

double RmsReprojectionError(const Reconstruction& rec) {
  double sum = 0.0;
  size_t count = 0;
  for (const auto& [id, point] : rec.Points3D()) {
    for (const TrackElement& el : point.track.elements) {
      const Image& image = rec.GetImage(el.image_id);
      const Eigen::Vector3d in_cam = image.cam_from_world * point.xyz;
      if (in_cam.z() <= 0) continue;
      const Eigen::Vector2d error = rec.GetCamera(image.camera_id).ImgFromCam(in_cam) -
                                    image.points2D[el.point2D_idx].xy;
      sum += error.squaredNorm();
      ++count;
    }
  }
  return count > 0 ? std::sqrt(sum / count) : 0.0;
}

void Disturb(Reconstruction* rec, double noise_px, uint64_t seed) {
  Random random(seed);
  std::vector<point3D_t> ids;
  for (const auto& [id, point] : rec->Points3D()) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  for (const point3D_t id : ids) {
    Point3D& point = rec->GetPoint3D(id);
    const Image& image = rec->GetImage(point.track.elements.front().image_id);
    const double depth = (image.ProjectionCenter() - point.xyz).norm();
    const double sigma = noise_px * depth / rec->GetCamera(image.camera_id).MeanFocalLength();
    point.xyz += sigma * Eigen::Vector3d(random.Normal(0, 1), random.Normal(0, 1),
                                         random.Normal(0, 1));
  }
}

constexpr const char* kUsage =
    "usage: ba_solvers MODEL_DIR [--rounds N] [--noise PX] [--threads N] [--only SOLVER]\n"
    "  SOLVER: dense_schur, sparse_schur, sparse_schur_3 or iterative_schur\n";

int Main(int argc, char** argv) {
  if (argc >= 2 && (std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h")) {
    std::printf("%s", kUsage);
    return 0;
  }
  if (argc < 2) {
    std::fprintf(stderr, "%s", kUsage);
    return 2;
  }
  int rounds = 3, threads = 0;
  std::string only;
  double noise_px = 2.0;
  for (int i = 2; i < argc; i += 2) {
    const std::string flag = argv[i];
    if (i + 1 == argc) {
      std::fprintf(stderr, "%s needs a value\n%s", flag.c_str(), kUsage);
      return 2;
    }
    if (flag == "--rounds") rounds = std::atoi(argv[i + 1]);
    else if (flag == "--noise") noise_px = std::atof(argv[i + 1]);
    else if (flag == "--threads") threads = std::atoi(argv[i + 1]);
    else if (flag == "--only") only = argv[i + 1];
    else {
      std::fprintf(stderr, "unknown flag %s\n%s", flag.c_str(), kUsage);
      return 2;
    }
  }
  if (rounds < 1 || threads < 0 || !(noise_px >= 0.0)) {
    std::fprintf(stderr, "need --rounds >= 1, --threads >= 0 and --noise >= 0\n");
    return 2;
  }
  struct Variant {
    std::string name;
    BundleLinearSolver solver;
    // Hold the second gauge frame's whole centre (over-fixing the gauge by two
    // coordinates) by three priors instead of one, to check that the gauge prior costs
    // nothing (every pose block keeps tangent size 6, for Ceres' fixed-size Schur kernel; a
    // SubsetManifold would not, and was 16 % slower).
    bool full_gauge_block = false;
  };
  std::vector<Variant> variants = {
      {"dense_schur", BundleLinearSolver::kDenseSchur},
      {"sparse_schur", BundleLinearSolver::kSparseSchur},
      {"sparse_schur_3", BundleLinearSolver::kSparseSchur, true},
      {"iterative_schur", BundleLinearSolver::kIterativeSchur}};
  if (!only.empty()) {
    std::erase_if(variants, [&](const Variant& v) { return v.name != only; });
    if (variants.empty()) {
      std::fprintf(stderr, "--only: no solver named %s\n%s", only.c_str(), kUsage);
      return 2;
    }
  }
  const Reconstruction model = ReadColmapModel(argv[1]);
  std::vector<image_t> frames = model.RegImageIds();
  std::sort(frames.begin(), frames.end());
  if (frames.size() < 3) {
    std::fprintf(stderr, "the model needs 3 or more registered frames\n");
    return 2;
  }
  std::printf("%zu frames, %zu points, %zu observations, noise %.1f px\n", frames.size(),
              model.NumPoints3D(), model.ComputeNumObservations(), noise_px);
  std::map<std::string, std::vector<double>> seconds;
  for (int round = 0; round < rounds; ++round) {
    for (const auto& [name, solver, full_gauge_block] : variants) {
      Reconstruction rec = model;
      Disturb(&rec, noise_px, 17 + round);
      BundleAdjustmentConfig config;
      for (const image_t id : frames) config.AddImage(id);
      for (const auto& [id, camera] : rec.Cameras()) config.SetConstantCamera(id);
      const image_t scale_gauge = FarthestRegisteredImage(rec, frames[0], frames[1]);
      FixGaugeWithTwoImages(rec, frames[0], scale_gauge, &config);
      if (full_gauge_block) config.SetConstantCentreCoords(scale_gauge, {0, 1, 2});
      BundleAdjustmentOptions options = BundleAdjustmentOptions::Global();
      options.linear_solver = solver;
      options.num_threads = threads > 0 ? threads : -1;
      BundleAdjuster adjuster(options, config);
      Timer timer;
      adjuster.Solve(&rec);
      seconds[name].push_back(timer.ElapsedSeconds());
      std::printf("round %d %-16s %6.2f s  %3d iterations  rms %.3f px  (%s)\n", round + 1,
                  name.c_str(), seconds[name].back(), adjuster.report().num_iterations,
                  RmsReprojectionError(rec), adjuster.report().termination.c_str());
    }
  }
  for (auto& [name, times] : seconds) {
    std::sort(times.begin(), times.end());
    std::printf("median %-16s %6.2f s\n", name.c_str(), times[times.size() / 2]);
  }
  return 0;
}

}  // namespace
}  // namespace loopsfm

int main(int argc, char** argv) {
  try {
    return loopsfm::Main(argc, argv);
  } catch (const loopsfm::Error& error) {  // a model folder that is missing or unreadable
    std::fprintf(stderr, "ba_solvers: %s\n", error.what());
    return 2;
  }
}

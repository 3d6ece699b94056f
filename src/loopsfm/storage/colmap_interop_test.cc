// COLMAP reads what we write, and we read what COLMAP writes. Runs the `colmap` binary
// (3.8); skipped when it is not on PATH.

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <numeric>
#include <sstream>

#include <Eigen/Geometry>

#include "loopsfm/math/random.h"
#include "loopsfm/storage/database.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

namespace fs = std::filesystem;

bool ColmapOnPath() { return std::system("command -v colmap > /dev/null 2>&1") == 0; }

class ColmapInteropTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!ColmapOnPath()) GTEST_SKIP() << "`colmap` is not on PATH; install COLMAP 3.8 to run";
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           fmt::format("loopsfm_colmap_interop_{}_{}", getpid(), info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    if (!dir_.empty() && !HasFailure()) fs::remove_all(dir_);
  }

  // Runs a colmap command; on failure the log's tail becomes part of the test output.
  void RunColmap(const std::string& args, const std::string& log_name) {
    const fs::path log = dir_ / log_name;
    const int rc = std::system(("colmap " + args + " > '" + log.string() + "' 2>&1").c_str());
    if (rc != 0) {
      std::ifstream in(log);
      std::stringstream text;
      text << in.rdbuf();
      const std::string s = text.str();
      FAIL() << "colmap " << args << " failed (" << rc << "):\n"
             << s.substr(s.size() > 4000 ? s.size() - 4000 : 0);
    }
  }

  fs::path dir_;
};

// ---- reading COLMAP's binary model -------------------------------------------------------

struct ModelImage {
  image_t image_id = 0;
  std::string name;
  Rigid3d cam_from_world;
};

template <typename T>
T ReadValue(std::istream& in) {
  T value{};
  in.read(reinterpret_cast<char*>(&value), sizeof(T));
  return value;
}

// images.bin: uint64 count; per image: uint32 id, 4 doubles qvec (w, x, y, z), 3 doubles
// tvec, uint32 camera_id, NUL-terminated name, uint64 num_points2D, then per point
// (double x, double y, uint64 point3D_id).
std::vector<ModelImage> ReadImagesBin(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  EXPECT_TRUE(in.good()) << path;
  std::vector<ModelImage> images(ReadValue<uint64_t>(in));
  for (ModelImage& image : images) {
    image.image_id = ReadValue<uint32_t>(in);
    double q[4], t[3];
    for (double& v : q) v = ReadValue<double>(in);
    for (double& v : t) v = ReadValue<double>(in);
    image.cam_from_world = Rigid3d(Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized(),
                                   Eigen::Vector3d(t[0], t[1], t[2]));
    ReadValue<uint32_t>(in);
    std::getline(in, image.name, '\0');
    const auto num_points = ReadValue<uint64_t>(in);
    in.seekg(num_points * (2 * sizeof(double) + sizeof(uint64_t)), std::ios::cur);
  }
  EXPECT_TRUE(in.good()) << path;
  return images;
}

uint64_t ReadNumPoints3D(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return ReadValue<uint64_t>(in);
}

// ---- a synthetic scene written with our Database -----------------------------------------

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// Geometry of (i, j) from ground-truth poses, as a perfect verification would find it.
TwoViewGeometry TrueGeometry(const Rigid3d& cam_i, const Rigid3d& cam_j, const Eigen::Matrix3d& K,
                             const FeatureMatches& matches) {
  TwoViewGeometry geometry;
  geometry.config = TwoViewGeometry::kCalibrated;
  geometry.cam2_from_cam1 = cam_j * cam_i.Inverse();
  geometry.cam2_from_cam1.translation.normalize();
  geometry.E = Skew(geometry.cam2_from_cam1.translation) *
               geometry.cam2_from_cam1.rotation.toRotationMatrix();
  geometry.F = K.inverse().transpose() * geometry.E * K.inverse();
  geometry.inlier_matches = matches;
  return geometry;
}

TEST_F(ColmapInteropTest, MapperRegistersAllFramesOfOurDatabase) {
  constexpr int kNumCameras = 12, kNumPoints = 300;
  Random random(42);
  Camera camera;
  camera.model_id = CameraModelId::kPinhole;
  camera.width = 640;
  camera.height = 480;
  camera.params = {500, 500, 320, 240};
  camera.has_prior_focal_length = true;
  Eigen::Matrix3d K;
  K << 500, 0, 320, 0, 500, 240, 0, 0, 1;

  // Cameras on an arc of radius 6 around the origin, looking at it; points in a cube.
  std::vector<Rigid3d> cam_from_world;
  for (int i = 0; i < kNumCameras; ++i) {
    const double angle = (-60.0 + 120.0 * i / (kNumCameras - 1)) * M_PI / 180.0;
    const Eigen::Vector3d center(6 * std::sin(angle), 0.3 * std::sin(3 * angle),
                                 -6 * std::cos(angle));
    const Eigen::Vector3d z = -center.normalized();
    const Eigen::Vector3d x = Eigen::Vector3d::UnitY().cross(z).normalized();
    Eigen::Matrix3d R;
    R.row(0) = x;
    R.row(1) = z.cross(x);
    R.row(2) = z;
    cam_from_world.emplace_back(Eigen::Quaterniond(R), -(R * center));
  }
  std::vector<Eigen::Vector3d> points(kNumPoints);
  std::vector<Eigen::Matrix<int, 128, 1>> point_descriptors(kNumPoints);
  for (int p = 0; p < kNumPoints; ++p) {
    points[p] = {random.UniformReal(-1.5, 1.5), random.UniformReal(-1.5, 1.5),
                 random.UniformReal(-1.5, 1.5)};
    for (int d = 0; d < 128; ++d) point_descriptors[p](d) = static_cast<int>(random.UniformInt(0, 255));
  }

  // Per image: keypoints in shuffled order, and which keypoint sees which point.
  std::vector<std::map<int, point2D_t>> keypoint_of_point(kNumCameras);
  std::vector<FeatureSet> features(kNumCameras);
  for (int i = 0; i < kNumCameras; ++i) {
    std::vector<uint32_t> order = random.Sample(kNumPoints, kNumPoints);
    for (const uint32_t p : order) {
      const Eigen::Vector3d in_cam = cam_from_world[i] * points[p];
      const Eigen::Vector2d pixel =
          camera.ImgFromCam(in_cam) + Eigen::Vector2d(random.Normal(0, 0.2), random.Normal(0, 0.2));
      if (in_cam.z() <= 0 || pixel.x() < 0 || pixel.y() < 0 || pixel.x() > 640 || pixel.y() > 480)
        continue;
      keypoint_of_point[i][p] = static_cast<point2D_t>(features[i].keypoints.size());
      features[i].keypoints.push_back(FeatureKeypoint::FromScaleOrientation(
          pixel.x(), pixel.y(), random.UniformReal(2, 6), random.UniformReal(-3, 3)));
    }
    features[i].descriptors.resize(features[i].Size(), kDescriptorDim);
    for (const auto& [p, idx] : keypoint_of_point[i]) {
      for (int d = 0; d < 128; ++d) {
        features[i].descriptors(idx, d) = static_cast<uint8_t>(
            std::clamp<int>(point_descriptors[p](d) + random.UniformInt(-3, 3), 0, 255));
      }
    }
    ASSERT_GT(features[i].Size(), 250u) << "camera " << i << " sees too few points";
  }

  const fs::path db_path = dir_ / "database.db";
  {
    Database db = Database::Open(db_path.string());
    Database::Transaction transaction(db);
    const camera_t camera_id = db.WriteCamera(camera);
    std::vector<image_t> ids;
    for (int i = 0; i < kNumCameras; ++i) {
      ids.push_back(db.WriteFrame({kInvalidImageId, camera_id, fmt::format("frame_{:06d}.png", i)}));
      db.WriteFeatures(ids[i], features[i]);
    }
    for (int i = 0; i < kNumCameras; ++i) {
      for (int j = i + 1; j < kNumCameras; ++j) {
        FeatureMatches matches;
        for (const auto& [p, idx_i] : keypoint_of_point[i]) {
          const auto it = keypoint_of_point[j].find(p);
          if (it != keypoint_of_point[j].end()) matches.push_back({idx_i, it->second});
        }
        // Write every other pair in reversed order, so COLMAP reads our swapped rows too.
        if ((i + j) % 2 == 0) {
          db.WriteMatches(ids[i], ids[j], matches);
          db.WriteTwoViewGeometry(ids[i], ids[j],
                                  TrueGeometry(cam_from_world[i], cam_from_world[j], K, matches));
        } else {
          FeatureMatches reversed = matches;
          for (auto& m : reversed) std::swap(m.point2D_idx1, m.point2D_idx2);
          db.WriteMatches(ids[j], ids[i], reversed);
          db.WriteTwoViewGeometry(ids[j], ids[i],
                                  TrueGeometry(cam_from_world[j], cam_from_world[i], K, reversed));
        }
      }
    }
    transaction.Commit();
    EXPECT_EQ(db.NumVerifiedPairs(), static_cast<size_t>(kNumCameras * (kNumCameras - 1) / 2));
  }

  // The mapper needs no image files (it only fails to read colours).
  fs::create_directories(dir_ / "images");
  fs::create_directories(dir_ / "sparse");
  const auto start = std::chrono::steady_clock::now();
  RunColmap(fmt::format("mapper --database_path '{}' --image_path '{}' --output_path '{}' "
                        "--Mapper.num_threads 2",
                        db_path.string(), (dir_ / "images").string(), (dir_ / "sparse").string()),
            "mapper.log");
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cout << "colmap mapper took " << seconds << " s\n";
  if (HasFatalFailure()) return;
  ASSERT_TRUE(fs::exists(dir_ / "sparse" / "0" / "images.bin"));
  // COLMAP opened (and may have touched) our database; it is still ours.
  EXPECT_EQ(Database::Open(db_path.string()).NumFrames(), static_cast<size_t>(kNumCameras));
  EXPECT_FALSE(fs::exists(dir_ / "sparse" / "1")) << "the scene split into several models";

  const std::vector<ModelImage> model = ReadImagesBin(dir_ / "sparse" / "0" / "images.bin");
  ASSERT_EQ(model.size(), static_cast<size_t>(kNumCameras));
  EXPECT_GT(ReadNumPoints3D(dir_ / "sparse" / "0" / "points3D.bin"), 0.9 * kNumPoints);
  std::map<int, Rigid3d> estimated;
  for (const ModelImage& image : model) {
    const int i = image.image_id - 1;
    ASSERT_GE(i, 0);
    ASSERT_LT(i, kNumCameras);
    EXPECT_EQ(image.name, fmt::format("frame_{:06d}.png", i));
    estimated[i] = image.cam_from_world;
  }
  // Gauge-free checks: relative rotations, and camera-centre distances up to one scale.
  auto center = [](const Rigid3d& cam) { return cam.Inverse().translation; };
  const double scale = (center(estimated[0]) - center(estimated[kNumCameras - 1])).norm() /
                       (center(cam_from_world[0]) - center(cam_from_world[kNumCameras - 1])).norm();
  double max_rotation_error = 0, max_distance_error = 0;
  for (int i = 0; i < kNumCameras; ++i) {
    for (int j = i + 1; j < kNumCameras; ++j) {
      const Eigen::Quaterniond truth = cam_from_world[j].rotation * cam_from_world[i].rotation.inverse();
      const Eigen::Quaterniond est = estimated[j].rotation * estimated[i].rotation.inverse();
      const Eigen::Quaterniond error = truth.inverse() * est;
      max_rotation_error = std::max(
          max_rotation_error, 2 * std::atan2(error.vec().norm(), std::abs(error.w())) * 180 / M_PI);
      const double d_true = (center(cam_from_world[i]) - center(cam_from_world[j])).norm();
      const double d_est = (center(estimated[i]) - center(estimated[j])).norm() / scale;
      max_distance_error = std::max(max_distance_error, std::abs(d_est - d_true) / d_true);
    }
  }
  std::cout << "max relative rotation error " << max_rotation_error
            << " deg, max relative distance error " << max_distance_error << "\n";
  EXPECT_LT(max_rotation_error, 0.2) << "degrees";
  EXPECT_LT(max_distance_error, 0.01) << "relative";
}

// ---- databases written by COLMAP ---------------------------------------------------------

TEST_F(ColmapInteropTest, OpensEmptyColmapDatabase) {
  const std::string db_path = (dir_ / "colmap.db").string();
  RunColmap(fmt::format("database_creator --database_path '{}'", db_path), "creator.log");
  if (HasFatalFailure()) return;
  Database db = Database::Open(db_path);
  EXPECT_EQ(db.NumFrames(), 0u);
  const camera_t camera_id = db.WriteCamera(Camera::GuessFromImageSize(640, 480));
  EXPECT_EQ(db.WriteFrame({kInvalidImageId, camera_id, "x.png"}), 1u);
}

// A smooth random texture of blobs, so SIFT finds stable features.
std::vector<float> Texture(Random& random, int width, int height) {
  std::vector<float> image(width * height, 128.0f);
  for (int k = 0; k < 600; ++k) {
    const double cx = random.UniformReal(0, width), cy = random.UniformReal(0, height);
    const double r = random.UniformReal(3, 18), value = random.UniformReal(-90, 90);
    for (int y = std::max(0, int(cy - 3 * r)); y < std::min(height, int(cy + 3 * r)); ++y) {
      for (int x = std::max(0, int(cx - 3 * r)); x < std::min(width, int(cx + 3 * r)); ++x) {
        const double d2 = (x - cx) * (x - cx) + (y - cy) * (y - cy);
        image[y * width + x] += static_cast<float>(value * std::exp(-d2 / (2 * r * r)));
      }
    }
  }
  return image;
}

// Writes `texture` seen through img_from_texture (pixel indices) as a binary PGM.
void WritePgm(const fs::path& path, const std::vector<float>& texture, int width, int height,
              const Eigen::Matrix3d& img_from_texture) {
  const Eigen::Matrix3d texture_from_img = img_from_texture.inverse();
  std::ofstream out(path, std::ios::binary);
  out << "P5\n" << width << " " << height << "\n255\n";
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const Eigen::Vector3d s = texture_from_img * Eigen::Vector3d(x, y, 1);
      const double u = s.x() / s.z(), v = s.y() / s.z();
      float value = 128.0f;
      const int u0 = static_cast<int>(std::floor(u)), v0 = static_cast<int>(std::floor(v));
      if (u0 >= 0 && v0 >= 0 && u0 + 1 < width && v0 + 1 < height) {
        const double fu = u - u0, fv = v - v0;
        auto at = [&](int xx, int yy) { return texture[yy * width + xx]; };
        value = static_cast<float>((1 - fv) * ((1 - fu) * at(u0, v0) + fu * at(u0 + 1, v0)) +
                                   fv * ((1 - fu) * at(u0, v0 + 1) + fu * at(u0 + 1, v0 + 1)));
      }
      out.put(static_cast<char>(std::clamp(static_cast<int>(std::lround(value)), 0, 255)));
    }
  }
}

// COLMAP extracts and matches two views of a plane; we read its rows and check that its
// H, F and matches mean what we think they mean (orientation, row-major storage, swap).
TEST_F(ColmapInteropTest, ReadsFeaturesMatchesAndGeometryWrittenByColmap) {
  constexpr int kWidth = 640, kHeight = 480;
  Random random(5);
  const std::vector<float> texture = Texture(random, kWidth, kHeight);
  Eigen::Matrix3d warp;  // image b from image a, in pixel indices
  const double c = std::cos(0.08), s = std::sin(0.08);
  warp << 1.05 * c, -1.05 * s, 25, 1.05 * s, 1.05 * c, -10, 2e-5, -1e-5, 1;
  fs::create_directories(dir_ / "images");
  WritePgm(dir_ / "images" / "a.pgm", texture, kWidth, kHeight, Eigen::Matrix3d::Identity());
  WritePgm(dir_ / "images" / "b.pgm", texture, kWidth, kHeight, warp);

  const std::string db_path = (dir_ / "colmap.db").string();
  RunColmap(fmt::format("feature_extractor --database_path '{}' --image_path '{}' "
                        "--ImageReader.camera_model PINHOLE --ImageReader.single_camera 1 "
                        "--ImageReader.camera_params 500,500,320,240 "
                        "--SiftExtraction.use_gpu 0 --SiftExtraction.num_threads 2",
                        db_path, (dir_ / "images").string()),
            "extractor.log");
  if (HasFatalFailure()) return;
  RunColmap(fmt::format("exhaustive_matcher --database_path '{}' --SiftMatching.use_gpu 0 "
                        "--SiftMatching.num_threads 2",
                        db_path),
            "matcher.log");
  if (HasFatalFailure()) return;

  Database db = Database::Open(db_path);
  const auto cameras = db.ReadCameras();
  ASSERT_EQ(cameras.size(), 1u);
  EXPECT_EQ(cameras[0].model_id, CameraModelId::kPinhole);
  EXPECT_EQ(cameras[0].params, (std::vector<double>{500, 500, 320, 240}));
  const auto a = db.FindFrame("a.pgm"), b = db.FindFrame("b.pgm");
  ASSERT_TRUE(a && b);
  const FeatureSet fa = db.ReadFeatures(a->image_id), fb = db.ReadFeatures(b->image_id);
  EXPECT_GT(fa.Size(), 200u);
  EXPECT_EQ(static_cast<size_t>(fa.descriptors.rows()), fa.Size());
  EXPECT_TRUE(db.ExistsMatches(a->image_id, b->image_id));
  EXPECT_GT(db.ReadMatches(a->image_id, b->image_id).size(), 100u);

  const auto geometry = db.ReadTwoViewGeometry(a->image_id, b->image_id);
  ASSERT_TRUE(geometry.has_value());
  ASSERT_GT(geometry->inlier_matches.size(), 100u);
  std::cout << "COLMAP config " << geometry->config << ", "
            << geometry->inlier_matches.size() << " inliers\n";
  // COLMAP's pixel centres are at +0.5: the true warp in its convention.
  Eigen::Matrix3d shift = Eigen::Matrix3d::Identity();
  shift(0, 2) = shift(1, 2) = 0.5;
  const Eigen::Matrix3d true_h = shift * warp * shift.inverse();
  std::vector<double> h_errors, true_errors, f_errors;
  for (const FeatureMatch& m : geometry->inlier_matches) {
    const Eigen::Vector3d xa(fa.keypoints[m.point2D_idx1].x, fa.keypoints[m.point2D_idx1].y, 1);
    const Eigen::Vector3d xb(fb.keypoints[m.point2D_idx2].x, fb.keypoints[m.point2D_idx2].y, 1);
    h_errors.push_back(((geometry->H * xa).hnormalized() - xb.head<2>()).norm());
    true_errors.push_back(((true_h * xa).hnormalized() - xb.head<2>()).norm());
    const Eigen::Vector3d line = geometry->F * xa;
    f_errors.push_back(std::abs(xb.dot(line)) / line.head<2>().norm());
  }
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  EXPECT_LT(median(true_errors), 1.0) << "COLMAP's inliers do not follow the true warp";
  EXPECT_LT(median(h_errors), 1.0) << "H is not image b from image a";
  EXPECT_LT(median(f_errors), 1.0) << "F is not x_b' F x_a = 0";

  // The reversed read inverts H and transposes F.
  const auto reversed = db.ReadTwoViewGeometry(b->image_id, a->image_id);
  ASSERT_TRUE(reversed.has_value());
  const FeatureMatch m = reversed->inlier_matches.front();
  const Eigen::Vector3d xb(fb.keypoints[m.point2D_idx1].x, fb.keypoints[m.point2D_idx1].y, 1);
  const Eigen::Vector3d xa(fa.keypoints[m.point2D_idx2].x, fa.keypoints[m.point2D_idx2].y, 1);
  EXPECT_LT(((reversed->H * xb).hnormalized() - xa.head<2>()).norm(), 2.0);
}

}  // namespace
}  // namespace loopsfm

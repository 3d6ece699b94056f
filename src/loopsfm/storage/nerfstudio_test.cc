#include "loopsfm/storage/nerfstudio.h"

#include <gtest/gtest.h>

#include <fstream>

#include "loopsfm/storage/model_io_test_scene.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

// transform_matrix back to COLMAP's cam_from_world: OpenGL axes to OpenCV (negate the
// camera's y and z axes), then invert [R | C] as R^T, -R^T C.
Eigen::Matrix<double, 3, 4> CamFromWorldOf(const nlohmann::json& frame) {
  Eigen::Matrix4d c2w;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) c2w(r, c) = frame["transform_matrix"][r][c].get<double>();
  }
  EXPECT_EQ(c2w.row(3), Eigen::RowVector4d(0, 0, 0, 1));
  const Eigen::Matrix3d world_from_cam_gl = c2w.topLeftCorner<3, 3>();
  const Eigen::Matrix3d gl_from_cv = Eigen::Vector3d(1, -1, -1).asDiagonal();
  const Eigen::Matrix3d rotation = (world_from_cam_gl * gl_from_cv).transpose();
  Eigen::Matrix<double, 3, 4> cam_from_world;
  cam_from_world.leftCols<3>() = rotation;
  cam_from_world.col(3) = -rotation * c2w.block<3, 1>(0, 3);
  return cam_from_world;
}

TEST(Nerfstudio, PosesConvertBackToTheModelWithin1e9) {
  Reconstruction rec = model_io_test::MakeScene();
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "ns_poses";
  std::filesystem::create_directories(dir);
  WriteNerfstudioTransforms(dir / "transforms.json", NerfstudioTransforms(rec));
  std::ifstream in(dir / "transforms.json");
  const nlohmann::json transforms = nlohmann::json::parse(in);

  ASSERT_EQ(transforms["frames"].size(), rec.NumRegImages());
  EXPECT_EQ(transforms["ply_file_path"], "points.ply");
  for (const nlohmann::json& frame : transforms["frames"]) {
    const image_t id = frame["colmap_im_id"].get<image_t>();
    const Image& image = rec.GetImage(id);
    ASSERT_TRUE(image.registered);
    EXPECT_EQ(frame["file_path"], "images/" + image.name);
    const Eigen::Matrix<double, 3, 4> expected = image.cam_from_world.ToMatrix();
    EXPECT_LT((CamFromWorldOf(frame) - expected).cwiseAbs().maxCoeff(), 1e-9) << image.name;
  }
}

TEST(Nerfstudio, CameraCentreAndViewingDirectionUseOpenGLAxes) {
  // A camera at (1, 2, 3) looking along world +x: its OpenGL -z axis (forward) is world +x.
  Reconstruction rec = model_io_test::MakeScene();
  Image& image = rec.GetImage(1);
  const Eigen::Matrix3d world_from_cam_cv =
      (Eigen::Matrix3d() << 0, 0, 1, -1, 0, 0, 0, -1, 0).finished();  // columns: x, y, z axes
  image.cam_from_world =
      Rigid3d(Eigen::Quaterniond(world_from_cam_cv), Eigen::Vector3d(1, 2, 3)).Inverse();
  const nlohmann::json transforms = NerfstudioTransforms(rec);
  for (const nlohmann::json& frame : transforms["frames"]) {
    if (frame["colmap_im_id"] != 1) continue;
    const auto& m = frame["transform_matrix"];
    for (int r = 0; r < 3; ++r) {
      EXPECT_NEAR(m[r][3].get<double>(), (Eigen::Vector3d(1, 2, 3))(r), 1e-12);
      // -z (OpenGL forward) is world +x; +y (OpenGL up) is world +z.
      EXPECT_NEAR(-m[r][2].get<double>(), (Eigen::Vector3d(1, 0, 0))(r), 1e-12);
      EXPECT_NEAR(m[r][1].get<double>(), (Eigen::Vector3d(0, 0, 1))(r), 1e-12);
    }
  }
}

TEST(Nerfstudio, IntrinsicsPerFrameWhenFramesHaveDifferentCameras) {
  const Reconstruction rec = model_io_test::MakeScene();  // cameras 1 (PINHOLE), 7 (OPENCV)
  const nlohmann::json transforms = NerfstudioTransforms(rec);
  EXPECT_FALSE(transforms.contains("fl_x"));
  for (const nlohmann::json& frame : transforms["frames"]) {
    const Camera& camera = rec.GetCamera(rec.GetImage(frame["colmap_im_id"]).camera_id);
    EXPECT_EQ(frame["w"], camera.width);
    EXPECT_EQ(frame["h"], camera.height);
    EXPECT_EQ(frame["camera_model"], "OPENCV");
    EXPECT_EQ(frame["fl_x"], camera.params[0]);
    EXPECT_EQ(frame["fl_y"], camera.params[1]);
    EXPECT_EQ(frame["cx"], camera.params[2]);
    EXPECT_EQ(frame["cy"], camera.params[3]);
    if (camera.model_id == CameraModelId::kOpenCV) {
      EXPECT_EQ(frame["k1"], camera.params[4]);
      EXPECT_EQ(frame["k2"], camera.params[5]);
      EXPECT_EQ(frame["p1"], camera.params[6]);
      EXPECT_EQ(frame["p2"], camera.params[7]);
    } else {
      EXPECT_EQ(frame["k1"], 0.0);
    }
  }
}

TEST(Nerfstudio, SharedCameraAtTheTopLevel) {
  Reconstruction rec = model_io_test::MakeScene();
  for (image_t id : rec.RegImageIds()) rec.GetImage(id).camera_id = 1;
  Camera& camera = rec.GetCamera(1);
  camera.model_id = CameraModelId::kSimpleRadial;
  camera.params = {700.0, 320.5, 240.25, -0.12};
  const nlohmann::json transforms = NerfstudioTransforms(rec);
  EXPECT_EQ(transforms["camera_model"], "OPENCV");
  EXPECT_EQ(transforms["fl_x"], 700.0);
  EXPECT_EQ(transforms["fl_y"], 700.0);
  EXPECT_EQ(transforms["cx"], 320.5);
  EXPECT_EQ(transforms["cy"], 240.25);
  EXPECT_EQ(transforms["k1"], -0.12);
  EXPECT_EQ(transforms["k2"], 0.0);
  EXPECT_FALSE(transforms["frames"][0].contains("fl_x"));
}

TEST(Nerfstudio, FisheyeModelsBecomeOpenCVFisheye) {
  Camera camera;
  camera.camera_id = 3;
  camera.width = 1920;
  camera.height = 1080;
  camera.model_id = CameraModelId::kRadialFisheye;
  camera.params = {800.0, 960.0, 540.0, 0.05, -0.01};
  const nlohmann::json j = NerfstudioIntrinsics(camera);
  EXPECT_EQ(j["camera_model"], "OPENCV_FISHEYE");
  EXPECT_EQ(j["k1"], 0.05);
  EXPECT_EQ(j["k2"], -0.01);
  EXPECT_EQ(j["k3"], 0.0);
  EXPECT_EQ(j["k4"], 0.0);
  EXPECT_FALSE(j.contains("p1"));
}

TEST(Nerfstudio, RationalDistortionIsRefusedWithAWayOut) {
  Camera camera;
  camera.camera_id = 2;
  camera.width = 640;
  camera.height = 480;
  camera.model_id = CameraModelId::kFullOpenCV;
  camera.params = {500, 500, 320, 240, 0.1, 0.01, 0, 0, 0.001, 0.2, 0, 0};
  try {
    NerfstudioIntrinsics(camera);
    FAIL() << "FULL_OPENCV with k4 set was accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("gsplat"), std::string::npos) << e.what();
  }
  camera.params[9] = 0.0;  // k4 = 0: k1, k2, k3, p1, p2 fit OPENCV
  const nlohmann::json j = NerfstudioIntrinsics(camera);
  EXPECT_EQ(j["k3"], 0.001);
}

TEST(Nerfstudio, AModelWithoutRegisteredFramesIsRefused) {
  Reconstruction rec = model_io_test::MakeScene();
  for (image_t id : rec.RegImageIds()) rec.DeRegisterImage(id);
  EXPECT_THROW(NerfstudioTransforms(rec), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm

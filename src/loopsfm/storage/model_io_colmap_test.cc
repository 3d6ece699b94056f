// COLMAP 3.8 reads the model files we write: `colmap model_converter` turns our binary
// model into text (and our text model into binary), and we read COLMAP's output back to
// the same poses and points; `colmap model_analyzer` reports the right counts. Skipped
// when `colmap` is not on PATH.

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <sstream>

#include "loopsfm/storage/colmap_model.h"
#include "loopsfm/storage/model_io_test_scene.h"

namespace loopsfm {
namespace {

namespace fs = std::filesystem;
using model_io_test::ExpectSameModel;
using model_io_test::MakeScene;

class ModelIoColmapTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (std::system("command -v colmap > /dev/null 2>&1") != 0) {
      GTEST_SKIP() << "`colmap` is not on PATH; install COLMAP 3.8 to check interoperability";
    }
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           fmt::format("loopsfm_model_io_colmap_{}_{}", getpid(), info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    if (!dir_.empty() && !HasFailure()) fs::remove_all(dir_);
  }

  // Runs `colmap args`; returns its combined output, or records a failure with it.
  std::string RunColmap(const std::string& args) {
    const fs::path log = dir_ / "colmap.log";
    const int rc = std::system(("colmap " + args + " > '" + log.string() + "' 2>&1").c_str());
    std::ifstream in(log);
    std::stringstream text;
    text << in.rdbuf();
    EXPECT_EQ(rc, 0) << "colmap " << args << " failed:\n" << text.str();
    return text.str();
  }

  fs::path dir_;
};

TEST_F(ModelIoColmapTest, ColmapConvertsOurBinaryModelToTheSameTextModel) {
  const Reconstruction rec = MakeScene();
  WriteColmapModelBinary(dir_ / "bin", rec);
  fs::create_directories(dir_ / "txt");
  RunColmap(fmt::format("model_converter --input_path '{}' --output_path '{}' --output_type TXT",
                        (dir_ / "bin").string(), (dir_ / "txt").string()));
  ASSERT_TRUE(fs::exists(dir_ / "txt" / "images.txt"));
  // COLMAP prints 17 significant digits; allow for the last one.
  ExpectSameModel(rec, ReadColmapModelText(dir_ / "txt"), 1e-12);
}

TEST_F(ModelIoColmapTest, ColmapConvertsOurTextModelToTheSameBinaryModel) {
  const Reconstruction rec = MakeScene();
  WriteColmapModelText(dir_ / "txt", rec);
  fs::create_directories(dir_ / "bin");
  RunColmap(fmt::format("model_converter --input_path '{}' --output_path '{}' --output_type BIN",
                        (dir_ / "txt").string(), (dir_ / "bin").string()));
  ExpectSameModel(rec, ReadColmapModelBinary(dir_ / "bin"), 0.0);
}

TEST_F(ModelIoColmapTest, ColmapAnalyzerCountsOurModel) {
  const Reconstruction rec = MakeScene();
  WriteColmapModelBinary(dir_ / "bin", rec);
  const std::string out =
      RunColmap(fmt::format("model_analyzer --path '{}'", (dir_ / "bin").string()));
  EXPECT_NE(out.find("Cameras: 2"), std::string::npos) << out;
  EXPECT_NE(out.find("Registered images: 5"), std::string::npos) << out;
  EXPECT_NE(out.find(fmt::format("Points: {}", rec.NumPoints3D())), std::string::npos) << out;
  size_t observations = 0;
  for (const auto& [id, point] : rec.Points3D()) {
    for (const auto& el : point.track.elements) observations += rec.IsRegistered(el.image_id);
  }
  EXPECT_NE(out.find(fmt::format("Observations: {}", observations)), std::string::npos) << out;
}

}  // namespace
}  // namespace loopsfm

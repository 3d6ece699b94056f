#include "loopsfm/pipeline/export.h"

#include <gtest/gtest.h>

#include <fstream>

#include "loopsfm/scene/dataset_files.h"
#include "loopsfm/storage/colmap_model.h"
#include "loopsfm/storage/model_io_test_scene.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {
namespace fs = std::filesystem;

fs::path FreshDir(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / ("export_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

ExportOptions ModelFormats() {
  ExportOptions options;
  options.formats = ParseExportFormats("colmap,ply,tum,nerfstudio");
  options.colorize = false;  // no frames to read
  return options;
}

TEST(Export, NoModelLeavesEarlierResultsAlone) {
  const fs::path out = FreshDir("no_model");
  fs::create_directories(out / "sparse" / "0");
  std::ofstream(out / "sparse" / "0" / "cameras.bin") << "earlier";
  std::ofstream(out / "points.ply") << "earlier";
  std::vector<Reconstruction> none;
  const ExportReport report = Export(&none, {}, "", out, ModelFormats());
  EXPECT_TRUE(report.written.empty());
  EXPECT_TRUE(fs::exists(out / "sparse" / "0" / "cameras.bin"));
  EXPECT_TRUE(fs::exists(out / "points.ply"));
}

TEST(Export, NewModelsReplaceTheOldFoldersWhole) {
  const fs::path out = FreshDir("replace");
  // An earlier run left two models; this one makes one.
  fs::create_directories(out / "sparse" / "1");
  std::ofstream(out / "sparse" / "1" / "cameras.bin") << "stale";
  std::vector<Reconstruction> models = {model_io_test::MakeScene()};
  const ExportReport report = Export(&models, {}, "", out, ModelFormats());
  EXPECT_FALSE(fs::exists(out / "sparse" / "1")) << "a stale model of an earlier run is left";
  EXPECT_FALSE(fs::exists(out / "sparse.new"));
  const Reconstruction read = ReadColmapModel(out / "sparse" / "0");
  EXPECT_EQ(read.NumRegImages(), models[0].NumRegImages());
  EXPECT_EQ(read.NumPoints3D(), models[0].NumPoints3D());
  EXPECT_TRUE(fs::exists(out / "points.ply"));
  EXPECT_TRUE(fs::exists(out / "trajectory.txt"));
  EXPECT_TRUE(fs::exists(out / "transforms.json"));
  ASSERT_EQ(report.models.size(), 1u);
  EXPECT_EQ(report.models[0].num_registered, models[0].NumRegImages());
}

// Frames localised between keyframes (--all-frames): a pose each in the trajectory and
// transforms.json, in the COLMAP model only when asked, and never twice when a model that
// holds them is exported again with OUT/localized.txt.
TEST(Export, LocalizedFramesJoinThePathAndTheModelOnlyWhenAsked) {
  const fs::path out = FreshDir("localized");
  std::vector<Reconstruction> models = {model_io_test::MakeScene()};
  const Image& first = models[0].GetImage(models[0].RegImageIds().front());
  LocalizedFrame between;
  between.name = "between.png";
  between.pose.camera_id = first.camera_id;
  between.pose.cam_from_world = first.cam_from_world;
  const size_t keyframes = models[0].NumRegImages();

  Export(&models, {}, "", out, ModelFormats(), {between});
  EXPECT_EQ(ReadTrajectoryFile(out / "trajectory.txt").size(), keyframes + 1);
  EXPECT_EQ(ReadColmapModel(out / "sparse" / "0").NumRegImages(), keyframes);
  std::ifstream transforms(out / "transforms.json");
  const std::string text((std::istreambuf_iterator<char>(transforms)), {});
  EXPECT_NE(text.find("between.png"), std::string::npos);

  ExportOptions in_model = ModelFormats();
  in_model.localized_in_model = true;
  Export(&models, {}, "", out, in_model, {between});
  const Reconstruction written = ReadColmapModel(out / "sparse" / "0");
  ASSERT_EQ(written.NumRegImages(), keyframes + 1);
  WriteTrajectoryFile(out / "localized.txt", {{"between.png", first.cam_from_world.Inverse()}});
  ExportRun(out, std::nullopt, in_model);
  EXPECT_EQ(ReadColmapModel(out / "sparse" / "0").NumRegImages(), keyframes + 1);
  EXPECT_EQ(ReadTrajectoryFile(out / "trajectory.txt").size(), keyframes + 1);
}

TEST(Export, FormatListsAreParsedAndCheckedByName) {
  EXPECT_EQ(ParseExportFormats("none").size(), 0u);
  EXPECT_EQ(ParseExportFormats("ply,tum"),
            (std::set<ExportFormat>{ExportFormat::kPly, ExportFormat::kTum}));
  EXPECT_TRUE(ParseExportFormats("all").count(ExportFormat::kGsplat));
  EXPECT_FALSE(ParseExportFormats("default").count(ExportFormat::kGsplat));
  EXPECT_TRUE(ParseExportFormats("default").count(ExportFormat::kReport));
  try {
    ParseExportFormats("ply,,tum");
    FAIL() << "an empty entry was accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("nerfstudio"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ParseExportFormats("PLY"), InvalidArgument);
}

}  // namespace
}  // namespace loopsfm

#include "loopsfm/pipeline/export.h"

#include <gtest/gtest.h>

#include <fstream>

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

#include "loopsfm/storage/database.h"

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include <Eigen/Geometry>

#include "loopsfm/math/random.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

namespace fs = std::filesystem;

class DatabaseTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           fmt::format("loopsfm_database_test_{}_{}", getpid(), info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    path_ = (dir_ / "database.db").string();
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path dir_;
  std::string path_;
};

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Runs SQL on a raw connection, as another program (or COLMAP) would.
void RawExec(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  char* error = nullptr;
  const int rc = sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &error);
  EXPECT_EQ(rc, SQLITE_OK) << (error ? error : "");
  sqlite3_free(error);
  sqlite3_close(db);
}

// The raw bytes of one blob, for checking the on-disk layout.
std::string RawBlob(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  EXPECT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* stmt = nullptr;
  EXPECT_EQ(sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt, nullptr), SQLITE_OK);
  std::string bytes;
  if (sqlite3_step(stmt) == SQLITE_ROW) {
    bytes.assign(static_cast<const char*>(sqlite3_column_blob(stmt, 0)),
                 sqlite3_column_bytes(stmt, 0));
  }
  sqlite3_finalize(stmt);
  sqlite3_close(db);
  return bytes;
}

Camera TestCamera() {
  Camera camera;
  camera.model_id = CameraModelId::kOpenCV;
  camera.width = 1280;
  camera.height = 720;
  camera.params = {900.5, 901.25, 640.1, 359.7, 0.01, -0.002, 0.0003, -0.0004};
  camera.has_prior_focal_length = true;
  return camera;
}

FeatureSet RandomFeatures(Random& random, int n) {
  FeatureSet set;
  for (int i = 0; i < n; ++i) {
    set.keypoints.push_back(FeatureKeypoint::FromScaleOrientation(
        random.UniformReal(0, 640), random.UniformReal(0, 480), random.UniformReal(1, 10),
        random.UniformReal(-3, 3)));
  }
  set.descriptors.resize(n, kDescriptorDim);
  for (int i = 0; i < set.descriptors.size(); ++i) {
    set.descriptors.data()[i] = static_cast<uint8_t>(random.UniformInt(0, 255));
  }
  return set;
}

// Two frames with one camera each; returns their ids (1 and 2).
std::pair<image_t, image_t> AddTwoFrames(Database& db) {
  const camera_t camera_id = db.WriteCamera(Camera::GuessFromImageSize(640, 480));
  return {db.WriteFrame({kInvalidImageId, camera_id, "a.png"}),
          db.WriteFrame({kInvalidImageId, camera_id, "b.png"})};
}

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

TEST(PairId, PacksLikeColmap) {
  EXPECT_EQ(PairToPairId(1, 2), 2147483647ull + 2);
  EXPECT_EQ(PairToPairId(2, 1), PairToPairId(1, 2));
  EXPECT_EQ(PairToPairId(7, 3), 3ull * 2147483647ull + 7);
  const ImagePair pair = PairIdToPair(PairToPairId(123456, 2000000000));
  EXPECT_EQ(pair.image_id1, 123456u);
  EXPECT_EQ(pair.image_id2, 2000000000u);
  EXPECT_TRUE(SwapImagePair(5, 4));
  EXPECT_FALSE(SwapImagePair(4, 5));
}

TEST_F(DatabaseTest, CreatesColmapSchema) {
  { Database::Open(path_); }
  // Column lists of `colmap database_creator` (COLMAP 3.8), in order.
  const std::map<std::string, std::vector<std::string>> expected = {
      {"cameras", {"camera_id", "model", "width", "height", "params", "prior_focal_length"}},
      {"images",
       {"image_id", "name", "camera_id", "prior_qw", "prior_qx", "prior_qy", "prior_qz",
        "prior_tx", "prior_ty", "prior_tz"}},
      {"keypoints", {"image_id", "rows", "cols", "data"}},
      {"descriptors", {"image_id", "rows", "cols", "data"}},
      {"matches", {"pair_id", "rows", "cols", "data"}},
      {"two_view_geometries",
       {"pair_id", "rows", "cols", "data", "config", "F", "E", "H", "qvec", "tvec"}},
  };
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path_.c_str(), &db), SQLITE_OK);
  for (const auto& [table, columns] : expected) {
    sqlite3_stmt* stmt = nullptr;
    ASSERT_EQ(sqlite3_prepare_v2(db, ("PRAGMA table_info(" + table + ")").c_str(), -1, &stmt,
                                 nullptr),
              SQLITE_OK);
    std::vector<std::string> got;
    while (sqlite3_step(stmt) == SQLITE_ROW) {
      got.emplace_back(reinterpret_cast<const char*>(sqlite3_column_text(stmt, 1)));
    }
    sqlite3_finalize(stmt);
    EXPECT_EQ(got, columns) << table;
  }
  sqlite3_close(db);
}

TEST_F(DatabaseTest, CamerasRoundTrip) {
  Database db = Database::Open(path_);
  const Camera camera = TestCamera();
  const camera_t id1 = db.WriteCamera(camera);
  const camera_t id2 = db.WriteCamera(Camera::GuessFromImageSize(640, 480));
  EXPECT_EQ(id1, 1u);
  EXPECT_EQ(id2, 2u);
  const auto read = db.ReadCamera(id1);
  ASSERT_TRUE(read.has_value());
  EXPECT_TRUE(read->SameIntrinsics(camera));
  EXPECT_TRUE(read->has_prior_focal_length);
  EXPECT_EQ(read->camera_id, id1);
  EXPECT_FALSE(db.ReadCamera(99).has_value());

  // Writing with an id updates that row.
  Camera updated = *read;
  updated.params[0] = 1000.0;
  EXPECT_EQ(db.WriteCamera(updated), id1);
  EXPECT_EQ(db.NumCameras(), 2u);
  EXPECT_DOUBLE_EQ(db.ReadCameras().at(0).params[0], 1000.0);
  EXPECT_EQ(db.ReadCameras().at(1).model_id, CameraModelId::kSimpleRadial);

  // params are a blob of doubles in the model's order (SIMPLE_RADIAL: f, cx, cy, k).
  const std::string blob = RawBlob(path_, "SELECT params FROM cameras WHERE camera_id = 2");
  ASSERT_EQ(blob.size(), 4 * sizeof(double));
  double params[4];
  std::memcpy(params, blob.data(), blob.size());
  EXPECT_EQ(params[0], 1.2 * 640);
  EXPECT_EQ(params[1], 320.0);
  EXPECT_EQ(params[2], 240.0);
  EXPECT_EQ(params[3], 0.0);
}

TEST_F(DatabaseTest, EveryCameraModelRoundTrips) {
  Database db = Database::Open(path_);
  for (const CameraModelId id : kCameraModelIds) {
    Camera camera = TestCamera();
    camera.model_id = id;
    camera.params.clear();
    for (int i = 0; i < CameraModelNumParams(id); ++i) camera.params.push_back(900.0 / (i + 1));
    const auto read = db.ReadCamera(db.WriteCamera(camera));
    ASSERT_TRUE(read.has_value());
    EXPECT_EQ(read->model_id, id);
    EXPECT_TRUE(read->SameIntrinsics(camera)) << camera.ModelName();
  }
}

TEST_F(DatabaseTest, FramesAreIdempotentByName) {
  Database db = Database::Open(path_);
  const camera_t camera_id = db.WriteCamera(TestCamera());
  const image_t a = db.WriteFrame({kInvalidImageId, camera_id, "frame_000000.png"});
  const image_t b = db.WriteFrame({kInvalidImageId, camera_id, "frame_000010.png"});
  EXPECT_EQ(a, 1u);
  EXPECT_EQ(b, 2u);
  EXPECT_EQ(db.WriteFrame({kInvalidImageId, camera_id, "frame_000000.png"}), a);
  EXPECT_EQ(db.WriteFrame({b, camera_id, "frame_000010.png"}), b);
  EXPECT_EQ(db.NumFrames(), 2u);
  EXPECT_TRUE(db.ExistsFrame("frame_000010.png"));
  EXPECT_FALSE(db.ExistsFrame("frame_000020.png"));
  const auto found = db.FindFrame("frame_000010.png");
  ASSERT_TRUE(found.has_value());
  EXPECT_EQ(found->image_id, b);
  EXPECT_EQ(found->camera_id, camera_id);
  const auto frames = db.ReadFrames();
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames[0].name, "frame_000000.png");
  EXPECT_EQ(frames[1].image_id, b);

  // A given id is honoured, and conflicts are refused.
  EXPECT_EQ(db.WriteFrame({7, camera_id, "seven.png"}), 7u);
  EXPECT_THROW(db.WriteFrame({8, camera_id, "seven.png"}), StorageError);
  EXPECT_THROW(db.WriteFrame({7, camera_id, "other.png"}), StorageError);
  EXPECT_THROW(db.WriteFrame({kInvalidImageId, 42, "no_camera.png"}), StorageError);
  EXPECT_EQ(db.NumFrames(), 3u);

  db.WriteFrameOrigin(b, {10, 123.5, "parallax"});
  const auto source = db.ReadFrameOrigin(b);
  ASSERT_TRUE(source.has_value());
  EXPECT_EQ(source->source_index, 10);
  EXPECT_EQ(source->sharpness, 123.5);
  EXPECT_EQ(source->reason, "parallax");
  EXPECT_FALSE(db.ReadFrameOrigin(a).has_value());
  const auto all = db.ReadFrameOrigins();
  ASSERT_EQ(all.size(), 1u);
  EXPECT_EQ(all.at(b).reason, "parallax");
}

// A database written before frames recorded why they were kept gets the column on opening;
// its frames read back with an empty reason.
TEST_F(DatabaseTest, FrameOriginsWithoutReasonColumnAreUpgraded) {
  image_t b = 0;
  {
    Database db = Database::Open(path_);
    b = AddTwoFrames(db).second;
    db.WriteFrameOrigin(b, {7, 1.0, "first"});
  }
  // The table as loopsfm wrote it before the column.
  RawExec(path_,
          "CREATE TABLE old (image_id INTEGER PRIMARY KEY NOT NULL, source_index INTEGER NOT "
          "NULL, sharpness REAL NOT NULL, FOREIGN KEY(image_id) REFERENCES images(image_id) ON "
          "DELETE CASCADE);"
          "INSERT INTO old SELECT image_id, source_index, sharpness FROM loopsfm_frames;"
          "DROP TABLE loopsfm_frames; ALTER TABLE old RENAME TO loopsfm_frames;");
  Database db = Database::Open(path_);
  const auto source = db.ReadFrameOrigin(b);
  ASSERT_TRUE(source.has_value());
  EXPECT_EQ(source->source_index, 7);
  EXPECT_EQ(source->reason, "");
  db.WriteFrameOrigin(b, {7, 1.0, "fill-in"});
  EXPECT_EQ(db.ReadFrameOrigin(b)->reason, "fill-in");
}

TEST_F(DatabaseTest, FeaturesRoundTrip) {
  Database db = Database::Open(path_);
  const auto [a, b] = AddTwoFrames(db);
  Random random(1);
  const FeatureSet features = RandomFeatures(random, 300);
  EXPECT_FALSE(db.HasFeatures(a));
  db.WriteFeatures(a, features);
  EXPECT_TRUE(db.HasFeatures(a));
  EXPECT_FALSE(db.HasFeatures(b));

  const FeatureSet read = db.ReadFeatures(a);
  ASSERT_EQ(read.Size(), 300u);
  for (size_t i = 0; i < read.Size(); ++i) {
    EXPECT_EQ(read.keypoints[i].x, features.keypoints[i].x);
    EXPECT_EQ(read.keypoints[i].a12, features.keypoints[i].a12);
    EXPECT_EQ(read.keypoints[i].a22, features.keypoints[i].a22);
  }
  EXPECT_EQ(read.descriptors, features.descriptors);
  EXPECT_TRUE(db.ReadKeypoints(b).empty());
  EXPECT_EQ(db.ReadDescriptors(b).rows(), 0);

  // Keypoints are float32 rows of (x, y, a11, a12, a21, a22).
  const std::string blob = RawBlob(path_, "SELECT data FROM keypoints WHERE image_id = 1");
  ASSERT_EQ(blob.size(), 300 * 6 * sizeof(float));
  float row[6];
  std::memcpy(row, blob.data() + 6 * sizeof(float), sizeof(row));
  EXPECT_EQ(row[0], features.keypoints[1].x);
  EXPECT_EQ(row[3], features.keypoints[1].a12);
  // Descriptors are uint8 rows of 128.
  const std::string desc = RawBlob(path_, "SELECT data FROM descriptors WHERE image_id = 1");
  ASSERT_EQ(desc.size(), 300u * 128u);
  EXPECT_EQ(static_cast<uint8_t>(desc[128 + 5]), features.descriptors(1, 5));

  // Writing again replaces.
  db.WriteFeatures(a, RandomFeatures(random, 5));
  EXPECT_EQ(db.ReadKeypoints(a).size(), 5u);
}

TEST_F(DatabaseTest, ReadsTwoAndFourColumnKeypoints) {
  { Database db = Database::Open(path_); AddTwoFrames(db); }
  const float four[2][4] = {{10.5f, 20.5f, 3.0f, 0.5f}, {1.0f, 2.0f, 1.5f, -1.0f}};
  const float two[1][2] = {{7.25f, 8.75f}};
  sqlite3* raw = nullptr;
  ASSERT_EQ(sqlite3_open(path_.c_str(), &raw), SQLITE_OK);
  sqlite3_stmt* stmt = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(raw, "INSERT INTO keypoints VALUES(?, ?, ?, ?)", -1, &stmt, nullptr),
            SQLITE_OK);
  auto insert = [&](int image_id, int rows, int cols, const void* data) {
    sqlite3_bind_int(stmt, 1, image_id);
    sqlite3_bind_int(stmt, 2, rows);
    sqlite3_bind_int(stmt, 3, cols);
    sqlite3_bind_blob(stmt, 4, data, rows * cols * sizeof(float), SQLITE_STATIC);
    EXPECT_EQ(sqlite3_step(stmt), SQLITE_DONE);
    sqlite3_reset(stmt);
  };
  insert(1, 2, 4, four);
  insert(2, 1, 2, two);
  sqlite3_finalize(stmt);
  sqlite3_close(raw);

  Database db = Database::Open(path_);
  const FeatureKeypoints k4 = db.ReadKeypoints(1);
  ASSERT_EQ(k4.size(), 2u);
  EXPECT_EQ(k4[0].x, 10.5f);
  EXPECT_NEAR(k4[0].Scale(), 3.0f, 1e-5);
  EXPECT_NEAR(k4[0].Orientation(), 0.5f, 1e-5);
  EXPECT_NEAR(k4[1].Orientation(), -1.0f, 1e-5);
  EXPECT_NEAR(k4[0].a12, -3.0f * std::sin(0.5f), 1e-5);
  const FeatureKeypoints k2 = db.ReadKeypoints(2);
  ASSERT_EQ(k2.size(), 1u);
  EXPECT_EQ(k2[0].y, 8.75f);
  EXPECT_EQ(k2[0].a11, 1.0f);
  EXPECT_EQ(k2[0].a12, 0.0f);
}

TEST_F(DatabaseTest, MatchesAreSwappedForReversedPairs) {
  Database db = Database::Open(path_);
  const auto [a, b] = AddTwoFrames(db);
  const camera_t camera_id = db.ReadFrame(a)->camera_id;
  const image_t c = db.WriteFrame({kInvalidImageId, camera_id, "c.png"});
  const FeatureMatches matches = {{0, 5}, {1, 7}, {4, 2}};
  db.WriteMatches(b, a, matches);  // stored as (a, b) with columns swapped
  EXPECT_TRUE(db.ExistsMatches(a, b));
  EXPECT_TRUE(db.ExistsMatches(b, a));
  EXPECT_EQ(db.ReadMatches(b, a), matches);
  const FeatureMatches forward = db.ReadMatches(a, b);
  ASSERT_EQ(forward.size(), 3u);
  EXPECT_EQ(forward[2], (FeatureMatch{2, 4}));
  const std::string blob =
      RawBlob(path_, fmt::format("SELECT data FROM matches WHERE pair_id = {}", PairToPairId(a, b)));
  ASSERT_EQ(blob.size(), 6 * sizeof(uint32_t));
  uint32_t raw[6];
  std::memcpy(raw, blob.data(), blob.size());
  EXPECT_EQ(raw[0], 5u);  // row 0 = (idx in a, idx in b)
  EXPECT_EQ(raw[1], 0u);

  // An empty row records a tried pair.
  EXPECT_FALSE(db.ExistsMatches(a, c));
  db.WriteMatches(a, c, {});
  EXPECT_TRUE(db.ExistsMatches(c, a));
  EXPECT_TRUE(db.ReadMatches(a, c).empty());
  EXPECT_EQ(db.NumMatchedPairs(), 2u);
  EXPECT_EQ(db.ReadAllMatchedPairs(), (std::vector<ImagePair>{{a, b}, {a, c}}));
  const auto all = db.ReadAllMatches();
  ASSERT_EQ(all.size(), 2u);
  EXPECT_EQ(all[0].second, forward);

  db.WriteMatches(a, b, {{9, 9}});  // replaces
  EXPECT_EQ(db.ReadMatches(a, b).size(), 1u);
  db.ClearMatches();
  EXPECT_EQ(db.NumMatchedPairs(), 0u);
}

TEST_F(DatabaseTest, TwoViewGeometryRoundTripsInBothOrders) {
  Database db = Database::Open(path_);
  const auto [a, b] = AddTwoFrames(db);
  Random random(7);
  const Eigen::Quaterniond rotation =
      Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.2, 1, -0.1).normalized()));
  const Rigid3d b_from_a(rotation, Eigen::Vector3d(0.8, -0.1, 0.2).normalized());
  Eigen::Matrix3d K;
  K << 500, 0, 320, 0, 520, 240, 0, 0, 1;
  TwoViewGeometry geometry;
  geometry.config = TwoViewGeometry::kCalibrated;
  geometry.E = Skew(b_from_a.translation) * b_from_a.rotation.toRotationMatrix();
  geometry.F = K.inverse().transpose() * geometry.E * K.inverse();
  geometry.H << 1.1, 0.05, 12, -0.02, 0.95, -7, 1e-4, 2e-4, 1;
  geometry.cam2_from_cam1 = b_from_a;
  geometry.inlier_matches = {{0, 1}, {2, 3}, {5, 4}};

  // A point seen by both cameras, for checking the epipolar constraints.
  const Eigen::Vector3d point_in_a(0.3, -0.2, 4.0);
  const Eigen::Vector3d xa = K * (point_in_a / point_in_a.z());
  const Eigen::Vector3d point_in_b = b_from_a * point_in_a;
  const Eigen::Vector3d xb = K * (point_in_b / point_in_b.z());
  ASSERT_NEAR(xb.dot(geometry.F * xa), 0.0, 1e-9);

  db.WriteTwoViewGeometry(a, b, geometry);
  EXPECT_TRUE(db.ExistsTwoViewGeometry(b, a));
  const auto ab = db.ReadTwoViewGeometry(a, b);
  ASSERT_TRUE(ab.has_value());
  EXPECT_EQ(ab->config, TwoViewGeometry::kCalibrated);
  EXPECT_EQ(ab->F, geometry.F);
  EXPECT_EQ(ab->E, geometry.E);
  EXPECT_EQ(ab->H, geometry.H);
  EXPECT_TRUE(ab->cam2_from_cam1.rotation.isApprox(rotation, 1e-15));
  EXPECT_EQ(ab->cam2_from_cam1.translation, b_from_a.translation);
  EXPECT_EQ(ab->inlier_matches, geometry.inlier_matches);

  // F, E, H are stored row-major; qvec as (w, x, y, z).
  const std::string f_blob = RawBlob(path_, "SELECT F FROM two_view_geometries");
  ASSERT_EQ(f_blob.size(), 9 * sizeof(double));
  double f[9];
  std::memcpy(f, f_blob.data(), sizeof(f));
  EXPECT_EQ(f[1], geometry.F(0, 1));
  EXPECT_EQ(f[3], geometry.F(1, 0));
  double h[9];
  std::memcpy(h, RawBlob(path_, "SELECT H FROM two_view_geometries").data(), sizeof(h));
  EXPECT_EQ(h[2], 12.0);
  double q[4];
  std::memcpy(q, RawBlob(path_, "SELECT qvec FROM two_view_geometries").data(), sizeof(q));
  EXPECT_EQ(q[0], rotation.w());
  EXPECT_EQ(q[3], rotation.z());

  // Read in the other order: the geometry of (b, a).
  const auto ba = db.ReadTwoViewGeometry(b, a);
  ASSERT_TRUE(ba.has_value());
  EXPECT_NEAR(xa.dot(ba->F * xb), 0.0, 1e-9);
  const Eigen::Vector3d na = K.inverse() * xa, nb = K.inverse() * xb;
  EXPECT_NEAR(na.dot(ba->E * nb), 0.0, 1e-12);
  EXPECT_TRUE((ba->H * geometry.H).isApprox(Eigen::Matrix3d::Identity(), 1e-12));
  EXPECT_TRUE((ba->cam2_from_cam1 * point_in_b).isApprox(point_in_a, 1e-12));
  EXPECT_EQ(ba->inlier_matches[2], (FeatureMatch{4, 5}));

  // Writing the (b, a) view stores the same row.
  db.WriteTwoViewGeometry(b, a, *ba);
  const auto again = db.ReadTwoViewGeometry(a, b);
  EXPECT_TRUE(again->F.isApprox(geometry.F, 1e-12));
  EXPECT_TRUE(again->H.isApprox(geometry.H, 1e-12));
  EXPECT_TRUE((again->cam2_from_cam1 * point_in_a).isApprox(point_in_b, 1e-12));
  EXPECT_EQ(again->inlier_matches, geometry.inlier_matches);

  const auto all = db.ReadAllTwoViewGeometries();
  ASSERT_EQ(all.size(), 1u);
  EXPECT_EQ(all[0].first, ImagePair(a, b));
  EXPECT_EQ(all[0].second.inlier_matches, geometry.inlier_matches);
}

TEST_F(DatabaseTest, VerifiedPairsSkipDegenerateAndEmpty) {
  Database db = Database::Open(path_);
  const auto [a, b] = AddTwoFrames(db);
  const camera_t camera_id = db.ReadFrame(a)->camera_id;
  const image_t c = db.WriteFrame({kInvalidImageId, camera_id, "c.png"});
  TwoViewGeometry good;
  good.config = TwoViewGeometry::kUncalibrated;
  good.inlier_matches = {{0, 0}, {1, 1}};
  TwoViewGeometry degenerate = good;
  degenerate.config = TwoViewGeometry::kDegenerate;
  TwoViewGeometry empty;  // tried, nothing found; H zero must survive the swap
  empty.config = TwoViewGeometry::kUndefined;
  db.WriteTwoViewGeometry(b, a, good);
  db.WriteTwoViewGeometry(a, c, degenerate);
  db.WriteTwoViewGeometry(c, b, empty);
  EXPECT_EQ(db.NumVerifiedPairs(), 1u);
  const auto verified = db.ReadVerifiedPairs();
  ASSERT_EQ(verified.size(), 1u);
  EXPECT_EQ(verified[0].pair, ImagePair(a, b));
  EXPECT_EQ(verified[0].num_inliers, 2);
  EXPECT_EQ(verified[0].config, TwoViewGeometry::kUncalibrated);
  const auto read_empty = db.ReadTwoViewGeometry(b, c);
  ASSERT_TRUE(read_empty.has_value());
  EXPECT_TRUE(read_empty->H.allFinite());
  EXPECT_TRUE(read_empty->inlier_matches.empty());
  EXPECT_EQ(db.ReadAllTwoViewGeometries().size(), 3u);
  db.ClearTwoViewGeometries();
  EXPECT_FALSE(db.ExistsTwoViewGeometry(a, b));
}

TEST_F(DatabaseTest, ResumeSeesStoredRowsAndRollsBackFailedBatches) {
  Random random(3);
  {
    Database db = Database::Open(path_);
    const auto [a, b] = AddTwoFrames(db);
    Database::Transaction transaction(db);
    db.WriteFeatures(a, RandomFeatures(random, 10));
    db.WriteMatches(a, b, {{1, 2}});
    db.WriteMeta("stage.features", "done");
  }
  {
    Database db = Database::Open(path_);
    EXPECT_EQ(db.NumFrames(), 2u);
    EXPECT_TRUE(db.HasFeatures(1));
    EXPECT_EQ(db.ReadMatches(1, 2).size(), 1u);
    EXPECT_EQ(db.ReadMeta("stage.features"), "done");
    EXPECT_EQ(db.ReadMeta("schema_version"), std::to_string(Database::kSchemaVersion));
    // A batch interrupted by an error leaves nothing behind.
    try {
      Database::Transaction transaction(db);
      db.WriteFeatures(2, RandomFeatures(random, 10));
      db.WriteMatches(2, 1, {});
      throw std::runtime_error("simulated failure");
    } catch (const std::runtime_error&) {
    }
    EXPECT_FALSE(db.HasFeatures(2));
    EXPECT_EQ(db.ReadMatches(1, 2).size(), 1u);
    // Re-running the stage gives the same ids.
    EXPECT_EQ(db.WriteFrame({kInvalidImageId, 1, "b.png"}), 2u);
  }
}

TEST_F(DatabaseTest, RefusesFilesThatAreNotSqlite) {
  const fs::path text = dir_ / "notes.db";
  std::ofstream(text) << "camera poses, to do: everything\n";
  const fs::path video = dir_ / "video.db";
  {
    std::ofstream out(video, std::ios::binary);
    const char mp4[] = "\x00\x00\x00\x20" "ftypisom\x00\x00\x02\x00isomiso2avc1mp41";
    out.write(mp4, sizeof(mp4));
    for (int i = 0; i < 5000; ++i) out.put(static_cast<char>(i * 31));
  }
  for (const fs::path& path : {text, video}) {
    const std::string before = ReadBytes(path);
    try {
      Database::Open(path.string());
      FAIL() << path;
    } catch (const StorageError& e) {
      EXPECT_NE(std::string(e.what()).find("not a SQLite database"), std::string::npos)
          << e.what();
      EXPECT_NE(std::string(e.what()).find("left unchanged"), std::string::npos) << e.what();
    }
    EXPECT_EQ(ReadBytes(path), before);
    EXPECT_FALSE(fs::exists(path.string() + "-wal"));
    EXPECT_FALSE(fs::exists(path.string() + "-journal"));
  }
}

TEST_F(DatabaseTest, RefusesSomeoneElsesSqliteDatabase) {
  RawExec(path_,
          "CREATE TABLE users(id INTEGER PRIMARY KEY, name TEXT);"
          "INSERT INTO users VALUES(1, 'ada');"
          "CREATE TABLE orders(id INTEGER, user INTEGER);");
  const std::string before = ReadBytes(path_);
  try {
    Database::Open(path_);
    FAIL();
  } catch (const StorageError& e) {
    EXPECT_NE(std::string(e.what()).find("another program"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("users"), std::string::npos) << e.what();
  }
  EXPECT_EQ(ReadBytes(path_), before);

  // A table with COLMAP's name but not its columns is not COLMAP's either.
  const std::string other = (dir_ / "other.db").string();
  RawExec(other, "CREATE TABLE cameras(id INTEGER, label TEXT); CREATE TABLE images(path TEXT);");
  const std::string other_before = ReadBytes(other);
  EXPECT_THROW(Database::Open(other), StorageError);
  EXPECT_EQ(ReadBytes(other), other_before);
}

TEST_F(DatabaseTest, RefusesFoldersAndMissingFolders) {
  try {
    Database::Open(dir_.string());
    FAIL();
  } catch (const StorageError& e) {
    EXPECT_NE(std::string(e.what()).find("is a folder"), std::string::npos) << e.what();
  }
  const fs::path missing = dir_ / "no_such_folder" / "database.db";
  try {
    Database::Open(missing.string());
    FAIL();
  } catch (const StorageError& e) {
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(missing.parent_path()));
}

TEST_F(DatabaseTest, RefusesDatabaseOfNewerLoopsfm) {
  { Database db = Database::Open(path_); db.WriteMeta("schema_version", "99"); }
  const std::string before = ReadBytes(path_);
  EXPECT_THROW(Database::Open(path_), StorageError);
  EXPECT_EQ(ReadBytes(path_), before);
}

TEST_F(DatabaseTest, OpensEmptyFileAndMovedDatabase) {
  std::ofstream(path_).close();  // zero bytes: an empty SQLite database
  Database db = Database::Open(path_);
  db.WriteCamera(TestCamera());
  Database moved = std::move(db);
  EXPECT_EQ(moved.NumCameras(), 1u);
  EXPECT_EQ(moved.Path(), path_);
}

}  // namespace
}  // namespace loopsfm

namespace loopsfm {
namespace {

// A camera row that no camera can have (written by another tool, or damaged): a clear
// StorageError naming the camera, not a camera with a zero size or a NaN focal length.
TEST(Database, ImpossibleCameraRowsAreRefused) {
  const std::string path =
      (std::filesystem::temp_directory_path() / "loopsfm_db_bad_camera.db").string();
  for (const char* update : {"UPDATE cameras SET width = 0",
                             "UPDATE cameras SET params = zeroblob(32)",
                             "UPDATE cameras SET params = X'000000000000F87F000000000000F87F"
                             "000000000000F87F000000000000F87F'"}) {
    for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path + suffix);
    {
      Database db = Database::Open(path);
      ASSERT_EQ(db.WriteCamera(Camera::GuessFromImageSize(640, 480)), 1u);
    }
    sqlite3* raw = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &raw), SQLITE_OK);
    ASSERT_EQ(sqlite3_exec(raw, update, nullptr, nullptr, nullptr), SQLITE_OK) << update;
    sqlite3_close(raw);
    const Database db = Database::Open(path);
    try {
      db.ReadCameras();
      ADD_FAILURE() << update << ": read without an error";
    } catch (const StorageError& e) {
      EXPECT_NE(std::string(e.what()).find("camera 1"), std::string::npos) << e.what();
    }
  }
  for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path + suffix);
}

}  // namespace
}  // namespace loopsfm

#include "loopsfm/storage/database.h"

#include <sqlite3.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include <Eigen/LU>

#include "loopsfm/storage/sqlite_util.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using namespace sqlite;  // this module's SQLite helpers

static_assert(sizeof(FeatureKeypoint) == 6 * sizeof(float), "keypoint blob layout");
static_assert(sizeof(FeatureMatch) == 2 * sizeof(uint32_t), "match blob layout");

using RowMajor3d = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;

FeatureMatches MatchesFromBlob(const BlobView& blob, bool swap, const std::string& what) {
  if (blob.rows > 0 && blob.cols != 2) {
    throw StorageError(fmt::format("{} has {} columns, expected 2", what, blob.cols));
  }
  FeatureMatches matches(blob.rows);
  if (blob.rows > 0) std::memcpy(matches.data(), blob.data, matches.size() * sizeof(FeatureMatch));
  if (swap) {
    for (auto& m : matches) std::swap(m.point2D_idx1, m.point2D_idx2);
  }
  return matches;
}

// The geometry of the pair seen from the other side (COLMAP's TwoViewGeometry::Invert):
// x2' F x1 = 0 becomes x1' F' x2 = 0, likewise E; H maps image 2 to image 1; the pose is
// cam1_from_cam2.
TwoViewGeometry Inverted(const TwoViewGeometry& geometry) {
  TwoViewGeometry inverted = geometry;
  inverted.F = geometry.F.transpose();
  inverted.E = geometry.E.transpose();
  // COLMAP inverts H unconditionally, which turns an unset (zero) H into NaNs; keep it zero.
  bool invertible = false;
  geometry.H.computeInverseWithCheck(inverted.H, invertible,
                                     1e-12 * std::pow(geometry.H.norm(), 3));
  if (!invertible) inverted.H.setZero();
  inverted.cam2_from_cam1 = geometry.cam2_from_cam1.Inverse();
  for (auto& m : inverted.inlier_matches) std::swap(m.point2D_idx1, m.point2D_idx2);
  return inverted;
}

// Reads columns rows, cols, data, config, F, E, H, qvec, tvec starting at `col`.
TwoViewGeometry ReadGeometryRow(sqlite3_stmt* stmt, int col, const std::string& what) {
  TwoViewGeometry geometry;
  geometry.inlier_matches =
      MatchesFromBlob(ReadMatrixBlob(stmt, col, sizeof(uint32_t), what), false, what);
  geometry.config = static_cast<int>(sqlite3_column_int64(stmt, col + 3));
  RowMajor3d m;
  ReadDoubles(stmt, col + 4, m.data(), 9);
  geometry.F = m;
  ReadDoubles(stmt, col + 5, m.data(), 9);
  geometry.E = m;
  ReadDoubles(stmt, col + 6, m.data(), 9);
  geometry.H = m;
  double wxyz[4];
  if (ReadDoubles(stmt, col + 7, wxyz, 4) && (wxyz[0] != 0 || wxyz[1] != 0 || wxyz[2] != 0 ||
                                              wxyz[3] != 0)) {
    geometry.cam2_from_cam1.rotation = Eigen::Quaterniond(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
  }
  ReadDoubles(stmt, col + 8, geometry.cam2_from_cam1.translation.data(), 3);
  return geometry;
}

std::string PairName(image_t a, image_t b) { return fmt::format("pair ({}, {})", a, b); }

}  // namespace

// ---- cameras ----------------------------------------------------------------------------

namespace {
Camera ReadCameraRow(sqlite3_stmt* stmt, const std::string& path) {
  Camera camera;
  camera.camera_id = static_cast<camera_t>(sqlite3_column_int64(stmt, 0));
  const int model = sqlite3_column_int(stmt, 1);
  if (!IsKnownCameraModel(model)) {
    throw StorageError(fmt::format(
        "database {}: camera {} uses COLMAP camera model id {}, which loopsfm does not "
        "support (supported: {})",
        path, camera.camera_id, model, CameraModelNameList()));
  }
  camera.model_id = static_cast<CameraModelId>(model);
  camera.width = sqlite3_column_int(stmt, 2);
  camera.height = sqlite3_column_int(stmt, 3);
  const size_t num_bytes = static_cast<size_t>(sqlite3_column_bytes(stmt, 4));
  const size_t num_params = static_cast<size_t>(CameraModelNumParams(camera.model_id));
  // Checked before copying: a byte count that is not a whole number of doubles would
  // overrun the parameter vector.
  if (num_bytes != num_params * sizeof(double)) {
    throw StorageError(fmt::format(
        "database {}: camera {} ({}) has {} bytes of parameters, expected {} ({} doubles)", path,
        camera.camera_id, camera.ModelName(), num_bytes, num_params * sizeof(double),
        num_params));
  }
  camera.params.resize(num_params);
  std::memcpy(camera.params.data(), sqlite3_column_blob(stmt, 4), num_bytes);
  camera.has_prior_focal_length = sqlite3_column_int64(stmt, 5) != 0;
  try {
    camera.Check();
  } catch (const InputError& e) {
    throw StorageError(fmt::format("database {}: camera {}: {}; the database is damaged: start "
                                   "the output folder again (--overwrite)",
                                   path, camera.camera_id, e.what()));
  }
  return camera;
}
}  // namespace

camera_t Database::WriteCamera(const Camera& camera) {
  camera.Check();
  sqlite3_stmt* stmt = Prepare(
      "INSERT INTO cameras(camera_id, model, width, height, params, prior_focal_length) "
      "VALUES(?, ?, ?, ?, ?, ?) ON CONFLICT(camera_id) DO UPDATE SET model = excluded.model, "
      "width = excluded.width, height = excluded.height, params = excluded.params, "
      "prior_focal_length = excluded.prior_focal_length");
  StatementScope scope(stmt);
  if (camera.camera_id != kInvalidCameraId) BindId(stmt, 1, camera.camera_id);
  BindId(stmt, 2, static_cast<int>(camera.model_id));
  BindId(stmt, 3, camera.width);
  BindId(stmt, 4, camera.height);
  BindBlob(stmt, 5, camera.params.data(), camera.params.size() * sizeof(double));
  BindId(stmt, 6, camera.has_prior_focal_length ? 1 : 0);
  Step(stmt);
  return camera.camera_id != kInvalidCameraId
             ? camera.camera_id
             : static_cast<camera_t>(sqlite3_last_insert_rowid(db_));
}

std::optional<Camera> Database::ReadCamera(camera_t camera_id) const {
  sqlite3_stmt* stmt = Prepare("SELECT * FROM cameras WHERE camera_id = ?");
  StatementScope scope(stmt);
  BindId(stmt, 1, camera_id);
  if (!Step(stmt)) return std::nullopt;
  return ReadCameraRow(stmt, path_);
}

std::vector<Camera> Database::ReadCameras() const {
  sqlite3_stmt* stmt = Prepare("SELECT * FROM cameras ORDER BY camera_id");
  StatementScope scope(stmt);
  std::vector<Camera> cameras;
  while (Step(stmt)) cameras.push_back(ReadCameraRow(stmt, path_));
  return cameras;
}

size_t Database::NumCameras() const { return CountRows("SELECT COUNT(*) FROM cameras"); }

// ---- frames -----------------------------------------------------------------------------

namespace {
Frame ReadFrameRow(sqlite3_stmt* stmt) {
  Frame frame;
  frame.image_id = static_cast<image_t>(sqlite3_column_int64(stmt, 0));
  frame.name = ColumnText(stmt, 1);
  frame.camera_id = static_cast<camera_t>(sqlite3_column_int64(stmt, 2));
  return frame;
}
}  // namespace

image_t Database::WriteFrame(const Frame& frame) {
  Transaction transaction(*this);
  if (const auto existing = FindFrame(frame.name)) {
    if (frame.image_id != kInvalidImageId && frame.image_id != existing->image_id) {
      throw StorageError(fmt::format(
          "database {}: frame '{}' is stored with image id {}, not {}; the database belongs "
          "to another run. Start from a new database.",
          path_, frame.name, existing->image_id, frame.image_id));
    }
    if (existing->camera_id != frame.camera_id) {
      sqlite3_stmt* stmt = Prepare("UPDATE images SET camera_id = ? WHERE image_id = ?");
      StatementScope scope(stmt);
      BindId(stmt, 1, frame.camera_id);
      BindId(stmt, 2, existing->image_id);
      Step(stmt);
    }
    transaction.Commit();
    return existing->image_id;
  }
  if (!ExistsRow("SELECT 1 FROM cameras WHERE camera_id = ?", frame.camera_id)) {
    throw StorageError(fmt::format(
        "database {}: frame '{}' refers to camera {}, which is not stored; write the camera "
        "first",
        path_, frame.name, frame.camera_id));
  }
  if (frame.image_id != kInvalidImageId) {
    if (const auto other = ReadFrame(frame.image_id)) {
      throw StorageError(fmt::format(
          "database {}: image id {} already belongs to frame '{}', cannot store '{}' under it",
          path_, frame.image_id, other->name, frame.name));
    }
  }
  sqlite3_stmt* stmt = Prepare("INSERT INTO images(image_id, name, camera_id) VALUES(?, ?, ?)");
  StatementScope scope(stmt);
  if (frame.image_id != kInvalidImageId) BindId(stmt, 1, frame.image_id);
  Check(stmt, sqlite3_bind_text(stmt, 2, frame.name.data(), static_cast<int>(frame.name.size()),
                                SQLITE_STATIC),
        "binding a name");
  BindId(stmt, 3, frame.camera_id);
  Step(stmt);
  const auto image_id = static_cast<image_t>(sqlite3_last_insert_rowid(db_));
  transaction.Commit();
  return image_id;
}

std::optional<Frame> Database::ReadFrame(image_t image_id) const {
  sqlite3_stmt* stmt = Prepare("SELECT image_id, name, camera_id FROM images WHERE image_id = ?");
  StatementScope scope(stmt);
  BindId(stmt, 1, image_id);
  if (!Step(stmt)) return std::nullopt;
  return ReadFrameRow(stmt);
}

std::optional<Frame> Database::FindFrame(const std::string& name) const {
  sqlite3_stmt* stmt = Prepare("SELECT image_id, name, camera_id FROM images WHERE name = ?");
  StatementScope scope(stmt);
  Check(stmt, sqlite3_bind_text(stmt, 1, name.data(), static_cast<int>(name.size()),
                                SQLITE_STATIC),
        "binding a name");
  if (!Step(stmt)) return std::nullopt;
  return ReadFrameRow(stmt);
}

std::vector<Frame> Database::ReadFrames() const {
  sqlite3_stmt* stmt = Prepare("SELECT image_id, name, camera_id FROM images ORDER BY image_id");
  StatementScope scope(stmt);
  std::vector<Frame> frames;
  while (Step(stmt)) frames.push_back(ReadFrameRow(stmt));
  return frames;
}

size_t Database::NumFrames() const { return CountRows("SELECT COUNT(*) FROM images"); }

void Database::WriteFrameOrigin(image_t image_id, const FrameOrigin& source) {
  sqlite3_stmt* stmt = Prepare(
      "INSERT OR REPLACE INTO loopsfm_frames(image_id, source_index, sharpness, reason) "
      "VALUES(?, ?, ?, ?)");
  StatementScope scope(stmt);
  BindId(stmt, 1, image_id);
  BindId(stmt, 2, source.source_index);
  Check(stmt, sqlite3_bind_double(stmt, 3, source.sharpness), "binding a double");
  Check(stmt, sqlite3_bind_text(stmt, 4, source.reason.data(),
                                static_cast<int>(source.reason.size()), SQLITE_STATIC),
        "binding text");
  Step(stmt);
}

std::optional<FrameOrigin> Database::ReadFrameOrigin(image_t image_id) const {
  sqlite3_stmt* stmt =
      Prepare("SELECT source_index, sharpness, reason FROM loopsfm_frames WHERE image_id = ?");
  StatementScope scope(stmt);
  BindId(stmt, 1, image_id);
  if (!Step(stmt)) return std::nullopt;
  return FrameOrigin{sqlite3_column_int64(stmt, 0), sqlite3_column_double(stmt, 1),
                     ColumnText(stmt, 2)};
}

std::unordered_map<image_t, FrameOrigin> Database::ReadFrameOrigins() const {
  sqlite3_stmt* stmt =
      Prepare("SELECT image_id, source_index, sharpness, reason FROM loopsfm_frames");
  StatementScope scope(stmt);
  std::unordered_map<image_t, FrameOrigin> origins;
  while (Step(stmt)) {
    origins[static_cast<image_t>(sqlite3_column_int64(stmt, 0))] = FrameOrigin{
        sqlite3_column_int64(stmt, 1), sqlite3_column_double(stmt, 2), ColumnText(stmt, 3)};
  }
  return origins;
}

// ---- features ---------------------------------------------------------------------------

void Database::WriteFeatures(image_t image_id, const FeatureSet& features) {
  LOOPSFM_CHECK_MSG(features.descriptors.rows() == 0 ||
                        static_cast<size_t>(features.descriptors.rows()) == features.Size(),
                    "{} keypoints but {} descriptors", features.Size(),
                    features.descriptors.rows());
  Transaction transaction(*this);
  {
    sqlite3_stmt* stmt = Prepare(
        "INSERT OR REPLACE INTO keypoints(image_id, rows, cols, data) VALUES(?, ?, ?, ?)");
    StatementScope scope(stmt);
    BindId(stmt, 1, image_id);
    BindMatrixBlob(stmt, 2, features.Size(), 6, features.keypoints.data(),
                   features.Size() * sizeof(FeatureKeypoint));
    Step(stmt);
  }
  {
    sqlite3_stmt* stmt = Prepare(
        "INSERT OR REPLACE INTO descriptors(image_id, rows, cols, data) VALUES(?, ?, ?, ?)");
    StatementScope scope(stmt);
    BindId(stmt, 1, image_id);
    BindMatrixBlob(stmt, 2, features.descriptors.rows(), kDescriptorDim,
                   features.descriptors.data(), features.descriptors.size());
    Step(stmt);
  }
  transaction.Commit();
}

FeatureKeypoints Database::ReadKeypoints(image_t image_id) const {
  sqlite3_stmt* stmt = Prepare("SELECT rows, cols, data FROM keypoints WHERE image_id = ?");
  StatementScope scope(stmt);
  BindId(stmt, 1, image_id);
  if (!Step(stmt)) return {};
  const std::string what = fmt::format("keypoints of image {}", image_id);
  const BlobView blob = ReadMatrixBlob(stmt, 0, sizeof(float), what);
  if (blob.rows == 0) return {};
  const auto* v = static_cast<const float*>(blob.data);
  const int64_t c = blob.cols;
  // COLMAP writes 6 columns; older COLMAP and other tools write (x, y, scale, orientation)
  // or just (x, y). Checked before allocating: with 0 columns, any row count fits 0 bytes.
  if (c != 6 && c != 4 && c != 2) {
    throw StorageError(fmt::format("database {}: {} have {} columns; expected 2, 4 or 6",
                                   path_, what, c));
  }
  FeatureKeypoints keypoints(blob.rows);
  for (int64_t i = 0; i < blob.rows; ++i) {
    const float* row = v + i * c;
    if (c == 6) {
      keypoints[i] = {row[0], row[1], row[2], row[3], row[4], row[5]};
    } else if (c == 4) {
      keypoints[i] = FeatureKeypoint::FromScaleOrientation(row[0], row[1], row[2], row[3]);
    } else {
      keypoints[i].x = row[0];
      keypoints[i].y = row[1];
    }
  }
  return keypoints;
}

FeatureDescriptors Database::ReadDescriptors(image_t image_id) const {
  sqlite3_stmt* stmt = Prepare("SELECT rows, cols, data FROM descriptors WHERE image_id = ?");
  StatementScope scope(stmt);
  BindId(stmt, 1, image_id);
  FeatureDescriptors descriptors(0, kDescriptorDim);
  if (!Step(stmt)) return descriptors;
  const std::string what = fmt::format("descriptors of image {}", image_id);
  const BlobView blob = ReadMatrixBlob(stmt, 0, sizeof(uint8_t), what);
  if (blob.rows > 0 && blob.cols != kDescriptorDim) {
    throw StorageError(fmt::format(
        "database {}: {} have {} dimensions; loopsfm reads {}-dimensional SIFT descriptors",
        path_, what, blob.cols, kDescriptorDim));
  }
  descriptors.resize(blob.rows, kDescriptorDim);
  if (blob.rows > 0) std::memcpy(descriptors.data(), blob.data, descriptors.size());
  return descriptors;
}

FeatureSet Database::ReadFeatures(image_t image_id) const {
  return {ReadKeypoints(image_id), ReadDescriptors(image_id)};
}

bool Database::HasFeatures(image_t image_id) const {
  return ExistsRow("SELECT 1 FROM keypoints WHERE image_id = ?", image_id) &&
         ExistsRow("SELECT 1 FROM descriptors WHERE image_id = ?", image_id);
}

// ---- matches ----------------------------------------------------------------------------

void Database::WriteMatches(image_t image_id1, image_t image_id2, const FeatureMatches& matches) {
  LOOPSFM_CHECK_MSG(image_id1 != image_id2, "matches of image {} with itself", image_id1);
  FeatureMatches swapped;
  const FeatureMatches* stored = &matches;
  if (SwapImagePair(image_id1, image_id2)) {
    swapped = matches;
    for (auto& m : swapped) std::swap(m.point2D_idx1, m.point2D_idx2);
    stored = &swapped;
  }
  sqlite3_stmt* stmt =
      Prepare("INSERT OR REPLACE INTO matches(pair_id, rows, cols, data) VALUES(?, ?, ?, ?)");
  StatementScope scope(stmt);
  BindId(stmt, 1, static_cast<int64_t>(PairToPairId(image_id1, image_id2)));
  BindMatrixBlob(stmt, 2, stored->size(), 2, stored->data(), stored->size() * sizeof(FeatureMatch));
  Step(stmt);
}

FeatureMatches Database::ReadMatches(image_t image_id1, image_t image_id2) const {
  sqlite3_stmt* stmt = Prepare("SELECT rows, cols, data FROM matches WHERE pair_id = ?");
  StatementScope scope(stmt);
  BindId(stmt, 1, static_cast<int64_t>(PairToPairId(image_id1, image_id2)));
  if (!Step(stmt)) return {};
  const std::string what = "matches of " + PairName(image_id1, image_id2);
  return MatchesFromBlob(ReadMatrixBlob(stmt, 0, sizeof(uint32_t), what),
                         SwapImagePair(image_id1, image_id2), what);
}

bool Database::ExistsMatches(image_t image_id1, image_t image_id2) const {
  return ExistsRow("SELECT 1 FROM matches WHERE pair_id = ?",
                   static_cast<int64_t>(PairToPairId(image_id1, image_id2)));
}

std::vector<ImagePair> Database::ReadAllMatchedPairs() const {
  sqlite3_stmt* stmt = Prepare("SELECT pair_id FROM matches ORDER BY pair_id");
  StatementScope scope(stmt);
  std::vector<ImagePair> pairs;
  while (Step(stmt)) pairs.push_back(PairIdToPair(sqlite3_column_int64(stmt, 0)));
  return pairs;
}

std::vector<std::pair<ImagePair, FeatureMatches>> Database::ReadAllMatches() const {
  sqlite3_stmt* stmt = Prepare("SELECT pair_id, rows, cols, data FROM matches ORDER BY pair_id");
  StatementScope scope(stmt);
  std::vector<std::pair<ImagePair, FeatureMatches>> all;
  while (Step(stmt)) {
    const ImagePair pair = PairIdToPair(sqlite3_column_int64(stmt, 0));
    const std::string what = "matches of " + PairName(pair.image_id1, pair.image_id2);
    all.emplace_back(pair,
                     MatchesFromBlob(ReadMatrixBlob(stmt, 1, sizeof(uint32_t), what), false, what));
  }
  return all;
}

size_t Database::NumMatchedPairs() const { return CountRows("SELECT COUNT(*) FROM matches"); }

void Database::ClearMatches() { Exec("DELETE FROM matches"); }

// ---- two-view geometries ----------------------------------------------------------------

void Database::WriteTwoViewGeometry(image_t image_id1, image_t image_id2,
                                    const TwoViewGeometry& tvg) {
  LOOPSFM_CHECK_MSG(image_id1 != image_id2, "geometry of image {} with itself", image_id1);
  const TwoViewGeometry stored = SwapImagePair(image_id1, image_id2) ? Inverted(tvg) : tvg;
  // Row-major, as COLMAP stores them (it transposes its column-major matrices).
  const RowMajor3d F = stored.F, E = stored.E, H = stored.H;
  const Eigen::Quaterniond& q = stored.cam2_from_cam1.rotation;
  const double qvec[4] = {q.w(), q.x(), q.y(), q.z()};
  const Eigen::Vector3d& tvec = stored.cam2_from_cam1.translation;
  sqlite3_stmt* stmt = Prepare(
      "INSERT OR REPLACE INTO two_view_geometries(pair_id, rows, cols, data, config, F, E, H, "
      "qvec, tvec) VALUES(?, ?, ?, ?, ?, ?, ?, ?, ?, ?)");
  StatementScope scope(stmt);
  BindId(stmt, 1, static_cast<int64_t>(PairToPairId(image_id1, image_id2)));
  const FeatureMatches& inliers = stored.inlier_matches;
  BindMatrixBlob(stmt, 2, inliers.size(), 2, inliers.data(), inliers.size() * sizeof(FeatureMatch));
  BindId(stmt, 5, stored.config);
  BindBlob(stmt, 6, F.data(), sizeof(double) * 9);
  BindBlob(stmt, 7, E.data(), sizeof(double) * 9);
  BindBlob(stmt, 8, H.data(), sizeof(double) * 9);
  BindBlob(stmt, 9, qvec, sizeof(qvec));
  BindBlob(stmt, 10, tvec.data(), sizeof(double) * 3);
  Step(stmt);
}

std::optional<TwoViewGeometry> Database::ReadTwoViewGeometry(image_t image_id1,
                                                             image_t image_id2) const {
  sqlite3_stmt* stmt = Prepare(
      "SELECT rows, cols, data, config, F, E, H, qvec, tvec FROM two_view_geometries "
      "WHERE pair_id = ?");
  StatementScope scope(stmt);
  BindId(stmt, 1, static_cast<int64_t>(PairToPairId(image_id1, image_id2)));
  if (!Step(stmt)) return std::nullopt;
  TwoViewGeometry geometry =
      ReadGeometryRow(stmt, 0, "two-view geometry of " + PairName(image_id1, image_id2));
  return SwapImagePair(image_id1, image_id2) ? Inverted(geometry) : geometry;
}

bool Database::ExistsTwoViewGeometry(image_t image_id1, image_t image_id2) const {
  return ExistsRow("SELECT 1 FROM two_view_geometries WHERE pair_id = ?",
                   static_cast<int64_t>(PairToPairId(image_id1, image_id2)));
}

std::vector<std::pair<ImagePair, TwoViewGeometry>> Database::ReadAllTwoViewGeometries() const {
  sqlite3_stmt* stmt = Prepare(
      "SELECT pair_id, rows, cols, data, config, F, E, H, qvec, tvec FROM two_view_geometries "
      "ORDER BY pair_id");
  StatementScope scope(stmt);
  std::vector<std::pair<ImagePair, TwoViewGeometry>> all;
  while (Step(stmt)) {
    const ImagePair pair = PairIdToPair(sqlite3_column_int64(stmt, 0));
    all.emplace_back(pair, ReadGeometryRow(stmt, 1, "two-view geometry of " +
                                                        PairName(pair.image_id1, pair.image_id2)));
  }
  return all;
}

// Matches TwoViewGeometry::IsVerified(): inliers and a config other than undefined (0) or
// degenerate (1).
std::vector<VerifiedPair> Database::ReadVerifiedPairs() const {
  sqlite3_stmt* stmt = Prepare(
      "SELECT pair_id, rows, config FROM two_view_geometries "
      "WHERE rows > 0 AND config NOT IN (0, 1) ORDER BY pair_id");
  StatementScope scope(stmt);
  std::vector<VerifiedPair> pairs;
  while (Step(stmt)) {
    pairs.push_back({PairIdToPair(sqlite3_column_int64(stmt, 0)), sqlite3_column_int(stmt, 1),
                     sqlite3_column_int(stmt, 2)});
  }
  return pairs;
}

size_t Database::NumVerifiedPairs() const {
  return CountRows(
      "SELECT COUNT(*) FROM two_view_geometries WHERE rows > 0 AND config NOT IN (0, 1)");
}

void Database::ClearTwoViewGeometries() { Exec("DELETE FROM two_view_geometries"); }

// ---- metadata ---------------------------------------------------------------------------

void Database::WriteMeta(const std::string& key, const std::string& value) {
  sqlite3_stmt* stmt = Prepare("INSERT OR REPLACE INTO loopsfm_meta(key, value) VALUES(?, ?)");
  StatementScope scope(stmt);
  Check(stmt, sqlite3_bind_text(stmt, 1, key.data(), static_cast<int>(key.size()), SQLITE_STATIC),
        "binding a key");
  Check(stmt,
        sqlite3_bind_text(stmt, 2, value.data(), static_cast<int>(value.size()), SQLITE_STATIC),
        "binding a value");
  Step(stmt);
}

std::optional<std::string> Database::ReadMeta(const std::string& key) const {
  sqlite3_stmt* stmt = Prepare("SELECT value FROM loopsfm_meta WHERE key = ?");
  StatementScope scope(stmt);
  Check(stmt, sqlite3_bind_text(stmt, 1, key.data(), static_cast<int>(key.size()), SQLITE_STATIC),
        "binding a key");
  if (!Step(stmt)) return std::nullopt;
  return ColumnText(stmt, 0);
}

}  // namespace loopsfm

#pragma once
// The project's database: a SQLite file with COLMAP 3.8's schema, so that `colmap mapper`,
// `colmap gui` and pycolmap read what loopsfm writes, and loopsfm reads what COLMAP wrote.
//
// COLMAP's tables and blob layouts (all blobs in native little-endian byte order):
//   cameras(camera_id, model, width, height, params, prior_focal_length)
//       params: the model's parameters as doubles.
//   images(image_id, name UNIQUE, camera_id, prior_qw .. prior_tz)
//       priors are written as NULL (COLMAP writes NaN, which SQLite stores as NULL).
//   keypoints(image_id, rows, cols, data)      float32, rows x 6 row-major:
//       x, y, a11, a12, a21, a22. COLMAP also accepts 2 (x, y) and 4 (x, y, scale,
//       orientation) columns; we read all three and always write 6.
//   descriptors(image_id, rows, cols, data)    uint8, rows x 128 row-major.
//   matches(pair_id, rows, cols, data)         uint32, rows x 2 row-major (raw matches).
//   two_view_geometries(pair_id, rows, cols, data, config, F, E, H, qvec, tvec)
//       data: inlier matches as above; F, E, H: 3x3 doubles ROW-major (COLMAP transposes
//       its column-major Eigen matrices before writing); qvec: cam2_from_cam1 rotation as
//       (w, x, y, z); tvec: its translation.
// pair_id = id1 * 2147483647 + id2 with id1 < id2 (PairToPairId in util/types.h). A pair
// given as (id1 > id2) is stored swapped: match columns exchanged, F and E transposed,
// H inverted, the relative pose inverted; reading it back in the caller's order undoes it.
//
// loopsfm's own tables (ignored by COLMAP):
//   loopsfm_meta(key, value)                         text key/value, incl. schema_version
//   loopsfm_frames(image_id, source_index, sharpness, reason) where a frame came from in the
//       video and why it was kept (video/keyframes.h: window, first, parallax, overlap,
//       tracking-lost, last, fill-in; empty in databases older than the column)
//
// Threading: a Database is used from one thread at a time (the pipeline serialises all
// reads and writes through one owner). It is movable, not copyable.
//
// Safety: Open() refuses files that are not SQLite and SQLite files that hold someone
// else's tables, without writing to them. Writes are idempotent per frame and per pair
// (re-running a stage replaces its rows), and each call is atomic, so a crash leaves a
// consistent database; batch writes inside a Transaction for speed.

#include <cstdint>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "loopsfm/scene/camera.h"
#include "loopsfm/scene/features.h"
#include "loopsfm/scene/frame.h"
#include "loopsfm/scene/two_view_geometry.h"
#include "loopsfm/util/types.h"

struct sqlite3;
struct sqlite3_stmt;

namespace loopsfm {

// Where a frame came from, kept beside COLMAP's images table.
struct FrameOrigin {
  // Index of the frame in the source video (or position in the image folder).
  int64_t source_index = -1;
  // Sharpness score used by keyframe selection (FrameSharpness in video/keyframes.h).
  double sharpness = 0.0;
  // Why the frame was kept (KeyframeReasonName in video/keyframes.h); empty when unknown.
  std::string reason;
};

// A verified pair's summary, read without decoding any blob.
struct VerifiedPair {
  ImagePair pair;
  int num_inliers = 0;
  int config = TwoViewGeometry::kUndefined;
};

class Database {
 public:
  // loopsfm's own schema version, stored in loopsfm_meta under "schema_version".
  static constexpr int kSchemaVersion = 1;

  // Opens the database at `path`, creating it (and its tables) when the file does not
  // exist. Throws StorageError when the path is a folder, its folder does not exist, the
  // file is not SQLite, the SQLite file holds tables that are not COLMAP's, it is
  // read-only or corrupt, or it was written by a newer loopsfm. A failed open leaves the
  // file untouched.
  static Database Open(const std::string& path);

  Database(Database&& other) noexcept;
  Database& operator=(Database&& other) noexcept;
  Database(const Database&) = delete;
  Database& operator=(const Database&) = delete;
  ~Database();

  const std::string& Path() const { return path_; }

  // Cameras. A camera with camera_id == kInvalidCameraId gets a new id; otherwise the row
  // with that id is inserted or updated. Returns the id.
  camera_t WriteCamera(const Camera& camera);
  std::optional<Camera> ReadCamera(camera_t camera_id) const;
  std::vector<Camera> ReadCameras() const;
  size_t NumCameras() const;

  // Frames (COLMAP's images). Idempotent by name: writing a name that exists returns its
  // id (updating its camera), so a resumed run gets the same ids. A given image_id must
  // agree with the stored one, else StorageError.
  image_t WriteFrame(const Frame& frame);
  std::optional<Frame> ReadFrame(image_t image_id) const;
  std::optional<Frame> FindFrame(const std::string& name) const;
  bool ExistsFrame(const std::string& name) const { return FindFrame(name).has_value(); }
  // All frames ordered by image_id.
  std::vector<Frame> ReadFrames() const;
  size_t NumFrames() const;

  void WriteFrameOrigin(image_t image_id, const FrameOrigin& source);
  std::optional<FrameOrigin> ReadFrameOrigin(image_t image_id) const;
  // Every frame's origin, by image id (frames without one are absent).
  std::unordered_map<image_t, FrameOrigin> ReadFrameOrigins() const;

  // Features. Replaces the frame's keypoints and descriptors in one step; the descriptor
  // rows must match the keypoints (or be empty, to store keypoints only).
  void WriteFeatures(image_t image_id, const FeatureSet& features);
  // Empty when the frame has none.
  FeatureKeypoints ReadKeypoints(image_t image_id) const;
  FeatureDescriptors ReadDescriptors(image_t image_id) const;
  FeatureSet ReadFeatures(image_t image_id) const;
  // True when both keypoints and descriptors are stored.
  bool HasFeatures(image_t image_id) const;

  // Raw matches (before verification). An empty list records that the pair was tried.
  // point2D_idx1 indexes image_id1's keypoints, in the caller's order.
  void WriteMatches(image_t image_id1, image_t image_id2, const FeatureMatches& matches);
  // Empty when the pair has no row.
  FeatureMatches ReadMatches(image_t image_id1, image_t image_id2) const;
  bool ExistsMatches(image_t image_id1, image_t image_id2) const;
  // Every pair with a matches row (tried pairs included), ordered by pair id.
  std::vector<ImagePair> ReadAllMatchedPairs() const;
  // Every pair's raw matches, in the stored order (image_id1 < image_id2).
  std::vector<std::pair<ImagePair, FeatureMatches>> ReadAllMatches() const;
  size_t NumMatchedPairs() const;
  void ClearMatches();

  // Verified geometry in the caller's order (see the swap rule above).
  void WriteTwoViewGeometry(image_t image_id1, image_t image_id2, const TwoViewGeometry& tvg);
  // nullopt when the pair has no row.
  std::optional<TwoViewGeometry> ReadTwoViewGeometry(image_t image_id1, image_t image_id2) const;
  bool ExistsTwoViewGeometry(image_t image_id1, image_t image_id2) const;
  // Every stored geometry, in the stored order (image_id1 < image_id2).
  std::vector<std::pair<ImagePair, TwoViewGeometry>> ReadAllTwoViewGeometries() const;
  // Pairs with at least one inlier and a usable config (not undefined / degenerate), with
  // their inlier counts; reads no blobs, so it is fast on large databases.
  std::vector<VerifiedPair> ReadVerifiedPairs() const;
  // Number of pairs ReadVerifiedPairs() returns.
  size_t NumVerifiedPairs() const;
  void ClearTwoViewGeometries();

  // loopsfm key/value metadata (stage markers, options fingerprints, ...).
  void WriteMeta(const std::string& key, const std::string& value);
  std::optional<std::string> ReadMeta(const std::string& key) const;

  // Groups writes into one SQLite transaction: much faster for many rows, and all or
  // nothing. Commits when it goes out of scope normally (or on Commit()), rolls back when
  // left by an exception. Transactions nest (implemented with SAVEPOINTs).
  class Transaction {
   public:
    explicit Transaction(Database& database);
    ~Transaction();
    void Commit();
    Transaction(const Transaction&) = delete;
    Transaction& operator=(const Transaction&) = delete;

   private:
    Database* database_;
    int uncaught_exceptions_;
    bool open_ = true;
  };

 private:
  Database() = default;
  void Close() noexcept;
  void Exec(const char* sql) const;
  // Returns a cached prepared statement for `sql` (reset and unbound by the caller's
  // StatementScope).
  sqlite3_stmt* Prepare(const char* sql) const;
  size_t CountRows(const char* sql) const;
  bool ExistsRow(const char* sql, int64_t id) const;
  void CreateTables();

  std::string path_;
  sqlite3* db_ = nullptr;
  mutable std::unordered_map<std::string, sqlite3_stmt*> statements_;
};

}  // namespace loopsfm

// The database's blob decoding: the fuzz bytes become one row of a COLMAP table (see
// database_fuzz_input.h), written through a second SQLite connection to a scratch
// database, then read back through every Database method that decodes that table.

#include <sqlite3.h>

#include <cstdio>
#include <cstdlib>

#include "database_fuzz_input.h"
#include "fuzz_util.h"
#include "loopsfm/storage/database.h"

namespace {

using loopsfm::Database;
using loopsfm::fuzz::DatabaseFuzzRow;
using loopsfm::fuzz::ExpectTypedErrors;

constexpr const char* kInsert[DatabaseFuzzRow::kNumTables] = {
    "INSERT OR REPLACE INTO cameras(camera_id, model, width, height, prior_focal_length, "
    "params) VALUES(1, ?1, ?2, ?3, ?4, ?10)",
    "INSERT OR REPLACE INTO keypoints(image_id, rows, cols, data) VALUES(1, ?1, ?2, ?10)",
    "INSERT OR REPLACE INTO descriptors(image_id, rows, cols, data) VALUES(1, ?1, ?2, ?10)",
    "INSERT OR REPLACE INTO matches(pair_id, rows, cols, data) VALUES(?11, ?1, ?2, ?10)",
    "INSERT OR REPLACE INTO two_view_geometries(pair_id, rows, cols, config, F, E, H, qvec, "
    "tvec, data) VALUES(?11, ?1, ?2, ?3, ?5, ?6, ?7, ?8, ?9, ?10)",
};

[[noreturn]] void Fail(sqlite3* db, const char* what) {
  std::fprintf(stderr, "database_blob_fuzz: %s: %s\n", what, sqlite3_errmsg(db));
  std::abort();
}

// The Database under test and a raw connection to the same file that writes the rows.
struct Fixture {
  Fixture() : database(Database::Open((loopsfm::fuzz::ScratchDir() / "fuzz.db").string())) {
    if (sqlite3_open_v2(database.Path().c_str(), &raw, SQLITE_OPEN_READWRITE, nullptr) !=
        SQLITE_OK) {
      Fail(raw, "opening the scratch database");
    }
    sqlite3_busy_timeout(raw, 5000);
    sqlite3_exec(raw, "PRAGMA synchronous = OFF", nullptr, nullptr, nullptr);
  }
  ~Fixture() { sqlite3_close_v2(raw); }

  void Write(const DatabaseFuzzRow& row) {
    sqlite3_stmt* stmt = nullptr;
    if (sqlite3_prepare_v2(raw, kInsert[row.table], -1, &stmt, nullptr) != SQLITE_OK) {
      Fail(raw, "preparing an insert");
    }
    for (int i = 0; i < 4; ++i) sqlite3_bind_int64(stmt, i + 1, row.ints[i]);
    for (int i = 0; i < 5; ++i) {
      sqlite3_bind_blob64(stmt, i + 5, row.blobs[i].data(), row.blobs[i].size(), SQLITE_STATIC);
    }
    sqlite3_bind_blob64(stmt, 10, row.data.data(), row.data.size(), SQLITE_STATIC);
    sqlite3_bind_int64(stmt, 11, static_cast<int64_t>(loopsfm::PairToPairId(1, 2)));
    const int rc = sqlite3_step(stmt);
    sqlite3_finalize(stmt);
    if (rc != SQLITE_DONE) Fail(raw, "writing the fuzz row");
  }

  Database database;
  sqlite3* raw = nullptr;
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static Fixture fixture;
  const DatabaseFuzzRow row =
      DatabaseFuzzRow::Decode({reinterpret_cast<const char*>(data), size});
  fixture.Write(row);
  const Database& db = fixture.database;
  switch (row.table) {
    case DatabaseFuzzRow::kCameras:
      ExpectTypedErrors([&] { db.ReadCamera(1); });
      ExpectTypedErrors([&] { db.ReadCameras(); });
      break;
    case DatabaseFuzzRow::kKeypoints:
      ExpectTypedErrors([&] { db.ReadKeypoints(1); });
      break;
    case DatabaseFuzzRow::kDescriptors:
      ExpectTypedErrors([&] { db.ReadDescriptors(1); });
      break;
    case DatabaseFuzzRow::kMatches:
      ExpectTypedErrors([&] { db.ReadMatches(1, 2); });
      ExpectTypedErrors([&] { db.ReadMatches(2, 1); });
      ExpectTypedErrors([&] { db.ReadAllMatches(); });
      break;
    case DatabaseFuzzRow::kTwoViewGeometries:
      ExpectTypedErrors([&] { db.ReadTwoViewGeometry(1, 2); });
      ExpectTypedErrors([&] { db.ReadTwoViewGeometry(2, 1); });
      ExpectTypedErrors([&] { db.ReadAllTwoViewGeometries(); });
      ExpectTypedErrors([&] { db.ReadVerifiedPairs(); });
      break;
  }
  return 0;
}

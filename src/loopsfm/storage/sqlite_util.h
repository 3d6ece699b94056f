#pragma once
// Small helpers over SQLite's C API shared by the database's source files (not part of
// the public API): cached statements that reset themselves, checked binds and steps, and
// blob readers that validate byte counts before copying.

#include <sqlite3.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>

#include <fmt/format.h>

#include "loopsfm/util/errors.h"

namespace loopsfm::sqlite {

// Resets a cached statement when the call that uses it ends, however it ends.
class StatementScope {
 public:
  explicit StatementScope(sqlite3_stmt* stmt) : stmt_(stmt) {}
  ~StatementScope() {
    sqlite3_reset(stmt_);
    sqlite3_clear_bindings(stmt_);
  }
  StatementScope(const StatementScope&) = delete;
  StatementScope& operator=(const StatementScope&) = delete;

 private:
  sqlite3_stmt* stmt_;
};

[[noreturn]] inline void ThrowSqlite(sqlite3* db, const std::string& what) {
  const char* path = db != nullptr ? sqlite3_db_filename(db, "main") : nullptr;
  throw StorageError(fmt::format("database {}: {} failed: {}", path ? path : "?", what,
                                 db != nullptr ? sqlite3_errmsg(db) : "cannot open"));
}

inline void Check(sqlite3_stmt* stmt, int rc, const char* what) {
  if (rc != SQLITE_OK) ThrowSqlite(sqlite3_db_handle(stmt), what);
}

// Steps a statement; true when a row is available.
inline bool Step(sqlite3_stmt* stmt) {
  const int rc = sqlite3_step(stmt);
  if (rc == SQLITE_ROW) return true;
  if (rc == SQLITE_DONE) return false;
  ThrowSqlite(sqlite3_db_handle(stmt), sqlite3_sql(stmt));
}

inline void BindId(sqlite3_stmt* stmt, int col, int64_t id) {
  Check(stmt, sqlite3_bind_int64(stmt, col, id), "binding an id");
}

// Binds a blob that must stay alive until the statement is stepped. Binds a zero-length
// blob rather than NULL when empty, as COLMAP readers only look at the byte count.
inline void BindBlob(sqlite3_stmt* stmt, int col, const void* data, size_t num_bytes) {
  const int rc = num_bytes == 0 ? sqlite3_bind_zeroblob(stmt, col, 0)
                                : sqlite3_bind_blob64(stmt, col, data, num_bytes, SQLITE_STATIC);
  Check(stmt, rc, "binding a blob");
}

inline void BindMatrixBlob(sqlite3_stmt* stmt, int col, int64_t rows, int64_t cols, const void* data,
                    size_t num_bytes) {
  BindId(stmt, col, rows);
  BindId(stmt, col + 1, cols);
  BindBlob(stmt, col + 2, data, num_bytes);
}

inline std::string ColumnText(sqlite3_stmt* stmt, int col) {
  const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(stmt, col));
  return text != nullptr ? std::string(text) : std::string();
}

// Reads a (rows, cols, data) triple starting at `col` and checks the byte count.
struct BlobView {
  int64_t rows = 0, cols = 0;
  const void* data = nullptr;
};
inline BlobView ReadMatrixBlob(sqlite3_stmt* stmt, int col, size_t scalar_size, const std::string& what) {
  BlobView view{sqlite3_column_int64(stmt, col), sqlite3_column_int64(stmt, col + 1),
                sqlite3_column_blob(stmt, col + 2)};
  const int64_t num_bytes = sqlite3_column_bytes(stmt, col + 2);
  // rows * cols * scalar_size == num_bytes, by division: the product of two corrupt counts
  // can overflow int64.
  const int64_t num_entries = num_bytes / static_cast<int64_t>(scalar_size);
  const bool consistent =
      view.rows >= 0 && view.cols >= 0 && num_bytes % static_cast<int64_t>(scalar_size) == 0 &&
      (view.rows == 0 ? num_entries == 0
                      : num_entries % view.rows == 0 && num_entries / view.rows == view.cols);
  if (!consistent) {
    throw StorageError(fmt::format(
        "database {}: {} is corrupt ({} x {} entries but {} bytes); re-run the stage that "
        "wrote it, or start from a new database",
        sqlite3_db_filename(sqlite3_db_handle(stmt), "main"), what, view.rows, view.cols,
        num_bytes));
  }
  if (view.rows == 0) view.data = nullptr;
  return view;
}

// Reads `n` doubles; false (and zeros) for an empty blob, which COLMAP writes for unset
// geometry.
inline bool ReadDoubles(sqlite3_stmt* stmt, int col, double* out, int n) {
  const int num_bytes = sqlite3_column_bytes(stmt, col);
  if (num_bytes == 0) {
    std::fill(out, out + n, 0.0);
    return false;
  }
  if (num_bytes != n * static_cast<int>(sizeof(double))) {
    throw StorageError(fmt::format("database {}: a two-view geometry blob has {} bytes, "
                                   "expected {}; the database is corrupt",
                                   sqlite3_db_filename(sqlite3_db_handle(stmt), "main"),
                                   num_bytes, n * sizeof(double)));
  }
  std::memcpy(out, sqlite3_column_blob(stmt, col), num_bytes);
  return true;
}

}  // namespace loopsfm::sqlite

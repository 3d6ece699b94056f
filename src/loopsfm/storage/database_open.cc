// Opening a database: refusing files that are not ours without touching them, then
// creating COLMAP's tables and ours. Also the connection plumbing and transactions.

#include <sqlite3.h>

#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <set>

#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include "loopsfm/storage/database.h"
#include "loopsfm/storage/sqlite_util.h"
#include "loopsfm/util/errors.h"

namespace loopsfm {
namespace {

using namespace sqlite;  // this module's SQLite helpers
namespace fs = std::filesystem;

// COLMAP 3.8's schema. Column names and constraints match what `colmap database_creator`
// writes, so COLMAP's own CREATE TABLE IF NOT EXISTS / schema update finds nothing to do.
constexpr const char* kCreateTables[] = {
    "CREATE TABLE IF NOT EXISTS cameras ("
    " camera_id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL,"
    " model INTEGER NOT NULL, width INTEGER NOT NULL, height INTEGER NOT NULL,"
    " params BLOB, prior_focal_length INTEGER NOT NULL)",
    "CREATE TABLE IF NOT EXISTS images ("
    " image_id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL,"
    " name TEXT NOT NULL UNIQUE, camera_id INTEGER NOT NULL,"
    " prior_qw REAL, prior_qx REAL, prior_qy REAL, prior_qz REAL,"
    " prior_tx REAL, prior_ty REAL, prior_tz REAL,"
    " CONSTRAINT image_id_check CHECK(image_id >= 0 and image_id < 2147483647),"
    " FOREIGN KEY(camera_id) REFERENCES cameras(camera_id))",
    "CREATE UNIQUE INDEX IF NOT EXISTS index_name ON images(name)",
    "CREATE TABLE IF NOT EXISTS keypoints ("
    " image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL,"
    " data BLOB, FOREIGN KEY(image_id) REFERENCES images(image_id) ON DELETE CASCADE)",
    "CREATE TABLE IF NOT EXISTS descriptors ("
    " image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL,"
    " data BLOB, FOREIGN KEY(image_id) REFERENCES images(image_id) ON DELETE CASCADE)",
    "CREATE TABLE IF NOT EXISTS matches ("
    " pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL,"
    " data BLOB)",
    "CREATE TABLE IF NOT EXISTS two_view_geometries ("
    " pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL,"
    " data BLOB, config INTEGER NOT NULL, F BLOB, E BLOB, H BLOB, qvec BLOB, tvec BLOB)",
    "CREATE TABLE IF NOT EXISTS loopsfm_meta (key TEXT PRIMARY KEY NOT NULL, value TEXT)",
    "CREATE TABLE IF NOT EXISTS loopsfm_frames ("
    " image_id INTEGER PRIMARY KEY NOT NULL, source_index INTEGER NOT NULL,"
    " sharpness REAL NOT NULL, reason TEXT NOT NULL DEFAULT '',"
    " FOREIGN KEY(image_id) REFERENCES images(image_id) ON DELETE CASCADE)",
};

// The columns we read from each known table. A table with one of these names but without
// these columns belongs to some other program.
const std::map<std::string, std::vector<std::string>> kRequiredColumns = {
    {"cameras", {"camera_id", "model", "width", "height", "params", "prior_focal_length"}},
    {"images", {"image_id", "name", "camera_id"}},
    {"keypoints", {"image_id", "rows", "cols", "data"}},
    {"descriptors", {"image_id", "rows", "cols", "data"}},
    {"matches", {"pair_id", "rows", "cols", "data"}},
    {"two_view_geometries",
     {"pair_id", "rows", "cols", "data", "config", "F", "E", "H", "qvec", "tvec"}},
    {"loopsfm_meta", {"key", "value"}},
    {"loopsfm_frames", {"image_id", "source_index", "sharpness"}},
};

// COLMAP 3.8 stores 3800 in PRAGMA user_version; we write the same schema.
constexpr int kColmapUserVersion = 3800;

const char* kWhatToDo =
    "Pass the path of a new file (it will be created) or of a database written by loopsfm "
    "or COLMAP.";

// Refuses paths we must not open; returns whether the file exists already.
bool CheckPath(const std::string& path) {
  if (path.empty()) throw StorageError("database path is empty. " + std::string(kWhatToDo));
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (fs::is_directory(status)) {
    throw StorageError(fmt::format(
        "database path {} is a folder; pass a file path such as {}/database.db", path,
        fs::path(path).lexically_normal().string()));
  }
  if (!fs::exists(status)) {
    fs::path parent = fs::path(path).parent_path();
    if (parent.empty()) parent = ".";
    if (!fs::is_directory(parent, ec)) {
      throw StorageError(fmt::format(
          "cannot create database {}: folder {} does not exist; create it first or choose "
          "another path",
          path, parent.string()));
    }
    return false;
  }
  if (!fs::is_regular_file(status)) {
    throw StorageError(fmt::format("database path {} is not a regular file. {}", path, kWhatToDo));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw StorageError(fmt::format("cannot read database {}; check its permissions", path));
  }
  char header[16] = {};
  in.read(header, sizeof(header));
  const auto num_read = in.gcount();
  // An empty file is an empty SQLite database (e.g. one created just before a crash).
  if (num_read > 0 && (num_read < 16 || std::memcmp(header, "SQLite format 3", 16) != 0)) {
    throw StorageError(fmt::format(
        "{} is not a SQLite database (it does not start with the SQLite header; is it a "
        "video, an image or a text file?). It was left unchanged. {}",
        path, kWhatToDo));
  }
  return true;
}

// Reads the table layout without writing anything and refuses databases that are not
// COLMAP's or ours.
void CheckSchemaIsOurs(sqlite3* db, const std::string& path) {
  std::map<std::string, std::set<std::string>> tables;
  auto query = [&](const std::string& sql, auto&& on_row) {
    sqlite3_stmt* stmt = nullptr;
    if (sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt, nullptr) != SQLITE_OK) {
      const int code = sqlite3_errcode(db);
      if (code == SQLITE_NOTADB || code == SQLITE_CORRUPT) {
        throw StorageError(fmt::format(
            "{} is not a readable SQLite database ({}). It was left unchanged. {}", path,
            sqlite3_errmsg(db), kWhatToDo));
      }
      ThrowSqlite(db, "reading the schema");
    }
    const std::unique_ptr<sqlite3_stmt, int (*)(sqlite3_stmt*)> owner(stmt, sqlite3_finalize);
    int rc;
    while ((rc = sqlite3_step(stmt)) == SQLITE_ROW) on_row(stmt);
    if (rc != SQLITE_DONE) ThrowSqlite(db, "reading the schema");
  };
  query("SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%'",
        [&](sqlite3_stmt* stmt) { tables[ColumnText(stmt, 0)]; });
  if (tables.empty()) return;  // a new, empty database
  for (auto& [table, table_columns] : tables) {
    if (!kRequiredColumns.count(table)) continue;
    // A named reference: clang before 16 cannot capture a structured binding.
    std::set<std::string>& columns = table_columns;
    query(fmt::format("PRAGMA table_info(\"{}\")", table),
          [&](sqlite3_stmt* stmt) { columns.insert(ColumnText(stmt, 1)); });
  }
  std::vector<std::string> names;
  for (const auto& [table, columns] : tables) names.push_back(table);
  if (names.size() > 8) names.resize(8), names.push_back("...");
  const bool is_colmap = tables.count("cameras") && tables.count("images");
  if (!is_colmap && !tables.count("loopsfm_meta")) {
    throw StorageError(fmt::format(
        "{} is a SQLite database of another program (tables: {}), not a COLMAP or loopsfm "
        "database. It was left unchanged. {}",
        path, fmt::join(names, ", "), kWhatToDo));
  }
  for (const auto& [table, columns] : tables) {
    const auto it = kRequiredColumns.find(table);
    if (it == kRequiredColumns.end()) continue;
    for (const std::string& column : it->second) {
      if (!columns.count(column)) {
        throw StorageError(fmt::format(
            "{} has a table '{}' without column '{}', so it is not a COLMAP or loopsfm "
            "database (or a corrupt one). It was left unchanged. {}",
            path, table, column, kWhatToDo));
      }
    }
  }
  if (tables.count("loopsfm_meta")) {
    query("SELECT value FROM loopsfm_meta WHERE key = 'schema_version'",
          [&](sqlite3_stmt* stmt) {
            const int version = sqlite3_column_int(stmt, 0);
            if (version > Database::kSchemaVersion) {
              throw StorageError(fmt::format(
                  "{} was written by a newer loopsfm (schema version {}; this build reads up "
                  "to {}). Update loopsfm or start from a new database.",
                  path, version, Database::kSchemaVersion));
            }
          });
  }
}

}  // namespace

Database Database::Open(const std::string& path) {
  const bool exists = CheckPath(path);
  Database database;
  database.path_ = path;
  const int flags =
      SQLITE_OPEN_READWRITE | SQLITE_OPEN_NOMUTEX | (exists ? 0 : SQLITE_OPEN_CREATE);
  if (sqlite3_open_v2(path.c_str(), &database.db_, flags, nullptr) != SQLITE_OK) {
    const std::string message = database.db_ ? sqlite3_errmsg(database.db_) : "out of memory";
    throw StorageError(fmt::format("cannot open database {}: {}", path, message));
  }
  sqlite3_extended_result_codes(database.db_, 1);
  // Another process (colmap gui, a viewer) may hold a read lock briefly.
  sqlite3_busy_timeout(database.db_, 5000);
  CheckSchemaIsOurs(database.db_, path);
  if (sqlite3_db_readonly(database.db_, "main") == 1) {
    throw StorageError(fmt::format(
        "database {} is read-only; check the file's and its folder's permissions, or copy "
        "it to a writable place",
        path));
  }
  // Only now that the file is known to be ours do we write to it. WAL is what COLMAP
  // itself uses; with synchronous=NORMAL a crash loses at most the last transactions and
  // never leaves the file inconsistent.
  database.Exec("PRAGMA journal_mode = WAL");
  database.Exec("PRAGMA synchronous = NORMAL");
  database.Exec("PRAGMA foreign_keys = ON");
  database.Exec("PRAGMA temp_store = MEMORY");
  {
    Transaction transaction(database);
    const bool fresh = database.CountRows(
                           "SELECT COUNT(*) FROM sqlite_master WHERE name = 'cameras'") == 0;
    database.CreateTables();
    // Databases written before frames recorded why they were kept get the column, empty.
    if (database.CountRows("SELECT COUNT(*) FROM pragma_table_info('loopsfm_frames') "
                           "WHERE name = 'reason'") == 0) {
      database.Exec("ALTER TABLE loopsfm_frames ADD COLUMN reason TEXT NOT NULL DEFAULT ''");
    }
    if (fresh) {
      database.Exec(fmt::format("PRAGMA user_version = {}", kColmapUserVersion).c_str());
    }
    if (!database.ReadMeta("schema_version")) {
      database.WriteMeta("schema_version", std::to_string(kSchemaVersion));
    }
    transaction.Commit();
  }
  return database;
}

Database::Database(Database&& other) noexcept { *this = std::move(other); }

Database& Database::operator=(Database&& other) noexcept {
  if (this != &other) {
    Close();
    path_ = std::move(other.path_);
    db_ = std::exchange(other.db_, nullptr);
    statements_ = std::move(other.statements_);
    other.statements_.clear();
  }
  return *this;
}

Database::~Database() { Close(); }

void Database::Close() noexcept {
  for (auto& [sql, stmt] : statements_) sqlite3_finalize(stmt);
  statements_.clear();
  if (db_ != nullptr) sqlite3_close_v2(db_);
  db_ = nullptr;
}

void Database::Exec(const char* sql) const {
  char* error = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &error) != SQLITE_OK) {
    const std::string message = error ? error : sqlite3_errmsg(db_);
    sqlite3_free(error);
    throw StorageError(fmt::format("database {}: '{}' failed: {}", path_, sql, message));
  }
}

sqlite3_stmt* Database::Prepare(const char* sql) const {
  LOOPSFM_CHECK_MSG(db_ != nullptr, "use of a closed (moved-from) Database");
  auto it = statements_.find(sql);
  if (it != statements_.end()) return it->second;
  sqlite3_stmt* stmt = nullptr;
  if (sqlite3_prepare_v3(db_, sql, -1, SQLITE_PREPARE_PERSISTENT, &stmt, nullptr) != SQLITE_OK) {
    ThrowSqlite(db_, fmt::format("preparing '{}'", sql));
  }
  statements_.emplace(sql, stmt);
  return stmt;
}

size_t Database::CountRows(const char* sql) const {
  sqlite3_stmt* stmt = Prepare(sql);
  StatementScope scope(stmt);
  return Step(stmt) ? static_cast<size_t>(sqlite3_column_int64(stmt, 0)) : 0;
}

bool Database::ExistsRow(const char* sql, int64_t id) const {
  sqlite3_stmt* stmt = Prepare(sql);
  StatementScope scope(stmt);
  BindId(stmt, 1, id);
  return Step(stmt);
}

void Database::CreateTables() {
  for (const char* sql : kCreateTables) Exec(sql);
}

// ---- transactions -----------------------------------------------------------------------

Database::Transaction::Transaction(Database& database)
    : database_(&database), uncaught_exceptions_(std::uncaught_exceptions()) {
  database_->Exec("SAVEPOINT loopsfm_transaction");
}

void Database::Transaction::Commit() {
  if (!open_) return;
  open_ = false;
  database_->Exec("RELEASE loopsfm_transaction");
}

Database::Transaction::~Transaction() {
  if (!open_) return;
  try {
    if (std::uncaught_exceptions() > uncaught_exceptions_) {
      open_ = false;
      database_->Exec("ROLLBACK TO loopsfm_transaction");
      database_->Exec("RELEASE loopsfm_transaction");
    } else {
      Commit();
    }
  } catch (const std::exception& e) {
    // A destructor cannot throw; callers that must know call Commit() themselves.
    spdlog::error("{}", e.what());
  }
}

}  // namespace loopsfm

#pragma once
// The file layout the mappers' checkpoints share: a magic line, a version (uint32), the
// length of a JSON header (uint64) and the header, which holds the fingerprint of what the
// mapping depends on, then a binary body. A file is replaced atomically (written beside it,
// then renamed), so a kill while writing leaves the previous checkpoint.

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>

#include <nlohmann/json.hpp>

#include "loopsfm/util/byte_io.h"

namespace loopsfm {

struct CheckpointFormat {
  std::string magic;    // the first line, with its '\n'
  uint32_t version = 0;
};

// Writes `header` (to which the fingerprint is added) and `body`. Throws StorageError when
// the file cannot be written (the previous one is kept).
void WriteCheckpointFile(const std::filesystem::path& path, const CheckpointFormat& format,
                         nlohmann::json header, const nlohmann::json& fingerprint,
                         const std::string& body);

// Calls `parse` with the header and a reader at the body when the file at `path` has the
// format and the fingerprint, and returns true when it did without an error. False when
// there is no file, when it was made from another input or with other options (said at info
// level), or when it cannot be read or parsed (a warning says why): a checkpoint only saves
// time, so its content never ends a run.
bool ReadCheckpointFile(const std::filesystem::path& path, const CheckpointFormat& format,
                        const nlohmann::json& fingerprint,
                        const std::function<void(const nlohmann::json&, ByteReader&)>& parse);

}  // namespace loopsfm

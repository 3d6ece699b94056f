#pragma once
// The global mapper's checkpoint file, OUT/global_mapper_checkpoint.bin: written after each
// stage of each component (sfm/global_mapper_checkpoint.h), read when a run goes on in the
// same output folder, so a stopped mapping skips the stages it had done. The layout is the
// incremental mapper's (checkpoint_file.h): a JSON header with the fingerprint (the mapper
// input and every mapper option but the thread count), the reports and what each component
// holds, then each component's edges, rotations, poses and states in binary.

#include <filesystem>
#include <optional>

#include <nlohmann/json.hpp>

#include "loopsfm/sfm/global_mapper.h"

namespace loopsfm {

nlohmann::json GlobalMapperCheckpointFingerprint(const MapperInput& input,
                                                 const IncrementalMapperOptions& mapper_options,
                                                 const GlobalMapperOptions& options);

// Throws StorageError when the file cannot be written (the previous one is kept).
void WriteGlobalMapperCheckpoint(const std::filesystem::path& path,
                                 const GlobalMapperCheckpoint& checkpoint,
                                 const nlohmann::json& fingerprint);

// The checkpoint at `path`, or nullopt when there is none, when it was made from another
// input or with other options, or when it cannot be read or does not fit `input` (a warning
// says why). Never throws for the file's content.
std::optional<GlobalMapperCheckpoint> ReadGlobalMapperCheckpoint(
    const std::filesystem::path& path, const MapperInput& input,
    const nlohmann::json& fingerprint);

// The checkpoint file of one global mapping of `input`: the checkpoint it goes on from
// (where the file holds one that fits) and the GlobalMapperCheckpointing that saves there.
// Not copied or moved: checkpointing() refers to it.
class GlobalMapperCheckpointFile {
 public:
  GlobalMapperCheckpointFile(std::filesystem::path path, const MapperInput& input,
                             const IncrementalMapperOptions& mapper_options,
                             const GlobalMapperOptions& options);
  GlobalMapperCheckpointFile(const GlobalMapperCheckpointFile&) = delete;
  GlobalMapperCheckpointFile& operator=(const GlobalMapperCheckpointFile&) = delete;

  const GlobalMapperCheckpointing& checkpointing() const { return checkpointing_; }

 private:
  std::filesystem::path path_;
  nlohmann::json fingerprint_;
  std::optional<GlobalMapperCheckpoint> resume_;
  GlobalMapperCheckpointing checkpointing_;
};

}  // namespace loopsfm

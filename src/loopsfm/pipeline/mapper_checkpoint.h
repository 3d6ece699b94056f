#pragma once
// The incremental mapper's checkpoint file, OUT/mapper_checkpoint.bin: written now and then
// while mapping (and once mapping has finished), read when a run goes on in the same output
// folder, so an interrupted mapping resumes from its last checkpoint instead of from the
// start (sfm/mapper_checkpoint.h). One file, replaced atomically (written beside it, then
// renamed), so a kill while writing leaves the previous checkpoint.
//
// It holds a fingerprint of what mapping depends on (the tracks, pairs and cameras it maps,
// and every mapper option but the thread count); a checkpoint made from other matches or
// with other options is set aside and mapping starts from the beginning.
//
// Layout: "loopsfm mapper checkpoint\n", a version (uint32), the length of a JSON header
// (uint64) and the header (fingerprint, mapper state, report), then each model's mapped
// state in binary (little-endian): cameras, registered frames with poses, 3D points.

#include <filesystem>
#include <optional>

#include <nlohmann/json.hpp>

#include "loopsfm/sfm/incremental_mapper.h"
#include "loopsfm/sfm/mapper_checkpoint.h"
#include "loopsfm/sfm/mapper_input.h"

namespace loopsfm {

// The mapper's report as JSON and back (checkpoints, segments mapped on other ranks);
// FromJson throws InputError or a JSON error for text that is not one.
nlohmann::json MapperReportJson(const MapperReport& report);
MapperReport MapperReportFromJson(const nlohmann::json& json);

nlohmann::json MapperCheckpointFingerprint(const MapperInput& input,
                                           const IncrementalMapperOptions& options);

// Throws StorageError when the file cannot be written (the previous one is kept).
void WriteMapperCheckpoint(const std::filesystem::path& path, const MapperCheckpoint& checkpoint,
                           const nlohmann::json& fingerprint);

// The checkpoint at `path`, or nullopt when there is none, when it was made from another
// input or with other options (said at info level), or when it cannot be read (a warning
// says why). Never throws for the file's content: a checkpoint only saves time.
std::optional<MapperCheckpoint> ReadMapperCheckpoint(const std::filesystem::path& path,
                                                     const nlohmann::json& fingerprint);

// The checkpoint file of one mapping of `input`: the checkpoint it goes on from (where the
// file holds one that fits) and the MapperCheckpointing that saves there every
// interval_seconds. Not copied or moved: checkpointing() refers to it.
class MapperCheckpointFile {
 public:
  MapperCheckpointFile(std::filesystem::path path, const MapperInput& input,
                       const IncrementalMapperOptions& options, double interval_seconds);
  MapperCheckpointFile(const MapperCheckpointFile&) = delete;
  MapperCheckpointFile& operator=(const MapperCheckpointFile&) = delete;

  const MapperCheckpointing& checkpointing() const { return checkpointing_; }
  // The file held a finished mapping: the mapper only hands its models back.
  bool Finished() const { return resume_ && resume_->finished; }

 private:
  std::filesystem::path path_;
  nlohmann::json fingerprint_;
  std::optional<MapperCheckpoint> resume_;
  MapperCheckpointing checkpointing_;
};

}  // namespace loopsfm

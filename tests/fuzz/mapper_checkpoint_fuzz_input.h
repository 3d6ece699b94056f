#pragma once
// The fingerprint of mapper_checkpoint_fuzz: the target reads every input with it, and
// write_seed_corpus writes the seeds with it, so the seeds get past the fingerprint check
// into the decoding of the mapper state and the models.

#include <nlohmann/json.hpp>

namespace loopsfm::fuzz {

inline nlohmann::json MapperCheckpointFuzzFingerprint() { return {{"fuzz", 1}}; }

}  // namespace loopsfm::fuzz

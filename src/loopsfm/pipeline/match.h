#pragma once
// The matching stage: choose pairs, match descriptors, verify two-view geometry, store raw
// matches and verified geometries in the database, build tracks. Pairs already stored are
// skipped (resume); every tried pair is recorded, verified or not, so pairing strategies can
// be compared.

#include <string>
#include <vector>

#include <filesystem>
#include <map>
#include <optional>
#include <set>
#include <unordered_map>
#include <unordered_set>

#include <nlohmann/json.hpp>

#include "loopsfm/matching/descriptor_matcher.h"
#include "loopsfm/matching/guided_pairing.h"
#include "loopsfm/retrieval/vocabulary_tree.h"
#include "loopsfm/matching/geometric_verification.h"
#include "loopsfm/matching/pair_selection.h"
#include "loopsfm/matching/sequential_waves.h"
#include "loopsfm/matching/view_graph_bridging.h"
#include "loopsfm/pipeline/work_sharing.h"
#include "loopsfm/storage/database.h"
#include "loopsfm/tracks/track_builder.h"
#include "loopsfm/util/progress.h"

namespace loopsfm {

// exhaustive: every pair; sequential: each frame with its K previous ones; vocabtree:
// sequential neighbours, then vocabulary-tree guided rounds with region growing (loops);
// lowres: every pair, but first matched on the largest-scale features only, and fully
// matched only when that gives enough matches.
enum class PairStrategy { kExhaustive, kSequential, kVocabTree, kLowRes };

// Parses "exhaustive" | "sequential" | "vocabtree" | "lowres"; throws InvalidArgument
// naming the choices.
PairStrategy ParsePairStrategy(const std::string& name);
std::string PairStrategyName(PairStrategy strategy);

struct MatchOptions {
  // How pairs are chosen.
  PairStrategy strategy = PairStrategy::kVocabTree;
  // Overlaps for sequential pairing.
  SequentialPairingOptions sequential;
  // Nearest-neighbour matching and ratio test.
  DescriptorMatchingOptions matcher;
  // RANSAC verification.
  TwoViewVerificationOptions verification;
  // Vocabulary tree trained on the scene's own descriptors (when no vocab_path is given).
  VocabTreeOptions vocab_tree;
  // A tree saved by `loopsfm vocab build`, used instead of training one.
  std::filesystem::path vocab_path;
  // Guided rounds: proposals per round and the stop rule.
  GuidedPairingOptions guided;
  // Vocabtree: match sequential neighbours first (video frames are ordered), in waves that
  // go on past failed pairs and add quadratic steps (see sequential_waves.h).
  bool vocab_include_sequential = true;
  SequentialWavesOptions sequential_waves;
  // Vocabtree: after the guided rounds, bridge where the view graph falls apart or a frame
  // has few verified partners (see view_graph_bridging.h).
  bool vocab_bridging = true;
  ViewGraphBridgingOptions bridging;
  // Lowres: features per frame in the prefilter (largest scale first) and the matches
  // the prefilter must find for the pair to be fully matched.
  int lowres_num_features = 300;
  int lowres_min_matches = 12;
  // Vocabtree: write the similarity (the partners pairing kept of it) and match matrices as PNG
  // next to the database (frames binned beyond 1,200 a side).
  bool write_matrix_images = true;
  // Vocabtree: also write the similarity matrix as text here (empty: not written).
  std::filesystem::path similarity_path;
  // Worker threads (0: all cores).
  int num_threads = 0;
  // Pairs processed per batch, per rank (bounds the descriptors held in memory).
  int batch_size = 256;
  // The ranks of an MPI run to share the pairs with (null: this process alone).
  WorkSharing* sharing = nullptr;
  // Seed of the verification RANSAC (each pair derives its own stream).
  uint64_t seed = kDefaultRandomSeed;
  // Show progress on stderr.
  bool show_progress = true;
  // Who follows the progress and may ask the run to stop (null: nobody); must outlive the
  // run. The stages of a reconstruction get the reconstruction's.
  const RunHooks* hooks = nullptr;
  void Check() const;
};

// Timings of the vocabulary-tree strategy (on top of matching).
struct VocabTreeTimings {
  double build_seconds = 0.0;    // sampling descriptors and training (or loading) the tree
  double score_seconds = 0.0;    // quantising all frames and the similarity matrix
  double propose_seconds = 0.0;  // choosing pairs in the guided rounds
  double match_seconds = 0.0;    // matching and verifying the proposed pairs
  SequentialWavesReport sequential;
  GuidedPairingReport guided;
  ViewGraphBridgingReport bridging;
};

struct MatchReport {
  size_t num_pairs = 0;          // pairs chosen by the strategy
  size_t num_pairs_resumed = 0;  // of which already in the database
  size_t num_pairs_matched = 0;  // matched now
  size_t num_pairs_verified = 0; // of those, passed verification
  size_t num_raw_matches = 0;
  size_t num_inliers = 0;
  double seconds = 0.0;
  double load_seconds = 0.0;
  // Writing the results (on rank 0 of an MPI run).
  double store_seconds = 0.0;
  // Pairs matched by each rank of an MPI run (rank 0 first; one entry in one process).
  std::vector<size_t> pairs_per_rank;
  // Per matched pair: descriptor matching time (median, ms) and verification time.
  double median_match_ms = 0.0;
  double median_verify_ms = 0.0;
  // The descriptor matching kernel that ran ("avx2", ...; auto resolved).
  std::string kernel;
  // Filled by the vocabtree strategy.
  VocabTreeTimings vocab;
  // Filled by the lowres strategy: prefilter time and pairs it let through.
  double lowres_prefilter_seconds = 0.0;
  size_t lowres_num_passed = 0;
  double MeanInliers() const {
    return num_pairs_verified ? double(num_inliers) / num_pairs_verified : 0.0;
  }
};

MatchReport MatchPairs(Database& database, const MatchOptions& options);

// Matches and verifies lists of pairs on demand, storing results; pairs already stored are
// read back instead of matched again. Holds a bounded cache of features.
class PairMatcher {
 public:
  PairMatcher(Database& database, const MatchOptions& options);
  // One flag per pair: verified (now or before).
  std::vector<bool> Match(const std::vector<ImagePair>& pairs, MatchReport* report);

 private:
  const Camera& CameraOf(image_t image_id) const;
  // A request for another rank to match `pairs` of the batch that needs the frames `batch`.
  void PutMatchRequest(ByteWriter& request, int rank, const std::unordered_set<image_t>& batch,
                       const std::vector<ImagePair>& pairs);

  Database& database_;
  const MatchOptions& options_;
  Random random_;
  std::unordered_map<image_t, camera_t> camera_of_;
  std::unordered_map<camera_t, Camera> cameras_;
  std::map<image_t, FeatureSet> cache_;
  // Per rank: the frames it holds from this matcher (nullopt before the first request).
  std::vector<std::optional<std::set<image_t>>> held_;
  std::vector<double> match_ms_, verify_ms_;
};

// A worker rank's part of PairMatcher: matching and verifying the pairs rank 0 sends.
WorkHandler MatchWorkHandler();

// The lowres strategy over all pairs; pairs the prefilter rejects are recorded as tried
// with no matches (an empty matches row), so a resumed run skips them.
void MatchLowResPrefiltered(Database& database, const std::vector<image_t>& ordered_ids,
                            const MatchOptions& options, PairMatcher& matcher, MatchReport* report);

// The report as JSON (for benchmarks and scripts).
nlohmann::json ToJson(const MatchReport& report);

// The vocabtree strategy: sequential neighbours, then guided rounds (see guided_pairing.h).
void MatchVocabTreeGuided(Database& database, const std::vector<image_t>& ordered_ids,
                          const MatchOptions& options, PairMatcher& matcher, MatchReport* report);

// Frames in capture order (by name: frame_%06d for video, file names for folders).
std::vector<Frame> FramesInCaptureOrder(const Database& database);

// Tracks from every verified pair in the database.
std::vector<Track> BuildTracksFromDatabase(const Database& database,
                                           const TrackBuildOptions& options,
                                           TrackBuildReport* report);

}  // namespace loopsfm

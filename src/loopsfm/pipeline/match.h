#pragma once
// The matching stage: choose pairs, match descriptors, verify two-view geometry, store raw
// matches and verified geometries in the database, build tracks. Pairs already stored are
// skipped (resume); every tried pair is recorded, verified or not, so pairing strategies can
// be compared.

#include <string>
#include <vector>

#include "loopsfm/matching/descriptor_matcher.h"
#include "loopsfm/matching/geometric_verification.h"
#include "loopsfm/matching/pair_selection.h"
#include "loopsfm/storage/database.h"
#include "loopsfm/tracks/track_builder.h"

namespace loopsfm {

enum class PairStrategy { kExhaustive, kSequential };

// Parses "exhaustive" | "sequential"; throws InvalidArgument naming the valid choices.
PairStrategy ParsePairStrategy(const std::string& name);
std::string PairStrategyName(PairStrategy strategy);

struct MatchOptions {
  // How pairs are chosen.
  PairStrategy strategy = PairStrategy::kSequential;
  // Overlaps for sequential pairing.
  SequentialPairingOptions sequential;
  // Nearest-neighbour matching and ratio test.
  DescriptorMatchingOptions matcher;
  // RANSAC verification.
  TwoViewVerificationOptions verification;
  // Worker threads (0: all cores).
  int num_threads = 0;
  // Pairs processed per batch (bounds the descriptors held in memory).
  int batch_size = 256;
  // Seed of the verification RANSAC (each pair derives its own stream).
  uint64_t seed = kDefaultRandomSeed;
  // Show progress on stderr.
  bool show_progress = true;
  void Check() const;
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
  // Per matched pair: descriptor matching time (median, ms) and verification time.
  double median_match_ms = 0.0;
  double median_verify_ms = 0.0;
  double MeanInliers() const {
    return num_pairs_verified ? double(num_inliers) / num_pairs_verified : 0.0;
  }
};

MatchReport MatchPairs(Database& database, const MatchOptions& options);

// Frames in capture order (by name: frame_%06d for video, file names for folders).
std::vector<Frame> FramesInCaptureOrder(const Database& database);

// Tracks from every verified pair in the database.
std::vector<Track> BuildTracksFromDatabase(const Database& database,
                                           const TrackBuildOptions& options,
                                           TrackBuildReport* report);

}  // namespace loopsfm

#include "loopsfm/pipeline/match.h"
#include "loopsfm/pipeline/fingerprint.h"

#include <algorithm>
#include <map>
#include <unordered_set>

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include "loopsfm/util/errors.h"
#include "loopsfm/util/progress.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {

PairStrategy ParsePairStrategy(const std::string& name) {
  if (name == "exhaustive") return PairStrategy::kExhaustive;
  if (name == "sequential") return PairStrategy::kSequential;
  if (name == "vocabtree") return PairStrategy::kVocabTree;
  if (name == "lowres") return PairStrategy::kLowRes;
  throw InvalidArgument(fmt::format(
      "unknown pairing strategy '{}'; choose exhaustive, sequential, vocabtree or lowres", name));
}

std::string PairStrategyName(PairStrategy strategy) {
  switch (strategy) {
    case PairStrategy::kExhaustive: return "exhaustive";
    case PairStrategy::kSequential: return "sequential";
    case PairStrategy::kVocabTree: return "vocabtree";
    case PairStrategy::kLowRes: return "lowres";
  }
  return "?";
}

void MatchOptions::Check() const {
  sequential.Check();
  matcher.Check();
  verification.Check();
  LOOPSFM_REQUIRE_OPTION(num_threads >= 0, "--threads must be 0 (all cores) or positive, got {}",
                         num_threads);
  LOOPSFM_REQUIRE_OPTION(batch_size > 0, "batch size must be positive, got {}", batch_size);
  LOOPSFM_REQUIRE_OPTION(lowres_num_features >= 16, "lowres features must be at least 16, got {}",
                         lowres_num_features);
  LOOPSFM_REQUIRE_OPTION(lowres_min_matches >= 1, "lowres minimum matches must be positive, got {}",
                         lowres_min_matches);
  vocab_tree.Check();
  guided.Check();
  sequential_waves.Check();
  bridging.Check();
}

std::vector<Frame> FramesInCaptureOrder(const Database& database) {
  std::vector<Frame> frames = database.ReadFrames();
  std::sort(frames.begin(), frames.end(),
            [](const Frame& a, const Frame& b) { return a.name < b.name; });
  return frames;
}

namespace {

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return values[mid];
}

struct PairResult {
  FeatureMatches matches;
  TwoViewVerification verification;
  double match_ms = 0.0;
  double verify_ms = 0.0;
};

}  // namespace

PairMatcher::PairMatcher(Database& database, const MatchOptions& options)
    : database_(database), options_(options), random_(options.seed) {
  for (const Frame& frame : database.ReadFrames()) camera_of_[frame.image_id] = frame.camera_id;
  for (const Camera& camera : database.ReadCameras()) cameras_[camera.camera_id] = camera;
}

std::vector<bool> PairMatcher::Match(const std::vector<ImagePair>& all_pairs, MatchReport* report) {
  Timer timer;
  std::vector<bool> verified(all_pairs.size(), false);
  std::vector<size_t> todo;
  for (size_t i = 0; i < all_pairs.size(); ++i) {
    const ImagePair& pair = all_pairs[i];
    if (database_.ExistsMatches(pair.image_id1, pair.image_id2)) {
      ++report->num_pairs_resumed;
      const auto geometry = database_.ReadTwoViewGeometry(pair.image_id1, pair.image_id2);
      verified[i] = geometry && geometry->IsVerified();
    } else {
      todo.push_back(i);
    }
  }
  report->num_pairs += all_pairs.size();
  const int threads = options_.num_threads > 0
                          ? options_.num_threads
                          : static_cast<int>(std::thread::hardware_concurrency());
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::max(1, threads));
  Progress progress("match", todo.size(), options_.show_progress && !todo.empty());

  for (size_t begin = 0; begin < todo.size(); begin += options_.batch_size) {
    const size_t end = std::min(todo.size(), begin + options_.batch_size);
    // Load the features this batch needs; drop the ones it does not.
    Timer load_timer;
    std::unordered_set<image_t> needed;
    for (size_t k = begin; k < end; ++k) {
      needed.insert(all_pairs[todo[k]].image_id1);
      needed.insert(all_pairs[todo[k]].image_id2);
    }
    for (auto it = cache_.begin(); it != cache_.end();) {
      it = needed.count(it->first) ? std::next(it) : cache_.erase(it);
    }
    for (image_t id : needed) {
      if (!cache_.count(id)) cache_.emplace(id, database_.ReadFeatures(id));
    }
    report->load_seconds += load_timer.ElapsedSeconds();

    std::vector<PairResult> results(end - begin);
    tbb::parallel_for(size_t{0}, end - begin, [&](size_t k) {
      const ImagePair& pair = all_pairs[todo[begin + k]];
      const FeatureSet& f1 = cache_.at(pair.image_id1);
      const FeatureSet& f2 = cache_.at(pair.image_id2);
      PairResult& result = results[k];
      Timer pair_timer;
      result.matches = MatchDescriptors(f1.descriptors, f2.descriptors, options_.matcher);
      result.match_ms = pair_timer.ElapsedMillis();
      pair_timer.Restart();
      Random pair_random = random_.Derive(PairToPairId(pair));
      result.verification = VerifyTwoViewGeometry(
          cameras_.at(camera_of_.at(pair.image_id1)), f1.keypoints,
          cameras_.at(camera_of_.at(pair.image_id2)), f2.keypoints, result.matches,
          options_.verification, pair_random);
      result.verify_ms = pair_timer.ElapsedMillis();
      progress.Advance();
    });

    Database::Transaction transaction(database_);
    for (size_t k = 0; k < results.size(); ++k) {
      const ImagePair& pair = all_pairs[todo[begin + k]];
      const PairResult& result = results[k];
      database_.WriteMatches(pair.image_id1, pair.image_id2, result.matches);
      database_.WriteTwoViewGeometry(pair.image_id1, pair.image_id2, result.verification.geometry);
      ++report->num_pairs_matched;
      report->num_raw_matches += result.matches.size();
      if (result.verification.geometry.IsVerified()) {
        verified[todo[begin + k]] = true;
        ++report->num_pairs_verified;
        report->num_inliers += result.verification.geometry.inlier_matches.size();
      }
      match_ms_.push_back(result.match_ms);
      verify_ms_.push_back(result.verify_ms);
    }
    transaction.Commit();
  }
  progress.Finish();
  report->median_match_ms = Median(match_ms_);
  report->median_verify_ms = Median(verify_ms_);
  report->seconds += timer.ElapsedSeconds();
  return verified;
}

MatchReport MatchPairs(Database& database, const MatchOptions& options) {
  options.Check();
  CheckFingerprint(database, "match", MatchFingerprint(options));
  Timer timer;
  MatchReport report;
  report.kernel = DescriptorKernelName(options.matcher.kernel == DescriptorKernel::kAuto
                                           ? FastestDescriptorKernel()
                                           : options.matcher.kernel);
  std::vector<image_t> ordered_ids;
  for (const Frame& frame : FramesInCaptureOrder(database)) ordered_ids.push_back(frame.image_id);
  PairMatcher matcher(database, options);
  switch (options.strategy) {
    case PairStrategy::kExhaustive:
      matcher.Match(ExhaustivePairs(ordered_ids), &report);
      break;
    case PairStrategy::kSequential:
      matcher.Match(SequentialPairs(ordered_ids, options.sequential), &report);
      break;
    case PairStrategy::kVocabTree:
      MatchVocabTreeGuided(database, ordered_ids, options, matcher, &report);
      break;
    case PairStrategy::kLowRes:
      MatchLowResPrefiltered(database, ordered_ids, options, matcher, &report);
      break;
  }
  report.seconds = timer.ElapsedSeconds();
  return report;
}

nlohmann::json ToJson(const MatchReport& r) {
  nlohmann::json rounds = nlohmann::json::array();
  for (const auto& round : r.vocab.guided.rounds) {
    rounds.push_back({{"from_scores", round.num_from_scores},
                      {"from_growing", round.num_from_growing},
                      {"verified", round.num_verified},
                      {"verified_from_scores", round.num_verified_from_scores}});
  }
  return {{"num_pairs", r.num_pairs},
          {"num_pairs_resumed", r.num_pairs_resumed},
          {"num_pairs_matched", r.num_pairs_matched},
          {"num_pairs_verified", r.num_pairs_verified},
          {"num_raw_matches", r.num_raw_matches},
          {"num_inliers", r.num_inliers},
          {"seconds", r.seconds},
          {"load_seconds", r.load_seconds},
          {"median_match_ms", r.median_match_ms},
          {"median_verify_ms", r.median_verify_ms},
          {"kernel", r.kernel},
          {"lowres_prefilter_seconds", r.lowres_prefilter_seconds},
          {"lowres_num_passed", r.lowres_num_passed},
          {"vocab",
           {{"build_seconds", r.vocab.build_seconds},
            {"score_seconds", r.vocab.score_seconds},
            {"propose_seconds", r.vocab.propose_seconds},
            {"match_seconds", r.vocab.match_seconds},
            {"sequential",
             {{"tried", r.vocab.sequential.num_tried},
              {"verified", r.vocab.sequential.num_verified},
              {"quadratic_tried", r.vocab.sequential.num_quadratic_tried},
              {"quadratic_verified", r.vocab.sequential.num_quadratic_verified}}},
            {"rounds", rounds},
            {"bridging",
             {{"components_before", r.vocab.bridging.num_components_before},
              {"largest_component_before", r.vocab.bridging.largest_component_before},
              {"components_after", r.vocab.bridging.num_components_after},
              {"largest_component_after", r.vocab.bridging.largest_component_after},
              {"rounds", r.vocab.bridging.num_rounds},
              {"tried", r.vocab.bridging.num_tried},
              {"verified", r.vocab.bridging.num_verified}}}}}};
}

std::vector<Track> BuildTracksFromDatabase(const Database& database,
                                           const TrackBuildOptions& options,
                                           TrackBuildReport* report) {
  std::unordered_map<image_t, size_t> num_points2D;
  for (const Frame& frame : database.ReadFrames()) {
    num_points2D[frame.image_id] = database.ReadKeypoints(frame.image_id).size();
  }
  const auto geometries = database.ReadAllTwoViewGeometries();
  std::vector<VerifiedPairMatches> pairs;
  for (const auto& [pair, geometry] : geometries) {
    if (geometry.IsVerified()) pairs.push_back({pair, &geometry.inlier_matches});
  }
  return BuildTracks(num_points2D, pairs, options, report);
}

}  // namespace loopsfm

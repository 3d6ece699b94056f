#include "loopsfm/pipeline/match.h"

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
  throw InvalidArgument(
      fmt::format("unknown pairing strategy '{}'; choose exhaustive or sequential", name));
}

std::string PairStrategyName(PairStrategy strategy) {
  switch (strategy) {
    case PairStrategy::kExhaustive: return "exhaustive";
    case PairStrategy::kSequential: return "sequential";
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

MatchReport MatchPairs(Database& database, const MatchOptions& options) {
  options.Check();
  Timer timer;
  MatchReport report;
  const std::vector<Frame> frames = FramesInCaptureOrder(database);
  std::vector<image_t> ordered_ids;
  std::unordered_map<image_t, camera_t> camera_of;
  for (const Frame& frame : frames) {
    ordered_ids.push_back(frame.image_id);
    camera_of[frame.image_id] = frame.camera_id;
  }
  std::unordered_map<camera_t, Camera> cameras;
  for (const Camera& camera : database.ReadCameras()) cameras[camera.camera_id] = camera;

  const std::vector<ImagePair> all_pairs = options.strategy == PairStrategy::kExhaustive
                                               ? ExhaustivePairs(ordered_ids)
                                               : SequentialPairs(ordered_ids, options.sequential);
  report.num_pairs = all_pairs.size();
  std::vector<ImagePair> pairs;
  for (const ImagePair& pair : all_pairs) {
    if (database.ExistsMatches(pair.image_id1, pair.image_id2)) {
      ++report.num_pairs_resumed;
    } else {
      pairs.push_back(pair);
    }
  }

  const int threads = options.num_threads > 0 ? options.num_threads
                                              : static_cast<int>(std::thread::hardware_concurrency());
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::max(1, threads));
  Progress progress("match", pairs.size(), options.show_progress);
  const Random random(options.seed);
  std::map<image_t, FeatureSet> cache;
  std::vector<double> match_ms, verify_ms;

  for (size_t begin = 0; begin < pairs.size(); begin += options.batch_size) {
    const size_t end = std::min(pairs.size(), begin + options.batch_size);
    // Load the features this batch needs; drop the ones it does not.
    Timer load_timer;
    std::unordered_set<image_t> needed;
    for (size_t i = begin; i < end; ++i) {
      needed.insert(pairs[i].image_id1);
      needed.insert(pairs[i].image_id2);
    }
    for (auto it = cache.begin(); it != cache.end();) {
      it = needed.count(it->first) ? std::next(it) : cache.erase(it);
    }
    for (image_t id : needed) {
      if (!cache.count(id)) cache.emplace(id, database.ReadFeatures(id));
    }
    report.load_seconds += load_timer.ElapsedSeconds();

    std::vector<PairResult> results(end - begin);
    tbb::parallel_for(size_t{0}, end - begin, [&](size_t k) {
      const ImagePair& pair = pairs[begin + k];
      const FeatureSet& f1 = cache.at(pair.image_id1);
      const FeatureSet& f2 = cache.at(pair.image_id2);
      PairResult& result = results[k];
      Timer pair_timer;
      result.matches = MatchDescriptors(f1.descriptors, f2.descriptors, options.matcher);
      result.match_ms = pair_timer.ElapsedMillis();
      pair_timer.Restart();
      Random pair_random = random.Derive(PairToPairId(pair));
      result.verification = VerifyTwoViewGeometry(
          cameras.at(camera_of.at(pair.image_id1)), f1.keypoints,
          cameras.at(camera_of.at(pair.image_id2)), f2.keypoints, result.matches,
          options.verification, pair_random);
      result.verify_ms = pair_timer.ElapsedMillis();
      progress.Advance();
    });

    Database::Transaction transaction(database);
    for (size_t k = 0; k < results.size(); ++k) {
      const ImagePair& pair = pairs[begin + k];
      const PairResult& result = results[k];
      database.WriteMatches(pair.image_id1, pair.image_id2, result.matches);
      database.WriteTwoViewGeometry(pair.image_id1, pair.image_id2, result.verification.geometry);
      ++report.num_pairs_matched;
      report.num_raw_matches += result.matches.size();
      if (result.verification.geometry.IsVerified()) {
        ++report.num_pairs_verified;
        report.num_inliers += result.verification.geometry.inlier_matches.size();
      }
      match_ms.push_back(result.match_ms);
      verify_ms.push_back(result.verify_ms);
    }
    transaction.Commit();
  }
  progress.Finish();
  report.median_match_ms = Median(match_ms);
  report.median_verify_ms = Median(verify_ms);
  report.seconds = timer.ElapsedSeconds();
  return report;
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

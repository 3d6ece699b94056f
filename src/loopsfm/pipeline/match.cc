#include "loopsfm/pipeline/match.h"
#include "loopsfm/pipeline/fingerprint.h"

#include <algorithm>
#include <array>
#include <memory>
#include <set>
#include <map>
#include <unordered_set>

#include "loopsfm/pipeline/wire_format.h"
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

// Matches and verifies one pair; `random` is the pair's own stream, so the result does not
// depend on which thread or rank computes it.
PairResult MatchPair(const Camera& camera1, const FeatureSet& features1, const Camera& camera2,
                     const FeatureSet& features2, const DescriptorMatchingOptions& matcher,
                     const TwoViewVerificationOptions& verification, Random random) {
  PairResult result;
  Timer timer;
  result.matches = MatchDescriptors(features1.descriptors, features2.descriptors, matcher);
  result.match_ms = timer.ElapsedMillis();
  timer.Restart();
  result.verification = VerifyTwoViewGeometry(camera1, features1.keypoints, camera2,
                                              features2.keypoints, result.matches, verification,
                                              random);
  result.verify_ms = timer.ElapsedMillis();
  return result;
}

// A pair's result as it travels from the rank that computed it.
void PutPairResult(ByteWriter& w, const PairResult& result) {
  w.PutVector(result.matches);
  PutGeometry(w, result.verification.geometry);
  w.Put(result.match_ms);
  w.Put(result.verify_ms);
}

PairResult GetPairResult(ByteReader& r) {
  PairResult result;
  result.matches = r.GetVector<FeatureMatch>();
  result.verification.geometry = GetGeometry(r);
  result.match_ms = r.Get<double>();
  result.verify_ms = r.Get<double>();
  return result;
}

// Pairs per unit of work: enough to be worth a message, few enough to balance.
constexpr size_t kPairsPerUnit = 4;

// A frame's camera and features, as a worker rank holds them between requests.
struct HeldFrame {
  Camera camera;
  FeatureSet features;
};

}  // namespace

PairMatcher::PairMatcher(Database& database, const MatchOptions& options)
    : database_(database), options_(options), random_(options.seed) {
  for (const Frame& frame : database.ReadFrames()) camera_of_[frame.image_id] = frame.camera_id;
  for (const Camera& camera : database.ReadCameras()) cameras_[camera.camera_id] = camera;
}

const Camera& PairMatcher::CameraOf(image_t image_id) const {
  return cameras_.at(camera_of_.at(image_id));
}

void PairMatcher::PutMatchRequest(ByteWriter& request, int rank,
                                  const std::unordered_set<image_t>& batch,
                                  const std::vector<ImagePair>& pairs) {
  // What the rank holds, as this matcher last told it: on the first request, nothing (it
  // forgets what an earlier matcher sent); frames of earlier batches are dropped.
  const bool first = !held_[rank].has_value();
  std::set<image_t>& held = first ? held_[rank].emplace() : *held_[rank];
  request.Put<uint8_t>(first ? 1 : 0);
  std::vector<image_t> drop;
  for (image_t id : held) {
    if (!batch.count(id)) drop.push_back(id);
  }
  for (image_t id : drop) held.erase(id);
  request.PutVector(drop);
  std::vector<image_t> send;
  for (const ImagePair& pair : pairs) {
    for (image_t id : {pair.image_id1, pair.image_id2}) {
      if (held.insert(id).second) send.push_back(id);
    }
  }
  request.Put<uint64_t>(send.size());
  for (image_t id : send) {
    request.Put<image_t>(id);
    PutCamera(request, CameraOf(id));
    PutFeatures(request, cache_.at(id));
  }
  request.Put(options_.matcher);
  request.Put(options_.verification);
  request.Put<uint64_t>(random_.Seed());
  request.PutVector(pairs);
}

WorkHandler MatchWorkHandler() {
  auto held = std::make_shared<std::unordered_map<image_t, std::shared_ptr<const HeldFrame>>>();
  return [held](ByteReader& request) {
    if (request.Get<uint8_t>()) held->clear();
    for (image_t id : request.GetVector<image_t>()) held->erase(id);
    const uint64_t num_sent = request.Get<uint64_t>();
    for (uint64_t n = 0; n < num_sent; ++n) {
      const auto id = request.Get<image_t>();
      auto frame = std::make_shared<HeldFrame>();
      frame->camera = GetCamera(request);
      frame->features = GetFeatures(request);
      (*held)[id] = std::move(frame);
    }
    const auto matcher = request.Get<DescriptorMatchingOptions>();
    const auto verification = request.Get<TwoViewVerificationOptions>();
    const Random random(request.Get<uint64_t>());
    // The frames this unit needs, held by the computation (a later request may drop them).
    std::vector<std::pair<ImagePair, std::array<std::shared_ptr<const HeldFrame>, 2>>> work;
    for (const ImagePair& pair : request.GetVector<ImagePair>()) {
      auto frame = [&](image_t id) {
        auto it = held->find(id);
        if (it == held->end()) throw Error(fmt::format("frame {} was not sent", id));
        return it->second;
      };
      work.push_back({pair, {frame(pair.image_id1), frame(pair.image_id2)}});
    }
    return [work = std::move(work), matcher, verification, random](ByteWriter& result) {
      for (const auto& [pair, frames] : work) {
        PutPairResult(result, MatchPair(frames[0]->camera, frames[0]->features,
                                        frames[1]->camera, frames[1]->features, matcher,
                                        verification, random.Derive(PairToPairId(pair))));
      }
    };
  };
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
  std::optional<WorkSharing> own_sharing;
  WorkSharing& sharing = options_.sharing ? *options_.sharing
                                          : own_sharing.emplace(nullptr, options_.num_threads);
  if (held_.size() != size_t(sharing.NumRanks())) held_.assign(sharing.NumRanks(), std::nullopt);
  Progress progress("match", todo.size(), options_.show_progress && !todo.empty(),
                    options_.hooks);
  const size_t batch_size = size_t(options_.batch_size) * sharing.NumRanks();

  for (size_t begin = 0; begin < todo.size(); begin += batch_size) {
    const size_t end = std::min(todo.size(), begin + batch_size);
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
    const size_t num_units = (end - begin + kPairsPerUnit - 1) / kPairsPerUnit;
    auto pairs_of = [&](size_t unit) {
      const size_t first = unit * kPairsPerUnit;
      return std::make_pair(first, std::min(end - begin, first + kPairsPerUnit));
    };
    int last_unit_rank = 0;  // who computed the last unit, which may be short
    WorkSharing::Job job;
    job.kind = WorkKind::kMatchPairs;
    job.next = [&](size_t unit) { return unit < num_units; };
    job.compute = [&](size_t unit) {
      const auto [first, last] = pairs_of(unit);
      for (size_t k = first; k < last; ++k) {
        const ImagePair& pair = all_pairs[todo[begin + k]];
        results[k] = MatchPair(CameraOf(pair.image_id1), cache_.at(pair.image_id1),
                               CameraOf(pair.image_id2), cache_.at(pair.image_id2),
                               options_.matcher, options_.verification,
                               random_.Derive(PairToPairId(pair)));
      }
    };
    job.request = [&](size_t unit, int rank, ByteWriter& request) {
      const auto [first, last] = pairs_of(unit);
      std::vector<ImagePair> pairs;
      for (size_t k = first; k < last; ++k) pairs.push_back(all_pairs[todo[begin + k]]);
      PutMatchRequest(request, rank, needed, pairs);
    };
    job.take_result = [&](size_t unit, int rank, ByteReader& result) {
      if (unit + 1 == num_units) last_unit_rank = rank;
      const auto [first, last] = pairs_of(unit);
      for (size_t k = first; k < last; ++k) results[k] = GetPairResult(result);
    };
    job.finish = [&](size_t unit) {
      const auto [first, last] = pairs_of(unit);
      for (size_t k = first; k < last; ++k) progress.Advance();
    };
    sharing.Run(job);
    const std::vector<size_t>& units = sharing.UnitsPerRank();
    report->pairs_per_rank.resize(std::max(report->pairs_per_rank.size(), units.size()), 0);
    for (size_t rank = 0; rank < units.size(); ++rank) {
      report->pairs_per_rank[rank] += units[rank] * kPairsPerUnit;
    }
    if (const size_t short_by = num_units * kPairsPerUnit - (end - begin); short_by > 0) {
      report->pairs_per_rank[last_unit_rank] -= short_by;
    }

    Timer store_timer;
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
    report->store_seconds += store_timer.ElapsedSeconds();
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
          {"store_seconds", r.store_seconds},
          {"pairs_per_rank", r.pairs_per_rank},
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

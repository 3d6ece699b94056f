#include "loopsfm/sfm/incremental_mapper.h"

#include <algorithm>
#include <memory>
#include <tuple>
#include <unordered_map>
#include <unordered_set>

#include "loopsfm/sfm/initial_pair.h"
#include "loopsfm/sfm/mapper_checkpoint.h"
#include "loopsfm/sfm/mapper_state.h"
#include "loopsfm/sfm/model_merger.h"
#include "loopsfm/util/errors.h"
#include "loopsfm/util/logging.h"
#include "loopsfm/util/timer.h"

namespace loopsfm {

namespace {

using ModelPtr = std::unique_ptr<MapperState>;

// Failed merges with one model after which its frames are no longer registered into
// another (two models that disagree would otherwise be built twice over).
constexpr int kMaxMergeFailures = 3;

class IncrementalMapper {
 public:
  IncrementalMapper(const MapperInput& input, const IncrementalMapperOptions& options,
                    MapperReport* report, const MapperProgress& progress,
                    const MapperCheckpointing& checkpointing, MapperHook* hook)
      : input_(input), options_(options), report_(*report), progress_(progress),
        checkpointing_(checkpointing), random_(options.seed), hook_(hook) {}

  std::vector<Reconstruction> Run() {
    Timer ranking;
    const std::vector<InitialPairCandidate> candidates = RankInitialPairs(input_, options_);
    spdlog::info("mapper: {} initial pair candidates ({} strict), {:.1f} s", candidates.size(),
                 std::count_if(candidates.begin(), candidates.end(),
                               [](const auto& c) { return c.tier == 0; }),
                 ranking.ElapsedSeconds());
    tried_.assign(candidates.size(), 0);
    ModelPtr model;
    bool finished = false;
    if (checkpointing_.resume) {
      try {
        finished = Restore(*checkpointing_.resume, &model);
      } catch (const InputError& e) {
        spdlog::warn("mapper: the checkpoint does not fit this input ({}); mapping starts from "
                     "the beginning", e.what());
      }
    }
    last_checkpoint_.Restart();
    if (!starts_.empty()) {
      // The first start model grows; the others are kept, to be merged where it meets them.
      for (size_t k = 1; k < starts_.size(); ++k) Keep(starts_[k]);
      Grow(starts_[0]);
      Keep(starts_[0]);
      starts_.clear();
    }
    while (!finished) {
      if (!model) {
        if (static_cast<int>(models_.size()) >= options_.max_num_models) break;
        model = StartModel(candidates);
        if (!model) break;
      }
      Grow(model);
      Keep(model);
    }
    if (!finished) {
      MergeKeptModels();
      std::sort(models_.begin(), models_.end(), [](const ModelPtr& a, const ModelPtr& b) {
        return a->reconstruction().NumRegImages() > b->reconstruction().NumRegImages();
      });
      if (hook_ && !models_.empty()) hook_->AfterMapping(*models_[0], &report_);
      if (checkpointing_.save) {
        Timer timer;
        checkpointing_.save(Save(nullptr, /*finished=*/true));
        report_.seconds_checkpoints += timer.ElapsedSeconds();  // after: not in the saved one
      }
    }
    std::vector<Reconstruction> result;
    for (ModelPtr& model : models_) {
      model->reconstruction().UpdateReprojectionErrors();
      result.push_back(std::move(model->reconstruction()));
    }
    report_.num_models = static_cast<int>(result.size());
    return result;
  }

  // Models to go on from (ExtendIncrementalModels), largest first: each takes over a model's
  // poses and triangulates its tracks.
  void SetStartModels(const std::vector<Reconstruction>& models) {
    std::vector<const Reconstruction*> order;
    for (const Reconstruction& model : models) order.push_back(&model);
    std::stable_sort(order.begin(), order.end(), [](const auto* a, const auto* b) {
      return a->NumRegImages() > b->NumRegImages();
    });
    for (const Reconstruction* model : order) {
      auto state = std::make_unique<MapperState>(input_, options_);
      if (state->TakeFramesOf(*model).size() < 2) continue;
      state->RetriangulateAll();
      state->FilterPoints({});
      starts_.push_back(std::move(state));
    }
  }

 private:
  // A grown model joins the kept ones if it is large enough; it is discarded otherwise.
  void Keep(ModelPtr& model) {
    if (static_cast<int>(model->reconstruction().NumRegImages()) >= options_.min_model_size) {
      models_.push_back(std::move(model));
    } else {
      ++report_.num_models_discarded;
      spdlog::info("mapper: discarded a model of {} frames; its frames stay free",
                   model->reconstruction().NumRegImages());
    }
    model.reset();
  }

  bool RegisteredInKeptModel(image_t id) const {
    return std::any_of(models_.begin(), models_.end(),
                       [&](const ModelPtr& m) { return m->reconstruction().IsRegistered(id); });
  }

  // The mapper's state now, `growing` being the model grown (null between models).
  MapperCheckpoint Save(const MapperState* growing, bool finished) const {
    MapperCheckpoint checkpoint;
    checkpoint.finished = finished;
    auto save_model = [&](const MapperState& model) {
      MapperCheckpoint::Model saved = model.Save();
      const auto failures = merge_failures_.find(&model);
      saved.merge_failures = failures == merge_failures_.end() ? 0 : failures->second;
      return saved;
    };
    for (const ModelPtr& model : models_) checkpoint.kept.push_back(save_model(*model));
    if (growing) {
      checkpoint.growing = save_model(*growing);
      checkpoint.failed_at.assign(growth_.failed_at.begin(), growth_.failed_at.end());
      std::sort(checkpoint.failed_at.begin(), checkpoint.failed_at.end());
      checkpoint.ever_failed.assign(growth_.ever_failed.begin(), growth_.ever_failed.end());
      std::sort(checkpoint.ever_failed.begin(), checkpoint.ever_failed.end());
      checkpoint.last_global_size = growth_.last_global_size;
      checkpoint.recent_frames = growth_.recent;
      checkpoint.refined_since_stall = growth_.refined_since_stall;
    }
    checkpoint.tried_initial_pairs = tried_;
    checkpoint.random_state = random_.State();
    if (hook_) hook_->Save(&checkpoint);
    checkpoint.report = report_;
    return checkpoint;
  }

  // Puts the mapper back in the state saved; `growing` gets the model that was being grown.
  // Returns whether mapping had finished. Throws InputError, leaving the mapper as it was,
  // for a state that does not fit this input.
  bool Restore(const MapperCheckpoint& checkpoint, ModelPtr* growing) {
    if (checkpoint.tried_initial_pairs.size() != tried_.size()) {
      throw InputError(fmt::format("it ranked {} initial pairs, this input {}",
                                   checkpoint.tried_initial_pairs.size(), tried_.size()));
    }
    std::optional<Random> random = Random::FromState(checkpoint.random_state);
    if (!random) throw InputError("its random state is not one");
    std::vector<ModelPtr> kept;
    for (const MapperCheckpoint::Model& saved : checkpoint.kept) {
      kept.push_back(std::make_unique<MapperState>(input_, options_));
      kept.back()->Restore(saved);
    }
    ModelPtr grown;
    if (checkpoint.growing) {
      grown = std::make_unique<MapperState>(input_, options_);
      grown->Restore(*checkpoint.growing);
    }
    if (hook_) hook_->Restore(checkpoint);  // the last step that may throw
    for (size_t m = 0; m < kept.size(); ++m) {
      if (checkpoint.kept[m].merge_failures > 0) {
        merge_failures_[kept[m].get()] = checkpoint.kept[m].merge_failures;
      }
      models_.push_back(std::move(kept[m]));
    }
    if (grown) {
      if (checkpoint.growing->merge_failures > 0) {
        merge_failures_[grown.get()] = checkpoint.growing->merge_failures;
      }
      *growing = std::move(grown);
      growth_.failed_at.clear();
      for (const auto& [id, count] : checkpoint.failed_at) growth_.failed_at[id] = count;
      growth_.ever_failed.clear();
      growth_.ever_failed.insert(checkpoint.ever_failed.begin(), checkpoint.ever_failed.end());
      growth_.last_global_size = checkpoint.last_global_size;
      growth_.recent = checkpoint.recent_frames;
      growth_.refined_since_stall = checkpoint.refined_since_stall;
      resume_growth_ = true;
    }
    tried_ = checkpoint.tried_initial_pairs;
    random_ = *random;
    report_ = checkpoint.report;
    spdlog::info("mapper: going on from a checkpoint ({} frames registered in {} models{})",
                 checkpoint.NumRegistered(), models_.size() + (*growing ? 1 : 0),
                 checkpoint.finished ? ", mapping had finished" : "");
    return checkpoint.finished;
  }

  void MaybeSaveCheckpoint(const MapperState& growing) {
    if (!checkpointing_.save ||
        last_checkpoint_.ElapsedSeconds() < checkpointing_.interval_seconds) {
      return;
    }
    Timer timer;
    checkpointing_.save(Save(&growing, /*finished=*/false));
    report_.seconds_checkpoints += timer.ElapsedSeconds();
    last_checkpoint_.Restart();
  }

  // The first candidate pair of free frames whose two-view model passes validation.
  ModelPtr StartModel(const std::vector<InitialPairCandidate>& candidates) {
    int trials = 0;
    for (size_t c = 0; c < candidates.size() && trials < options_.init_max_trials; ++c) {
      if (tried_[c]) continue;
      const ImagePair& pair = candidates[c].pair->pair;
      if (RegisteredInKeptModel(pair.image_id1) || RegisteredInKeptModel(pair.image_id2)) continue;
      tried_[c] = 1;
      if (TurnsOnTheSpot(candidates[c], input_, options_)) continue;  // not counted as a trial
      ++trials;
      auto model = std::make_unique<MapperState>(input_, options_);
      if (!InitializeModel(*model, candidates[c], &report_)) continue;
      const Reconstruction& rec = model->reconstruction();
      spdlog::info("model {}: initial pair {} + {} ({} inliers, {} well conditioned, median angle "
                   "{:.1f} deg, homography ratio {:.2f}): {} points",
                   models_.size() + 1, rec.GetImage(pair.image_id1).name,
                   rec.GetImage(pair.image_id2).name, candidates[c].num_inliers,
                   candidates[c].num_well_conditioned, candidates[c].median_tri_angle_deg,
                   candidates[c].h_ratio, rec.NumPoints3D());
      return model;
    }
    return nullptr;
  }

  // The kept model that has the image registered, or -1.
  int KeptModelOf(image_t id) const {
    for (size_t m = 0; m < models_.size(); ++m) {
      if (models_[m]->reconstruction().IsRegistered(id)) return static_cast<int>(m);
    }
    return -1;
  }

  // Merges `model` and kept model m when their common points agree; on success `model`
  // holds the merged one (in the larger model's frame) and m is removed from the kept list.
  bool TryMerge(ModelPtr& model, size_t m) {
    Timer timer;
    ModelPtr& other = models_[m];
    const bool other_larger =
        other->reconstruction().NumRegImages() > model->reconstruction().NumRegImages();
    MapperState& dst = other_larger ? *other : *model;
    const MapperState& src = other_larger ? *model : *other;
    const ModelMergeReport merge = MergeModels(dst, src, random_);
    report_.seconds_merging += timer.ElapsedSeconds();
    spdlog::debug("merge attempt: {} of {} common points agree", merge.num_inliers,
                  merge.num_correspondences);
    if (!merge.success) {
      ++merge_failures_[other.get()];
      return false;
    }
    if (other_larger) model = std::move(other);
    models_.erase(models_.begin() + m);
    ++report_.num_models_merged;
    spdlog::info("mapper: merged two models ({} of {} common points agree): {} frames added, {} "
                 "points joined, {} points added",
                 merge.num_inliers, merge.num_correspondences, merge.num_images_added,
                 merge.num_points_joined, merge.num_points_added);
    model->GlobalRefinement(&report_);
    return true;
  }

  // Grows until nothing registers, merging with kept models it meets on the way and with
  // any kept model it shares tracks with at the end.
  void Grow(ModelPtr& model) {
    bool merged = false;
    while (true) {
      GrowUntilStalled(model, /*refined=*/merged);
      merged = false;
      for (size_t m = 0; m < models_.size() && !merged; ++m) merged = TryMerge(model, m);
      if (!merged) break;
    }
  }

  // `refined`: the model has just been refined (a merge), so a stall before the next
  // registration ends the growth without refining it again.
  void GrowUntilStalled(ModelPtr& model, bool refined) {
    if (!resume_growth_) growth_ = {{}, {}, model->reconstruction().NumRegImages(), {}, refined};
    resume_growth_ = false;
    while (true) {
      MaybeSaveCheckpoint(*model);
      Timer ranking;  // choosing the next frame is part of registering it
      const std::vector<std::tuple<bool, size_t, image_t>> order = RegistrationOrder(*model);
      report_.seconds_registration += ranking.ElapsedSeconds();
      bool registered = false;
      for (const auto& [near, count, image_id] : order) {
        if ((registered = TryRegister(model, image_id, count))) break;
      }
      if (registered) continue;  // TryRegister says whether the model was refined since
      if (growth_.refined_since_stall) break;
      // Stalled: refine everything and give every frame another try.
      model->GlobalRefinement(&report_);
      growth_.last_global_size = model->reconstruction().NumRegImages();
      growth_.failed_at.clear();
      growth_.refined_since_stall = true;
    }
  }

  // The frames to try next, best first: (near a registered frame in capture order, visible
  // tracks, id), for frames that see enough tracks, and more than when they last failed.
  std::vector<std::tuple<bool, size_t, image_t>> RegistrationOrder(MapperState& model) {
    std::vector<std::tuple<bool, size_t, image_t>> order;
    for (const auto& [id, count] : model.CountVisibleTracks()) {
      if (count < static_cast<size_t>(options_.abs_pose_min_num_inliers)) continue;
      const auto failed = growth_.failed_at.find(id);
      if (failed != growth_.failed_at.end() &&
          count < options_.registration_retry_growth * failed->second) {
        continue;
      }
      const int owner = KeptModelOf(id);
      if (owner >= 0 && merge_failures_[models_[owner].get()] >= kMaxMergeFailures) continue;
      order.push_back(
          {model.NearRegisteredFrame(id, options_.registration_capture_window), count, id});
    }
    std::sort(order.begin(), order.end(), std::greater<>());
    return order;
  }

  // Registers the frame (which sees `count` tracks) with its triangulation and local bundle,
  // then the hook, a growth bundle when one is due, and a merge where the frame belongs to a
  // kept model. False (the failure noted) when it does not register.
  bool TryRegister(ModelPtr& model, image_t image_id, size_t count) {
    auto& [failed_at, ever_failed, last_global_size, recent, refined_since_stall] = growth_;
    Reconstruction& rec = model->reconstruction();
    if (!model->RegisterImage(image_id, random_, &report_)) {
      failed_at[image_id] = count;
      ever_failed.insert(image_id);
      return false;
    }
    Timer tri_timer;
    model->TriangulateImage(image_id);
    report_.seconds_triangulation += tri_timer.ElapsedSeconds();
    if (!model->LocalBundle(image_id, &report_)) {
      rec.DeRegisterImage(image_id);
      failed_at[image_id] = count;
      ever_failed.insert(image_id);
      return false;
    }
    // Frames next to this one registered before it on a wrong pose go back to the growth
    // (a registered frame has no entry in failed_at).
    model->UndoPosesAgainstNeighbours(image_id, &report_);
    ++report_.num_registered;
    refined_since_stall = false;
    failed_at.erase(image_id);
    if (ever_failed.erase(image_id)) ++report_.num_registered_on_retry;
    if (options_.global_ba_window > 0) {
      recent.push_back(image_id);
      if (recent.size() > static_cast<size_t>(options_.global_ba_window)) {
        recent.erase(recent.begin());
      }
    }
    if (hook_ && hook_->AfterRegistration(*model, image_id, &report_)) {
      // The hook ended with a global refinement.
      last_global_size = rec.NumRegImages();
      failed_at.clear();
    } else if (RefinementDue(rec.NumRegImages(), last_global_size) && !GrowthEndsSoon(rec)) {
      if (options_.global_ba_window > 0 &&
          rec.NumRegImages() > static_cast<size_t>(options_.global_ba_window)) {
        model->WindowRefinement(recent, &report_);
      } else {
        model->GlobalRefinement(&report_);
      }
      last_global_size = rec.NumRegImages();
      failed_at.clear();
    }
    if (progress_) progress_(rec.NumRegImages(), input_.frames.size());
    // A frame of a kept model: the two models meet here.
    const int owner = KeptModelOf(image_id);
    if (owner >= 0 && merge_failures_[models_[owner].get()] < kMaxMergeFailures &&
        TryMerge(model, owner)) {
      last_global_size = model->reconstruction().NumRegImages();
      failed_at.clear();
      refined_since_stall = true;  // the merge refined the whole: a stall now needs no more
    }
    return true;
  }

  // Whether a model grown to `now` frames since its last refinement at `last` frames is due
  // another: by the growth fraction, and at least every half window of new frames.
  bool RefinementDue(size_t now, size_t last) const {
    double step = options_.global_ba_growth * static_cast<double>(last);
    if (options_.global_ba_window > 0) step = std::min(step, options_.global_ba_window / 2.0);
    return static_cast<double>(now) >= static_cast<double>(last) + step;
  }

  // Whether the frames not in `rec` are few enough that the global bundle ending its growth
  // (see global_ba_end_margin) can stand in for one the growth has just called for.
  bool GrowthEndsSoon(const Reconstruction& rec) const {
    const size_t in_model = rec.NumRegImages();  // never more than the input's frames
    const size_t left = input_.frames.size() - in_model;
    return static_cast<double>(left) <= options_.global_ba_end_margin * in_model;
  }

  // Merges kept models pairwise, largest first, until no two agree.
  void MergeKeptModels() {
    bool merged = true;
    while (merged && models_.size() > 1) {
      merged = false;
      std::sort(models_.begin(), models_.end(), [](const ModelPtr& a, const ModelPtr& b) {
        return a->reconstruction().NumRegImages() > b->reconstruction().NumRegImages();
      });
      for (size_t a = 0; a + 1 < models_.size() && !merged; ++a) {
        for (size_t b = a + 1; b < models_.size() && !merged; ++b) {
          ModelPtr model = std::move(models_[b]);
          models_.erase(models_.begin() + b);
          merged = TryMerge(model, a);
          // Back in its place, or (merged, a was removed) as the merged model.
          models_.insert(merged ? models_.end() : models_.begin() + b, std::move(model));
        }
      }
    }
  }

  // Where the growth of a model stands between two registrations.
  struct Growth {
    // Visible tracks of each frame when it last failed to register.
    std::unordered_map<image_t, size_t> failed_at;
    // Frames that failed at least once (for the report; failed_at is cleared on refinement).
    std::unordered_set<image_t> ever_failed;
    size_t last_global_size = 0;
    // The frames registered most recently, oldest first (at most global_ba_window).
    std::vector<image_t> recent;
    // The whole model was refined (at a stall, or by a merge) after its latest registration:
    // a stall now ends the growth.
    bool refined_since_stall = false;
  };

  const MapperInput& input_;
  const IncrementalMapperOptions& options_;
  MapperReport& report_;
  MapperProgress progress_;
  const MapperCheckpointing& checkpointing_;
  Random random_;
  MapperHook* hook_;
  std::vector<ModelPtr> starts_;
  std::vector<ModelPtr> models_;
  std::unordered_map<const MapperState*, int> merge_failures_;
  std::vector<char> tried_;
  Growth growth_;
  // The next GrowUntilStalled goes on from a restored growth_ instead of starting afresh.
  bool resume_growth_ = false;
  Timer last_checkpoint_;
};

}  // namespace

std::vector<Reconstruction> RunIncrementalMapper(const MapperInput& input,
                                                 const IncrementalMapperOptions& options,
                                                 MapperReport* report,
                                                 const MapperProgress& progress,
                                                 const MapperCheckpointing& checkpointing,
                                                 MapperHook* hook) {
  options.Check();
  MapperReport local;
  IncrementalMapper mapper(input, options, report ? report : &local, progress, checkpointing,
                           hook);
  return mapper.Run();
}

std::vector<Reconstruction> ExtendIncrementalModels(const MapperInput& input,
                                                    const IncrementalMapperOptions& options,
                                                    const std::vector<Reconstruction>& models,
                                                    MapperReport* report, MapperHook* hook) {
  options.Check();
  MapperReport local;
  IncrementalMapper mapper(input, options, report ? report : &local, {}, {}, hook);
  mapper.SetStartModels(models);
  return mapper.Run();
}

}  // namespace loopsfm

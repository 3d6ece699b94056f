#pragma once
// The global mapper's progress after each of its stages (global_mapper.h), so a mapping that
// was stopped goes on from the last stage done instead of from the start, to the same result
// (with one thread: Ceres' multi-threaded sums may round differently).
// pipeline/global_mapper_checkpoint.h writes it to a file and reads it back.

#include <functional>
#include <map>
#include <optional>
#include <vector>

#include <Eigen/Geometry>

#include "loopsfm/geometry/rigid3.h"
#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/scene/relative_rotation.h"
#include "loopsfm/sfm/global_mapper_report.h"
#include "loopsfm/sfm/mapper_report.h"

namespace loopsfm {

struct GlobalMapperCheckpoint {
  // One connected component of the cleaned view graph, and how far its mapping got.
  struct Component {
    // Stage 1: its edges.
    std::vector<RelativeRotation> edges;
    // Stage 2: its frames' rotations (cam_from_world).
    std::optional<std::map<image_t, Eigen::Quaterniond>> rotations;
    // Stage 3: the poses global positioning gave.
    std::optional<std::map<image_t, Rigid3d>> positioned;
    // Stage 4, after its loose bundles: the cameras and poses (no points).
    std::optional<MappedState> loose;
    // Stage 4 done: the model, or none (`done` without a model: a stage failed).
    bool done = false;
    std::optional<MappedState> model;
  };
  // The components to map, largest first (stage 1 is done once a checkpoint exists).
  std::vector<Component> components;
  // What the reports held then (a run that goes on from here starts the stage times of
  // GlobalMapperReport again from zero).
  GlobalMapperReport report;
  MapperReport mapper_report;
};

struct GlobalMapperCheckpointing {
  // Called with the progress after each stage of each component.
  std::function<void(const GlobalMapperCheckpoint&)> save;
  // Where to go on from; null: from the start.
  const GlobalMapperCheckpoint* resume = nullptr;
};

}  // namespace loopsfm

#pragma once
// The values that travel between ranks (and into checkpoints) as bytes: cameras, features,
// matches, two-view geometries, grey images, mapper inputs and mapped models.

#include <opencv2/core.hpp>

#include "loopsfm/scene/camera.h"
#include "loopsfm/scene/features.h"
#include "loopsfm/scene/reconstruction.h"
#include "loopsfm/scene/two_view_geometry.h"
#include "loopsfm/sfm/mapper_input.h"
#include "loopsfm/util/byte_io.h"

namespace loopsfm {

void PutRotation(ByteWriter& w, const Eigen::Quaterniond& rotation);
Eigen::Quaterniond GetRotation(ByteReader& r);

void PutPose(ByteWriter& w, const Rigid3d& pose);
Rigid3d GetPose(ByteReader& r);

void PutCamera(ByteWriter& w, const Camera& camera);
Camera GetCamera(ByteReader& r);

void PutFeatures(ByteWriter& w, const FeatureSet& features);
FeatureSet GetFeatures(ByteReader& r);

void PutGeometry(ByteWriter& w, const TwoViewGeometry& geometry);
TwoViewGeometry GetGeometry(ByteReader& r);

// An 8-bit grey image.
void PutGreyImage(ByteWriter& w, const cv::Mat& grey);
cv::Mat GetGreyImage(ByteReader& r);

// A mapping's registered frames and points (the models of checkpoints and segments).
void PutMappedState(ByteWriter& w, const MappedState& state);
MappedState GetMappedState(ByteReader& r);

void PutMapperInput(ByteWriter& w, const MapperInput& input);
MapperInput GetMapperInput(ByteReader& r);

}  // namespace loopsfm

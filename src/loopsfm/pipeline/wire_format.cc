#include "loopsfm/pipeline/wire_format.h"

namespace loopsfm {
void PutRotation(ByteWriter& w, const Eigen::Quaterniond& rotation) {
  w.PutBytes(rotation.coeffs().data(), 4 * sizeof(double));
}

Eigen::Quaterniond GetRotation(ByteReader& r) {
  Eigen::Quaterniond rotation;
  r.GetBytes(rotation.coeffs().data(), 4 * sizeof(double));
  return rotation;
}

void PutPose(ByteWriter& w, const Rigid3d& pose) {
  PutRotation(w, pose.rotation);
  w.PutBytes(pose.translation.data(), 3 * sizeof(double));
}

Rigid3d GetPose(ByteReader& r) {
  Rigid3d pose;
  pose.rotation = GetRotation(r);
  r.GetBytes(pose.translation.data(), 3 * sizeof(double));
  return pose;
}

void PutCamera(ByteWriter& w, const Camera& camera) {
  w.Put<uint32_t>(camera.camera_id);
  w.Put<int32_t>(static_cast<int32_t>(camera.model_id));
  w.Put<int32_t>(camera.width);
  w.Put<int32_t>(camera.height);
  w.Put<uint8_t>(camera.has_prior_focal_length ? 1 : 0);
  w.PutVector(camera.params);
}

Camera GetCamera(ByteReader& r) {
  Camera camera;
  camera.camera_id = r.Get<uint32_t>();
  camera.model_id = static_cast<CameraModelId>(r.Get<int32_t>());
  camera.width = r.Get<int32_t>();
  camera.height = r.Get<int32_t>();
  camera.has_prior_focal_length = r.Get<uint8_t>() != 0;
  camera.params = r.GetVector<double>();
  return camera;
}

void PutFeatures(ByteWriter& w, const FeatureSet& features) {
  w.PutVector(features.keypoints);
  w.PutBytes(features.descriptors.data(), features.descriptors.size());
}

FeatureSet GetFeatures(ByteReader& r) {
  FeatureSet features;
  features.keypoints = r.GetVector<FeatureKeypoint>();
  features.descriptors.resize(static_cast<Eigen::Index>(features.keypoints.size()),
                              kDescriptorDim);
  r.GetBytes(features.descriptors.data(), features.descriptors.size());
  return features;
}

void PutGeometry(ByteWriter& w, const TwoViewGeometry& geometry) {
  w.Put<int32_t>(geometry.config);
  w.PutBytes(geometry.E.data(), 9 * sizeof(double));
  w.PutBytes(geometry.F.data(), 9 * sizeof(double));
  w.PutBytes(geometry.H.data(), 9 * sizeof(double));
  PutPose(w, geometry.cam2_from_cam1);
  w.PutVector(geometry.inlier_matches);
}

TwoViewGeometry GetGeometry(ByteReader& r) {
  TwoViewGeometry geometry;
  geometry.config = r.Get<int32_t>();
  r.GetBytes(geometry.E.data(), 9 * sizeof(double));
  r.GetBytes(geometry.F.data(), 9 * sizeof(double));
  r.GetBytes(geometry.H.data(), 9 * sizeof(double));
  geometry.cam2_from_cam1 = GetPose(r);
  geometry.inlier_matches = r.GetVector<FeatureMatch>();
  return geometry;
}

void PutGreyImage(ByteWriter& w, const cv::Mat& grey) {
  CV_Assert(grey.type() == CV_8UC1);
  w.Put<int32_t>(grey.rows);
  w.Put<int32_t>(grey.cols);
  for (int y = 0; y < grey.rows; ++y) w.PutBytes(grey.ptr<uint8_t>(y), size_t(grey.cols));
}

cv::Mat GetGreyImage(ByteReader& r) {
  const int rows = r.Get<int32_t>();
  const int cols = r.Get<int32_t>();
  if (rows < 0 || cols < 0) throw InputError("it has an image of negative size");
  cv::Mat grey(rows, cols, CV_8UC1);
  r.GetBytes(grey.data, grey.total());
  return grey;
}


void PutMappedState(ByteWriter& w, const MappedState& state) {
  w.Put<uint64_t>(state.cameras.size());
  for (const Camera& camera : state.cameras) PutCamera(w, camera);
  w.Put<uint64_t>(state.registered.size());
  for (const MappedState::RegisteredImage& image : state.registered) {
    w.Put<uint32_t>(image.image_id);
    PutPose(w, image.cam_from_world);
  }
  w.Put<uint64_t>(state.next_point3D_id);
  w.Put<uint64_t>(state.points.size());
  for (const MappedState::SavedPoint& point : state.points) {
    w.Put<uint64_t>(point.point3D_id);
    w.PutBytes(point.xyz.data(), 3 * sizeof(double));
    w.PutBytes(point.color.data(), 3);
    w.Put<double>(point.error);
    w.Put<uint64_t>(point.track.size());
    for (const TrackElement& el : point.track) {
      w.Put<uint32_t>(el.image_id);
      w.Put<uint32_t>(el.point2D_idx);
    }
  }
}

MappedState GetMappedState(ByteReader& r) {
  MappedState state;
  state.cameras.resize(r.GetCount(25));
  for (Camera& camera : state.cameras) camera = GetCamera(r);
  state.registered.resize(r.GetCount(4 + 7 * sizeof(double)));
  for (MappedState::RegisteredImage& image : state.registered) {
    image.image_id = r.Get<uint32_t>();
    image.cam_from_world = GetPose(r);
  }
  state.next_point3D_id = r.Get<uint64_t>();
  state.points.resize(r.GetCount(8 + 3 * sizeof(double) + 3 + sizeof(double) + 8));
  for (MappedState::SavedPoint& point : state.points) {
    point.point3D_id = r.Get<uint64_t>();
    r.GetBytes(point.xyz.data(), 3 * sizeof(double));
    r.GetBytes(point.color.data(), 3);
    point.error = r.Get<double>();
    point.track.resize(r.GetCount(8));
    for (TrackElement& el : point.track) {
      el.image_id = r.Get<uint32_t>();
      el.point2D_idx = r.Get<uint32_t>();
    }
  }
  return state;
}


void PutMapperInput(ByteWriter& w, const MapperInput& input) {
  w.Put<uint64_t>(input.cameras.size());
  for (const Camera& camera : input.cameras) PutCamera(w, camera);
  w.Put<uint64_t>(input.frames.size());
  for (const MapperFrame& frame : input.frames) {
    w.Put(frame.image_id);
    w.Put(frame.camera_id);
    w.PutString(frame.name);
    w.Put<uint64_t>(frame.points2D.size());
    w.PutBytes(frame.points2D.data(), frame.points2D.size() * sizeof(Eigen::Vector2d));
  }
  w.Put<uint64_t>(input.pairs.size());
  for (const MapperPair& pair : input.pairs) {
    w.Put(pair.pair);
    PutGeometry(w, pair.geometry);
  }
  w.Put<uint64_t>(input.tracks.size());
  for (const Track& track : input.tracks) w.PutVector(track.elements);
}

MapperInput GetMapperInput(ByteReader& r) {
  MapperInput input;
  input.cameras.resize(r.GetCount(25));
  for (Camera& camera : input.cameras) camera = GetCamera(r);
  input.frames.resize(r.GetCount(16));
  for (MapperFrame& frame : input.frames) {
    frame.image_id = r.Get<image_t>();
    frame.camera_id = r.Get<camera_t>();
    frame.name = r.GetString();
    frame.points2D.resize(r.GetCount(sizeof(Eigen::Vector2d)));
    r.GetBytes(frame.points2D.data(), frame.points2D.size() * sizeof(Eigen::Vector2d));
  }
  input.pairs.resize(r.GetCount(8));
  for (MapperPair& pair : input.pairs) {
    pair.pair = r.Get<ImagePair>();
    pair.geometry = GetGeometry(r);
  }
  input.tracks.resize(r.GetCount(8));
  for (Track& track : input.tracks) track.elements = r.GetVector<TrackElement>();
  return input;
}

}  // namespace loopsfm

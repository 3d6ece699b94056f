#pragma once
// A frame registered in the database (COLMAP's "image" row) before reconstruction.

#include <string>

#include "loopsfm/util/types.h"

namespace loopsfm {

struct Frame {
  image_t image_id = kInvalidImageId;
  camera_t camera_id = kInvalidCameraId;
  // "frame_%06d.png" for video frames (index in the source video), the file name for
  // image folders. Unique within a database.
  std::string name;
};

}  // namespace loopsfm

#include "loopsfm/sfm/global_view_graph.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "loopsfm/matching/relative_pose_refinement.h"
#include "loopsfm/sfm/sfm_test_problem.h"

namespace loopsfm {
namespace {

using testing::MakeMapperProblem;
using testing::MapperProblem;
using testing::MapperProblemOptions;

constexpr double kDeg = M_PI / 180.0;

// Frames with ids `ids`, in capture order (no keypoints).
MapperInput FramesInOrder(const std::vector<image_t>& ids) {
  MapperInput input;
  input.cameras = {testing::TestCamera()};
  for (const image_t id : ids) {
    MapperFrame frame;
    frame.image_id = id;
    frame.camera_id = input.cameras[0].camera_id;
    input.frames.push_back(frame);
  }
  return input;
}

// A pair of the given configuration with `num_inliers` inlier matches (config kCalibrated and
// one inlier: a verified pair).
MapperPair PairOf(image_t id1, image_t id2, int config = TwoViewGeometry::kCalibrated,
                  int num_inliers = 1) {
  MapperPair pair;
  pair.pair = ImagePair(id1, id2);
  pair.geometry.config = config;
  for (int k = 0; k < num_inliers; ++k) {
    pair.geometry.inlier_matches.push_back({static_cast<point2D_t>(k), static_cast<point2D_t>(k)});
  }
  return pair;
}

TEST(GlobalViewGraph, FramesAllPairedWithTheirNeighboursAreOneRun) {
  MapperInput input = FramesInOrder({1, 2, 3, 4, 5});
  for (image_t id = 1; id < 5; ++id) input.pairs.push_back(PairOf(id, id + 1));
  EXPECT_EQ(RunsBetweenCuts(input), std::vector<int>({0, 0, 0, 0, 0}));
}

TEST(GlobalViewGraph, ARunStartsWhereTwoFramesNextInCaptureOrderShareNoVerifiedPair) {
  MapperInput input = FramesInOrder({1, 2, 3, 4, 5, 6, 7});
  // Cuts between 2 and 3 and between 4 and 5; the pair (2, 4) spans the first cut but joins
  // no two frames next in capture order.
  for (const auto& [a, b] : {std::pair(1, 2), std::pair(3, 4), std::pair(5, 6), std::pair(6, 7),
                             std::pair(2, 4)}) {
    input.pairs.push_back(PairOf(a, b));
  }
  EXPECT_EQ(RunsBetweenCuts(input), std::vector<int>({0, 0, 1, 1, 2, 2, 2}));

  // An unverified pair between 6 and 7 (rejected, or without inliers) does not join them.
  input.pairs[3] = PairOf(6, 7, TwoViewGeometry::kDegenerate);
  EXPECT_EQ(RunsBetweenCuts(input), std::vector<int>({0, 0, 1, 1, 2, 2, 3}));
  input.pairs[3] = PairOf(6, 7, TwoViewGeometry::kCalibrated, /*num_inliers=*/0);
  EXPECT_EQ(RunsBetweenCuts(input), std::vector<int>({0, 0, 1, 1, 2, 2, 3}));
}

TEST(GlobalViewGraph, RunsFollowCaptureOrderWhateverTheIdOrder) {
  // Capture order 9, 4, 7, 2: every pair's ids are in the opposite order to capture order
  // somewhere. (4, 9) joins the first two frames, (7, 4) the next two, stored against the
  // ImagePair convention; nothing joins 7 and 2.
  MapperInput input = FramesInOrder({9, 4, 7, 2});
  input.pairs.push_back(PairOf(9, 4));
  MapperPair backwards = PairOf(4, 7);
  backwards.pair.image_id1 = 7;
  backwards.pair.image_id2 = 4;
  input.pairs.push_back(backwards);
  input.pairs.push_back(PairOf(2, 9));
  EXPECT_EQ(RunsBetweenCuts(input), std::vector<int>({0, 0, 0, 1}));
}

// The pair (i, j), i < j, of p's frames.
MapperPair& PairOfFrames(MapperProblem* p, int i, int j) {
  const ImagePair ids(p->input.frames[i].image_id, p->input.frames[j].image_id);
  const auto it = std::find_if(p->input.pairs.begin(), p->input.pairs.end(),
                               [&](const MapperPair& pair) { return pair.pair == ids; });
  EXPECT_NE(it, p->input.pairs.end());
  return *it;
}

// The true cam_j_from_cam_i of p's frames i < j, with a unit translation.
Rigid3d TruePose(const MapperProblem& p, int i, int j) {
  Rigid3d pose = p.cam_from_world[j] * p.cam_from_world[i].Inverse();
  pose.translation.normalize();
  return pose;
}

// `pose` with its rotation turned by 20 degrees about `axis`: a candidate that is wrong well
// beyond the view graph's 5 degree bound.
Rigid3d Wrong(const Rigid3d& pose, const Eigen::Vector3d& axis) {
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(20.0 * kDeg, axis.normalized())) *
                     pose.rotation,
                 pose.translation);
}

// Makes the pair of p's frames i < j planar: its stored pose (the homography's candidate)
// becomes h_pose, its F that of f_pose (cam_j_from_cam_i), and its inliers 48 new keypoints of
// frames i and j, projections of points 8-12 m in front of frame i under f_pose (without
// noise), so that EssentialPoseOfPair gives f_pose. H stays zero: EssentialPoseOfPair then
// takes E's pose as it is.
void MakePlanar(MapperProblem* p, int i, int j, const Rigid3d& f_pose, const Rigid3d& h_pose) {
  const Camera& camera = p->input.cameras[0];
  std::vector<Eigen::Vector2d>& points1 = p->input.frames[i].points2D;
  std::vector<Eigen::Vector2d>& points2 = p->input.frames[j].points2D;
  TwoViewGeometry& geometry = PairOfFrames(p, i, j).geometry;
  geometry.config = TwoViewGeometry::kPlanar;
  geometry.cam2_from_cam1 = h_pose;
  geometry.inlier_matches.clear();
  for (int u = 0; u < 8; ++u) {
    for (int v = 0; v < 6; ++v) {
      const Eigen::Vector2d pixel(40.0 + 80.0 * u, 40.0 + 80.0 * v);
      const double depth = 8.0 + (7 * u + 3 * v) % 5;
      const Eigen::Vector3d point = depth * camera.CamFromImg(pixel).homogeneous();
      geometry.inlier_matches.push_back({static_cast<point2D_t>(points1.size()),
                                         static_cast<point2D_t>(points2.size())});
      points1.push_back(pixel);
      points2.push_back(camera.ImgFromCam(f_pose * point));
    }
  }
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();  // pinhole: fx, fy, cx, cy
  K << camera.params[0], 0, camera.params[2], 0, camera.params[1], camera.params[3], 0, 0, 1;
  const Eigen::Matrix3d K_inv = K.inverse();
  geometry.F = K_inv.transpose() * EssentialFromPose(f_pose) * K_inv;
}

// A walk of `num_frames` frames, each paired with the next `overlap`, true poses.
MapperProblem Walk(int num_frames, int overlap) {
  MapperProblemOptions options;
  options.num_frames = num_frames;
  options.num_points = 600;
  options.overlap = overlap;
  return MakeMapperProblem(options);
}

void ExpectPose(const Rigid3d& actual, const Rigid3d& expected) {
  EXPECT_LT(actual.rotation.angularDistance(expected.rotation), 1e-4);
  EXPECT_LT((actual.translation - expected.translation).norm(), 1e-4);
}

// The PairPose of p's frames i < j.
const PairPose& PoseOfFrames(const std::vector<PairPose>& poses, const MapperProblem& p, int i,
                             int j) {
  const ImagePair ids(p.input.frames[i].image_id, p.input.frames[j].image_id);
  const auto it = std::find_if(poses.begin(), poses.end(), [&](const PairPose& pose) {
    return ImagePair(pose.image_id1, pose.image_id2) == ids;
  });
  EXPECT_NE(it, poses.end());
  return *it;
}

// Report counters left over from an earlier run, which PairPoses must reset.
GlobalMapperReport StaleReport() {
  GlobalMapperReport report;
  report.num_planar_pairs = report.num_planar_poses_from_homography = 7;
  return report;
}

// A walk of 6 frames, each paired with the next 3 at its true pose, whose pair of frames 1 and
// 3 is made planar, with the true pose as F's (f_is_right) or as the homography's, and one 20
// degrees off as the other. Frames 1 and 3 share triangles with frames 0, 2 and 4.
struct PlanarWalk {
  MapperProblem p;
  Rigid3d truth, wrong;
};

PlanarWalk WalkWithPlanarPair(bool f_is_right) {
  PlanarWalk walk;
  walk.p = Walk(6, 3);
  walk.truth = TruePose(walk.p, 1, 3);
  walk.wrong = Wrong(walk.truth, Eigen::Vector3d(1, 0, 0));
  if (f_is_right) {
    MakePlanar(&walk.p, 1, 3, walk.truth, walk.wrong);
  } else {
    MakePlanar(&walk.p, 1, 3, walk.wrong, walk.truth);
  }
  return walk;
}

// Expects PairPoses of p to give the pair of frames 1 and 3 the pose `expected`, and to
// count one planar pair, and from_homography of them that took the homography's pose. The
// report starts with counts left over from an earlier run, which PairPoses must reset.
void ExpectPlanarPairPose(const MapperProblem& p, const GlobalMapperOptions& options,
                          const Rigid3d& expected, int from_homography) {
  GlobalMapperReport report = StaleReport();
  const std::vector<PairPose> poses = PairPoses(p.input, FrameLookup(p.input), options, &report);
  ASSERT_EQ(poses.size(), p.input.pairs.size());
  ExpectPose(PoseOfFrames(poses, p, 1, 3).cam2_from_cam1, expected);
  EXPECT_TRUE(PoseOfFrames(poses, p, 1, 3).has_translation);
  EXPECT_EQ(report.num_planar_pairs, 1);
  EXPECT_EQ(report.num_planar_poses_from_homography, from_homography);
}

TEST(GlobalViewGraph, PlanarPairTakesTheEssentialPoseWhereTheTrianglesAgreeWithIt) {
  const PlanarWalk walk = WalkWithPlanarPair(/*f_is_right=*/true);
  ExpectPlanarPairPose(walk.p, GlobalMapperOptions(), walk.truth, 0);
}

TEST(GlobalViewGraph, PlanarPairTakesTheHomographyPoseWhereTheTrianglesAgreeWithIt) {
  const PlanarWalk walk = WalkWithPlanarPair(/*f_is_right=*/false);
  ExpectPlanarPairPose(walk.p, GlobalMapperOptions(), walk.truth, 1);

  // Without the vote, F's pose, wrong as it is.
  GlobalMapperOptions options;
  options.planar_pose_by_triangles = false;
  ExpectPlanarPairPose(walk.p, options, walk.wrong, 0);
}

TEST(GlobalViewGraph, PlanarPairInNoTriangleKeepsTheEssentialPose) {
  PlanarWalk walk = WalkWithPlanarPair(/*f_is_right=*/false);
  // Only the pairs (0, 1), (1, 3) and (3, 4) left: a chain, no triangle through (1, 3).
  const auto ids = [&](int i, int j) {
    return ImagePair(walk.p.input.frames[i].image_id, walk.p.input.frames[j].image_id);
  };
  std::erase_if(walk.p.input.pairs, [&](const MapperPair& pair) {
    return pair.pair != ids(0, 1) && pair.pair != ids(1, 3) && pair.pair != ids(3, 4);
  });
  ASSERT_EQ(walk.p.input.pairs.size(), 3u);
  ExpectPlanarPairPose(walk.p, GlobalMapperOptions(), walk.wrong, 0);
}

TEST(GlobalViewGraph, TrianglesVoteWithEitherCandidateOfTheirOtherPlanarPairs) {
  // The triangle of frames 0, 1, 2 with two planar pairs, each with a wrong F (turned about
  // different axes, so the two wrong ones do not chain into each other's) and a right
  // homography: only the right candidate of the other planar pair closes the triangle. With
  // (0, 1) and (1, 2) planar, each finds the other's candidates against its stored order;
  // with (0, 1) and (0, 2), in it.
  for (const int planar : {1, 0}) {
    SCOPED_TRACE(planar == 1 ? "(0, 1) and (1, 2)" : "(0, 1) and (0, 2)");
    MapperProblem p = Walk(3, 2);
    ASSERT_EQ(p.input.pairs.size(), 3u);
    const Rigid3d truth01 = TruePose(p, 0, 1), truth2 = TruePose(p, planar, 2);
    MakePlanar(&p, 0, 1, Wrong(truth01, Eigen::Vector3d(1, 0, 0)), truth01);
    MakePlanar(&p, planar, 2, Wrong(truth2, Eigen::Vector3d(0, 1, 0)), truth2);
    GlobalMapperReport report;
    const std::vector<PairPose> poses = PairPoses(
        p.input, FrameLookup(p.input), GlobalMapperOptions(), &report);
    ExpectPose(PoseOfFrames(poses, p, 0, 1).cam2_from_cam1, truth01);
    ExpectPose(PoseOfFrames(poses, p, planar, 2).cam2_from_cam1, truth2);
    EXPECT_EQ(report.num_planar_pairs, 2);
    EXPECT_EQ(report.num_planar_poses_from_homography, 2);
  }
}

TEST(GlobalViewGraph, PairPosesKeepVerifiedPairsWithAPoseInOrder) {
  MapperInput input = FramesInOrder({1, 2, 3, 4, 5, 6, 7});
  const Rigid3d pose(Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitY())),
                     Eigen::Vector3d(1, 0, 0));
  // A pure rotation that was left a translation: its direction means nothing.
  input.pairs.push_back(PairOf(1, 2, TwoViewGeometry::kPanoramic, 30));
  input.pairs.push_back(PairOf(2, 3, TwoViewGeometry::kDegenerate, 30));
  input.pairs.push_back(PairOf(3, 4, TwoViewGeometry::kCalibrated, 0));
  input.pairs.push_back(PairOf(4, 5, TwoViewGeometry::kWatermark, 30));
  input.pairs.push_back(PairOf(5, 6, TwoViewGeometry::kUncalibrated, 40));
  // Planar without an F: the homography's pose, the only candidate.
  input.pairs.push_back(PairOf(6, 7, TwoViewGeometry::kPlanar, 50));
  for (MapperPair& pair : input.pairs) pair.geometry.cam2_from_cam1 = pose;
  GlobalMapperReport report = StaleReport();
  const std::vector<PairPose> poses = PairPoses(
      input, FrameLookup(input), GlobalMapperOptions(), &report);
  ASSERT_EQ(poses.size(), 3u);
  EXPECT_EQ(poses[0].image_id1, 1u);
  EXPECT_EQ(poses[0].image_id2, 2u);
  EXPECT_FALSE(poses[0].has_translation);
  EXPECT_EQ(poses[0].weight, 30.0);
  EXPECT_EQ(poses[1].image_id1, 5u);
  EXPECT_TRUE(poses[1].has_translation);
  EXPECT_EQ(poses[1].weight, 40.0);
  EXPECT_EQ(poses[2].image_id1, 6u);
  EXPECT_TRUE(poses[2].has_translation);
  for (const PairPose& pair_pose : poses) ExpectPose(pair_pose.cam2_from_cam1, pose);
  EXPECT_EQ(report.num_planar_pairs, 0);
  EXPECT_EQ(report.num_planar_poses_from_homography, 0);
}

}  // namespace
}  // namespace loopsfm

// msg::Keyframe to and from the tracker's Keyframe: the one place the visual SLAM actors read and
// write keyframe messages, and the checks every consumer applies before using one.
#pragma once

#include <tessera/msg/keyframe.capnp.h>
#include <tessera/geometry/pose3.hpp>
#include <tessera/visual_slam/camera.hpp>
#include <tessera/visual_slam/tracker.hpp>

#include <opencv2/core.hpp>

#include <string>

namespace tessera::visual_slam {

/// Everything of a keyframe message besides the header.
struct KeyframeContent {
  const Keyframe* keyframe = nullptr;  ///< features, points, pose (camera-to-world)
  PinholeCamera camera;
  cv::Mat depth;  ///< CV_16UC1 in `camera`, full resolution; empty = none
  double depth_scale = 1000;
  int depth_step = 4;  ///< every depth_step-th pixel and row is kept
  int tracking_inliers = 0;
};

/// Fills `b` (header left to the caller). Descriptors of type CV_8U are "u8", CV_32F "f32".
void writeKeyframe(msg::Keyframe::Builder b, const KeyframeContent& k);

/// Bytes a Loan needs for this keyframe (keeps the bulk in one segment).
std::size_t keyframeSizeHint(const KeyframeContent& k);

/// "" when the message can be used, else what is wrong: no keypoints or descriptors, counts of
/// keypoints / points / descriptor rows that disagree, descriptor bytes that do not match
/// rows x bytes per row, an unknown descriptor type, a non-finite pose or point, bad
/// intrinsics, or a depth block whose size does not match its width and height.
std::string keyframeMessageError(msg::Keyframe::Reader m);

/// The message's pose (quaternion renormalised).
Pose3 keyframePose(msg::Keyframe::Reader m);

}  // namespace tessera::visual_slam

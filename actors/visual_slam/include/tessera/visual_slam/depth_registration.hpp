// Depth registered to a colour camera that is not the depth camera
// (docs/algorithms.md#rgb-d-visual-odometry).
//
// Features come from the colour image, their 3D points from the depth image, so both must see
// the same pixel. TUM's Kinect driver registered them; 7-Scenes did not: its depth is in the
// depth (IR) camera (585 px focal length, as the dataset states) and its colour image in the
// colour camera, a few centimetres to the side with a wider field of view. We do what the
// dataset's users do (e.g. the 7-Scenes set-up of the DSAC*/ACE relocalisers): re-project the
// depth into the colour camera with a standard Kinect calibration, track the colour camera, and
// move the result back to the depth camera (the frame of the dataset's poses).
//
// Units: depth values keep their scale (e.g. millimetres); poses in metres.
#pragma once

#include <tessera/visual_slam/camera.hpp>

#include <opencv2/core.hpp>

#include <Eigen/Geometry>

#include <optional>
#include <string>

namespace tessera::visual_slam {

struct ColorCalibration {
  PinholeCamera color;                 ///< the colour camera's intrinsics
  Eigen::Isometry3d color_from_depth;  ///< maps depth-camera points into the colour camera
  std::string source;
};

/// The calibration 7-Scenes' users apply: colour focal length 525 px, principal point at the
/// image centre (320, 240), and the depth-to-colour transform of the LIRIS Kinect calibration
/// (projet.liris.cnrs.fr/voir/activities-dataset/kinect-calibration.html): about 2.6 cm along
/// x and rotations below 0.5 degrees. An approximation: 7-Scenes publishes no calibration.
ColorCalibration sevenScenesColorCalibration();

/// The one place that decides whether depth is registered: the calibration to apply when colour
/// and depth are not registered and `register_depth` asks for it (7-Scenes' usual one,
/// sevenScenesColorCalibration()), else none (track the depth image's camera as given).
std::optional<ColorCalibration> depthRegistration(bool color_registered, bool register_depth);

/// `depth` (CV_16UC1, in depth_camera) re-projected into calib.color: each reading is
/// back-projected, moved by color_from_depth and projected, the nearest reading winning where
/// several land on one pixel (OpenCV's rgbd::registerDepth); pixels nothing lands on are 0.
/// Throws std::invalid_argument for a wrong type or size.
cv::Mat registerDepth(const cv::Mat& depth, const PinholeCamera& depth_camera,
                      const ColorCalibration& calib);

}  // namespace tessera::visual_slam

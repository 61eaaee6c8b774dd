// Rendered images of an environment ceiling camera (camera_network.hpp): what the camera sees of
// the floor and of a printed ArUco marker on the robot, for testing a real marker detector.
//
// Pixels. The camera's homography() maps floor points to pixel coordinates in OpenCV's
// convention: integer (u, v) = (column, row) is the centre of that pixel, so the image spans
// [-0.5, W - 0.5) x [-0.5, H - 0.5). The images are CV_8UC1, intrinsics().width_px x height_px.
//
// Floor. A deterministic mid-grey texture defined on the floor (world frame, metres), the same in
// every frame and every camera for a given floor_texture_seed: smooth noise at two scales plus
// tiles of 0.32 m with slightly different brightness; it repeats every 10.24 m. Pixels whose ray
// does not meet the floor (past the horizon) are uniform grey.
//
// Marker. A DICT_4X4_50 ArUco marker of side marker_size_m (the black square, border included)
// with a white quiet zone of one cell around it, lying flat in the marker plane, centred at
// marker_pose's position. Marker frame: x along marker_pose.theta (the robot's heading), y to its
// left. The marker image's top edge faces +x (forward), so its corners in ArUco's order are
//   0 top-left = front-left (+s/2, +s/2), 1 top-right = front-right (+s/2, -s/2),
//   2 bottom-right = rear-right (-s/2, -s/2), 3 bottom-left = rear-left (-s/2, +s/2)
// in the marker frame (s = marker_size_m), as markerCornerPixels() returns them. The marker is
// area-sampled (4 x 4 supersampling), then the whole image is Gaussian-blurred (blur_px) and gets
// additive Gaussian noise (noise_std grey levels), saturated to 0..255. A marker with any
// corner behind the camera is not drawn; one outside the image is simply not visible.
//
// Deterministic given the options and the std::mt19937_64 passed in (which only the noise draws
// from: one value per frame). The floor texture is made once per seed and kept (thread-safe).
#pragma once

#include <tessera/sim/camera_network.hpp>
#include <tessera/sim/config_check.hpp>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <array>
#include <optional>
#include <random>

namespace tessera::sim {

struct CameraImageOptions {
  double marker_size_m = 0.2;  ///< side of the black marker square [m]
  int marker_id = 7;           ///< DICT_4X4_50 id, [0, 50)
  double blur_px = 1.0;        ///< Gaussian blur sigma [px]; 0 = none
  double noise_std = 2.0;      ///< additive Gaussian noise std [grey levels]
  int floor_texture_seed = 1;  ///< selects the floor texture

  template <class V>
  void visit(V& v) {
    v("marker_size_m", marker_size_m, "side of the black marker square [m]");
    v("marker_id", marker_id, "ArUco id of the marker (DICT_4X4_50), 0..49");
    v("blur_px", blur_px, "Gaussian blur sigma of the optics [px], 0 for none");
    v("noise_std", noise_std, "additive Gaussian pixel noise std [grey levels]");
    v("floor_texture_seed", floor_texture_seed, "seed of the procedural floor texture");
  }
  /// Finds the first bad field (keys as in visit()).
  ConfigCheck check() const;
  /// Throws std::invalid_argument naming the first bad field.
  void validate() const { check().throwIfBad("camera image"); }
};

/// The camera's CV_8UC1 image of the floor with the marker at `marker_pose` (world frame, [m],
/// [rad]). Throws std::invalid_argument for bad options.
cv::Mat renderCameraImage(const EnvironmentCamera& camera, const Pose2& marker_pose,
                          const CameraImageOptions& options, std::mt19937_64& rng);

/// The true pixels of the marker's four corners in ArUco's order (see above), or nullopt when a
/// corner is behind the camera. The pixels may lie outside the image.
std::optional<std::array<Eigen::Vector2d, 4>> markerCornerPixels(const EnvironmentCamera& camera,
                                                                 const Pose2& marker_pose,
                                                                 double marker_size_m);

}  // namespace tessera::sim

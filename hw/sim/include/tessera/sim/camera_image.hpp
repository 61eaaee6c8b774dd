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
//
// Cost (640 x 480): renderCameraImage ~6.5 ms, half of it the floor's per-pixel lookup. A
// CameraImageRenderer keeps one camera's floor and reuses its buffers, so a frame costs the
// marker, blur and noise only (~3 ms, mostly the noise); its images are renderCameraImage's,
// pixel for pixel, for the same generator state.
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

/// One camera's images, rendered as renderCameraImage does but with the camera's floor made once
/// (in the constructor) and the working buffers kept between frames. Not thread-safe (one
/// renderer per camera and thread); copies are independent.
class CameraImageRenderer {
 public:
  /// Throws std::invalid_argument for bad options.
  CameraImageRenderer(const EnvironmentCamera& camera, const CameraImageOptions& options);

  /// renderCameraImage(camera(), marker_pose, options(), rng), written into `out`: a CV_8UC1
  /// image of the camera's size is written in place (it may wrap memory it does not own, such as
  /// a message's pixel buffer), anything else is reallocated. Throws std::invalid_argument for a
  /// non-finite pose.
  void render(const Pose2& marker_pose, std::mt19937_64& rng, cv::Mat& out);

  const EnvironmentCamera& camera() const { return camera_; }
  const CameraImageOptions& options() const { return options_; }

 private:
  EnvironmentCamera camera_;
  CameraImageOptions options_;
  cv::Mat floor_;         ///< CV_32F, the floor as the camera sees it, before blur and noise
  cv::Mat work_, noise_;  ///< CV_32F buffers reused between frames
};

/// The true pixels of the marker's four corners in ArUco's order (see above), or nullopt when a
/// corner is behind the camera. The pixels may lie outside the image.
std::optional<std::array<Eigen::Vector2d, 4>> markerCornerPixels(const EnvironmentCamera& camera,
                                                                 const Pose2& marker_pose,
                                                                 double marker_size_m);

}  // namespace tessera::sim

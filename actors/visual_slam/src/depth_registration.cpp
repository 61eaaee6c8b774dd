// registerDepth() through OpenCV contrib's rgbd::registerDepth, and the 7-Scenes calibration.
#include <tessera/visual_slam/depth_registration.hpp>

#include <opencv2/rgbd/depth.hpp>

#include <stdexcept>

namespace tessera::visual_slam {

ColorCalibration sevenScenesColorCalibration() {
  ColorCalibration c;
  c.color = {525.0, 525.0, 320.0, 240.0, 640, 480};
  Eigen::Matrix4d m;
  // Row-major 4x4, depth camera -> colour camera, from the LIRIS Kinect calibration.
  m << 9.9996518012567637e-01, 2.6765126468950343e-03, -7.9041012313000904e-03,
      -2.5558943178152542e-02,  //
      -2.7409311281316700e-03, 9.9996302803027592e-01, -8.1504520778013286e-03,
      1.0109636268061706e-04,  //
      7.8819942130445332e-03, 8.1718328771890631e-03, 9.9993554558014031e-01,
      2.0318321729487039e-03,  //
      0, 0, 0, 1;
  c.color_from_depth.matrix() = m;
  // The printed rotation is orthonormal to ~1e-8; make it exact.
  const Eigen::Quaterniond q(c.color_from_depth.rotation());
  c.color_from_depth.linear() = q.normalized().toRotationMatrix();
  c.source = "7-Scenes users' Kinect calibration (colour f = 525 px; LIRIS depth-to-colour)";
  return c;
}

std::optional<ColorCalibration> depthRegistration(bool color_registered, bool register_depth) {
  if (color_registered || !register_depth) return std::nullopt;
  return sevenScenesColorCalibration();
}

cv::Mat registerDepth(const cv::Mat& depth, const PinholeCamera& depth_camera,
                      const ColorCalibration& calib) {
  depth_camera.validate();
  calib.color.validate();
  if (depth.type() != CV_16UC1) throw std::invalid_argument("registerDepth: depth is not CV_16UC1");
  if (depth.cols != depth_camera.width || depth.rows != depth_camera.height)
    throw std::invalid_argument("registerDepth: depth size differs from the depth camera's");
  const cv::Matx33d kd(depth_camera.fx, 0, depth_camera.cx, 0, depth_camera.fy, depth_camera.cy, 0,
                       0, 1);
  const auto& c = calib.color;
  const cv::Matx33d kc(c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
  cv::Matx44d rt;
  for (int r = 0; r < 4; ++r)
    for (int k = 0; k < 4; ++k) rt(r, k) = calib.color_from_depth.matrix()(r, k);
  cv::Mat out;
  cv::rgbd::registerDepth(kd, kc, cv::noArray(), rt, depth, cv::Size(c.width, c.height), out,
                          false);
  return out;
}

}  // namespace tessera::visual_slam

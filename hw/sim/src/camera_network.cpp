#include <tessera/sim/camera_network.hpp>

#include <Eigen/Geometry>
#include <Eigen/LU>

#include <cmath>
#include <set>
#include <sstream>
#include <stdexcept>

namespace tessera::sim {

namespace {

constexpr double kMaxTilt = 0.5;  // [rad]; beyond this the camera could see the horizon

}  // namespace

ConfigCheck CameraIntrinsics::check() const {
  ConfigCheck c;
  c.positive("ceiling_height", ceiling_height).positive("focal_px", focal_px);
  c.require(width_px >= 1, "width_px", "must be positive", width_px);
  c.require(height_px >= 1, "height_px", "must be positive", height_px);
  c.nonNegative("pixel_noise", pixel_noise).probability("miss_probability", miss_probability);
  return c;
}

EnvironmentCamera::EnvironmentCamera(const CameraSite& site, const CameraIntrinsics& intrinsics)
    : site_(site), intrinsics_(intrinsics) {
  intrinsics_.validate();
  for (double t : {site.roll, site.pitch})
    if (!(std::abs(t) < kMaxTilt)) {
      std::ostringstream s;
      s << "camera " << site.id << ": tilt must be below " << kMaxTilt << " rad, got " << t;
      throw std::invalid_argument(s.str());
    }
  if (!site.position.allFinite() || !std::isfinite(site.yaw))
    throw std::invalid_argument("camera " + std::to_string(site.id) + ": position is not finite");

  // Camera axes in the world for an untilted camera: x (image u) along the yaw, z (optical axis)
  // straight down, y (image v) = z cross x, to the right of u seen from above.
  const double c = std::cos(site.yaw), s = std::sin(site.yaw);
  Eigen::Matrix3d r_wc0;
  r_wc0.col(0) << c, s, 0;
  r_wc0.col(1) << s, -c, 0;
  r_wc0.col(2) << 0, 0, -1;
  const Eigen::Matrix3d r_wc = r_wc0 * Eigen::AngleAxisd(site.roll, Eigen::Vector3d::UnitX()) *
                               Eigen::AngleAxisd(site.pitch, Eigen::Vector3d::UnitY());
  Eigen::Matrix3d k = Eigen::Matrix3d::Identity();
  k(0, 0) = k(1, 1) = intrinsics_.focal_px;
  k(0, 2) = 0.5 * intrinsics_.width_px;
  k(1, 2) = 0.5 * intrinsics_.height_px;
  // Floor point (x, y, 0) minus the camera centre (px, py, h) is M [x y 1]^T.
  Eigen::Matrix3d m;
  m << 1, 0, -site.position.x(), 0, 1, -site.position.y(), 0, 0, -intrinsics_.ceiling_height;
  h_ = k * r_wc.transpose() * m;
  // The floor point below the camera is always in front of it (tilt < kMaxTilt): scaling by its
  // depth keeps "third component > 0" meaning "in front" everywhere.
  h_ /= (h_ * site.position.homogeneous()).z();
  h_inv_ = h_.inverse();
}

std::optional<Eigen::Vector2d> EnvironmentCamera::project(const Eigen::Vector2d& floor) const {
  const Eigen::Vector3d q = h_ * floor.homogeneous();
  if (!(q.z() > 0)) return std::nullopt;
  return q.hnormalized();
}

Eigen::Vector2d EnvironmentCamera::floorPoint(const Eigen::Vector2d& pixel) const {
  return (h_inv_ * pixel.homogeneous()).hnormalized();
}

bool EnvironmentCamera::inView(const Eigen::Vector2d& floor) const {
  const auto px = project(floor);
  return px && px->x() >= 0 && px->y() >= 0 && px->x() < intrinsics_.width_px &&
         px->y() < intrinsics_.height_px;
}

std::array<Eigen::Vector2d, 4> EnvironmentCamera::footprint() const {
  const double w = intrinsics_.width_px, h = intrinsics_.height_px;
  return {floorPoint({0, 0}), floorPoint({w, 0}), floorPoint({w, h}), floorPoint({0, h})};
}

std::vector<Eigen::Vector2d> EnvironmentCamera::footprintPolygon(double max_distance) const {
  if (!(max_distance > 0) || !std::isfinite(max_distance))
    throw std::invalid_argument("footprint: max_distance must be finite and > 0");
  // The footprint in homogeneous floor coordinates X = [x y 1]: with rows h0, h1, h2 of H,
  // u >= 0, u <= W, v >= 0, v <= H read h0 X >= 0, W h2 X - h0 X >= 0, ... when h2 X > 0 (in
  // front), which any two opposite ones imply. Each is a half-plane g X >= 0; clipping the square
  // by the four (Sutherland-Hodgman) leaves a convex polygon.
  const double w = intrinsics_.width_px, hp = intrinsics_.height_px;
  const Eigen::RowVector3d h0 = h_.row(0), h1 = h_.row(1), h2 = h_.row(2);
  const std::array<Eigen::RowVector3d, 4> planes = {h1, w * h2 - h0, hp * h2 - h1, h0};
  const Eigen::Vector2d c = site_.position;
  const double d = max_distance;
  std::vector<Eigen::Vector2d> poly = {c + Eigen::Vector2d(-d, -d), c + Eigen::Vector2d(d, -d),
                                       c + Eigen::Vector2d(d, d),
                                       c + Eigen::Vector2d(-d, d)};  // counter-clockwise
  for (const Eigen::RowVector3d& g : planes) {
    // Scaled so that the value is a distance-like number whatever the scale of H.
    const Eigen::RowVector3d gn = g / std::max(g.head<2>().norm(), 1e-300);
    std::vector<Eigen::Vector2d> next;
    for (std::size_t i = 0; i < poly.size(); ++i) {
      const Eigen::Vector2d& a = poly[i];
      const Eigen::Vector2d& b = poly[(i + 1) % poly.size()];
      const double fa = gn.dot(a.homogeneous()), fb = gn.dot(b.homogeneous());
      if (fa >= 0) next.push_back(a);
      if ((fa >= 0) != (fb >= 0)) next.push_back(a + fa / (fa - fb) * (b - a));
    }
    poly.clear();
    // Drop vertices that coincide with their predecessor (a corner on a clipping line).
    for (const auto& p : next)
      if (poly.empty() || (p - poly.back()).norm() > 1e-9) poly.push_back(p);
    while (poly.size() > 1 && (poly.front() - poly.back()).norm() <= 1e-9) poly.pop_back();
  }
  return poly;
}

CameraNetwork::CameraNetwork(const std::vector<CameraSite>& sites,
                             const CameraIntrinsics& intrinsics) {
  std::set<int> ids;
  for (const CameraSite& s : sites) {
    if (!ids.insert(s.id).second)
      throw std::invalid_argument("camera network: duplicate camera id " + std::to_string(s.id));
    cameras_.emplace_back(s, intrinsics);
  }
  inside_.assign(cameras_.size(), false);
}

void CameraNetwork::reset() {
  inside_.assign(cameras_.size(), false);
}

CameraNetwork::Frame CameraNetwork::observe(const Eigen::Vector2d& marker, std::mt19937_64& rng) {
  Frame frame;
  std::vector<bool> now(cameras_.size(), false);
  for (std::size_t i = 0; i < cameras_.size(); ++i) now[i] = cameras_[i].inView(marker);
  for (std::size_t i = 0; i < cameras_.size(); ++i)
    if (inside_[i] && !now[i]) frame.transitions.push_back({cameras_[i].id(), false});
  for (std::size_t i = 0; i < cameras_.size(); ++i)
    if (!inside_[i] && now[i]) frame.transitions.push_back({cameras_[i].id(), true});
  inside_ = now;

  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (std::size_t i = 0; i < cameras_.size(); ++i) {
    if (!now[i]) continue;
    const EnvironmentCamera& cam = cameras_[i];
    MarkerReport r;
    r.camera_id = cam.id();
    r.true_pixel = *cam.project(marker);  // in view implies in front
    const double u = uniform(rng), nu = normal(rng), nv = normal(rng);
    r.detected = u >= cam.intrinsics().miss_probability;
    if (r.detected) r.pixel = r.true_pixel + cam.intrinsics().pixel_noise * Eigen::Vector2d(nu, nv);
    frame.reports.push_back(r);
  }
  return frame;
}

}  // namespace tessera::sim

// The camera network's calibrations and revisit constraints: see camera_constraint_builder.hpp.
#include <tessera/camera_network/camera_constraint_builder.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <stdexcept>
#include <utility>

namespace tessera::camera_network {

ConfigCheck CameraConstraintBuilderOptions::check() const {
  if (ConfigCheck c = calibration.check(); c.problem()) return c;
  if (ConfigCheck c = revisit.check(); c.problem()) return c;
  if (ConfigCheck c = visit_path.check(); c.problem()) return c;
  ConfigCheck c;
  c.require(marker.size() == 2 && std::isfinite(marker[0]) && std::isfinite(marker[1]), "marker",
            "must be [x, y] with finite values, got size", static_cast<double>(marker.size()))
      .require(image_width_px > 0, "image_width_px", "must be > 0", image_width_px)
      .require(image_height_px > 0, "image_height_px", "must be > 0", image_height_px)
      .positive("slam_position_std_m", slam_position_std_m)
      .nonNegative("slam_anchor_std_m", slam_anchor_std_m)
      .nonNegative("slam_anchor_std_rad", slam_anchor_std_rad)
      .require(stale_visits >= 1, "stale_visits", "must be >= 1", stale_visits)
      .require(max_visit_sightings >= 1, "max_visit_sightings", "must be >= 1", max_visit_sightings)
      .positive("odometry_shape_max_s", odometry_shape_max_s)
      .require(
          std::isfinite(relocalisation_covariance_scale) && relocalisation_covariance_scale >= 1,
          "relocalisation_covariance_scale", "must be finite and >= 1",
          relocalisation_covariance_scale);
  return c;
}

CameraConstraintBuilder::CameraConstraintBuilder(CameraConstraintBuilderOptions options)
    : options_(std::move(options)) {
  options_.check().throwIfBad("camera constraint builder");
  marker_ = {options_.marker[0], options_.marker[1]};
  origins_[0] = Pose2::identity();
}

bool CameraConstraintBuilder::addSubmap(std::uint32_t id, const Pose2& origin, bool anchored) {
  if (!origin.isFinite()) return false;
  origins_[id] = origin;
  current_ = std::max(current_, id);
  if (!anchored && !unanchored_since_) unanchored_since_ = id;
  return true;
}

Pose2 CameraConstraintBuilder::poseIn(std::uint32_t submap, const Pose2& chained) const {
  const auto it = origins_.find(submap);
  const Pose2 origin = it == origins_.end() ? Pose2::identity() : it->second;
  return origin.inverse() * chained;
}

Eigen::Vector2d CameraConstraintBuilder::markerIn(std::uint32_t submap,
                                                  const Pose2& chained_robot) const {
  return poseIn(submap, chained_robot) * marker_;
}

std::vector<CameraOutput> CameraConstraintBuilder::enter(int camera, std::int64_t stamp_ns) {
  // A new visit; an unfinished one (a missed leave) ends first.
  std::vector<CameraOutput> out;
  if (visits_.count(camera)) out = endVisit(camera, stamp_ns);
  visits_[camera] = Visit{};
  return out;
}

std::vector<CameraOutput> CameraConstraintBuilder::leave(int camera, std::int64_t stamp_ns) {
  if (!visits_.count(camera)) return {};
  return endVisit(camera, stamp_ns);
}

bool CameraConstraintBuilder::add(const CameraSighting& s) {
  if (!s.pixel.allFinite() || !s.robot.isFinite() || !std::isfinite(s.pixel_std) ||
      !(s.pixel_std > 0) || (s.odometry && !s.odometry->isFinite())) {
    ++ignored_;
    return false;
  }
  auto& v = visits_[s.camera];
  if (static_cast<int>(v.sightings.size()) >= options_.max_visit_sightings) {
    ++ignored_;
    return false;
  }
  v.sightings.push_back(s);
  return true;
}

std::vector<CameraOutput> CameraConstraintBuilder::finish(std::int64_t stamp_ns) {
  std::vector<CameraOutput> out;
  while (!visits_.empty()) {
    auto more = endVisit(visits_.begin()->first, stamp_ns);
    out.insert(out.end(), more.begin(), more.end());
  }
  auto more = release(true);
  out.insert(out.end(), more.begin(), more.end());
  return out;
}

std::vector<CameraOutput> CameraConstraintBuilder::addTrajectory(
    std::uint32_t id, const std::vector<std::pair<std::int64_t, Pose2>>& poses) {
  auto& t = trajectories_[id];
  if (!t.empty()) {
    const auto end = trajectory_ends_.find(t.back().first);
    if (end != trajectory_ends_.end() && end->second == id) trajectory_ends_.erase(end);
  }
  t.clear();
  for (const auto& p : poses)
    if (p.second.isFinite() && (t.empty() || p.first > t.back().first)) t.push_back(p);
  if (!t.empty()) {
    smoothed_until_ = std::max(smoothed_until_, t.back().first);
    trajectory_ends_.emplace(t.back().first, id);  // an equal end keeps the earlier submap
  }
  return release(false);
}

Pose2 CameraConstraintBuilder::smoothed(std::int64_t stamp, const Pose2& online) const {
  const auto end = trajectory_ends_.lower_bound(stamp);
  if (end == trajectory_ends_.end()) return online;
  const auto& t = trajectories_.at(end->second);
  if (stamp < t.front().first) return online;
  const auto origin = origins_.find(end->second);
  if (origin == origins_.end()) return online;
  const auto it = std::lower_bound(t.begin(), t.end(), stamp,
                                   [](const auto& a, std::int64_t s) { return a.first < s; });
  if (it->first == stamp) return origin->second * it->second;
  const auto prev = std::prev(it);
  const double f = double(stamp - prev->first) / double(it->first - prev->first);
  return origin->second * interpolate(prev->second, it->second, f);
}

std::vector<CameraOutput> CameraConstraintBuilder::release(bool all) {
  std::vector<CameraOutput> out;
  std::size_t n = 0;
  for (; n < held_.size(); ++n) {
    const auto& v = held_[n];
    if (!all && v.sightings.back().stamp_ns > smoothed_until_) break;
  }
  std::vector<HeldVisit> ready(std::make_move_iterator(held_.begin()),
                               std::make_move_iterator(held_.begin() + static_cast<long>(n)));
  held_.erase(held_.begin(), held_.begin() + static_cast<long>(n));
  for (auto& v : ready) {
    for (auto& s : v.sightings) s.robot = smoothed(s.stamp_ns, s.robot);
    auto more = process(std::move(v));
    out.insert(out.end(), more.begin(), more.end());
  }
  return out;
}

std::optional<CameraOutput> CameraConstraintBuilder::calibrate(
    int camera, const std::vector<CameraSighting>& sightings, std::uint32_t submap,
    std::int64_t stamp_ns, const std::vector<Pose2>* slam) {
  std::vector<FloorPixelPair> pairs;
  double pixel_std = 0;
  for (const auto& s : sightings) {
    pairs.push_back({markerIn(submap, s.robot), s.pixel});
    pixel_std = std::max(pixel_std, s.pixel_std);
  }
  CameraOutput o;
  o.camera = camera;
  o.stamp_ns = stamp_ns;
  o.sightings = static_cast<int>(sightings.size());
  if (pairs.empty()) {
    o.kind = CameraOutput::Kind::kCalibrationRefused;
    o.reason = "no sightings";
    return o;
  }
  auto r = estimateFloorHomography(pairs, options_.image_width_px, options_.image_height_px,
                                   pixel_std, options_.calibration);
  if (r.homography && slam && slam->size() == sightings.size() && options_.visit_path.enabled) {
    std::vector<std::int64_t> stamps;
    std::vector<Pose2> poses, anchor;
    std::vector<Eigen::Vector2d> pixels;
    for (std::size_t k = 0; k < sightings.size(); ++k) {
      stamps.push_back(sightings[k].stamp_ns);
      poses.push_back(poseIn(submap, sightings[k].robot));
      anchor.push_back(poseIn(submap, (*slam)[k]));
      pixels.push_back(sightings[k].pixel);
    }
    const auto path =
        refineVisitPath(stamps, poses, anchor, pixels, marker_, *r.homography, pixel_std,
                        options_.calibration.ransac_threshold_px, options_.visit_path);
    if (!path.poses.empty()) {
      std::vector<FloorPixelPair> refined;
      for (std::size_t k = 0; k < sightings.size(); ++k)
        refined.push_back({path.poses[k] * marker_, sightings[k].pixel});
      auto again =
          estimateFloorHomography(refined, options_.image_width_px, options_.image_height_px,
                                  pixel_std, options_.calibration);
      if (again.homography) {
        r = std::move(again);
        ++refined_paths_;
      }
    }
  }
  if (!r.homography) {
    o.kind = CameraOutput::Kind::kCalibrationRefused;
    o.reason = r.refusal;
    return o;
  }
  o.kind = CameraOutput::Kind::kCalibrated;
  o.calibration = CameraCalibration{camera, submap, stamp_ns, *r.homography};
  calibrations_[camera] = *o.calibration;
  strikes_[camera] = 0;
  return o;
}

std::vector<CameraOutput> CameraConstraintBuilder::endVisit(int camera, std::int64_t stamp_ns) {
  HeldVisit v{camera, current_, stamp_ns, std::move(visits_[camera].sightings)};
  visits_.erase(camera);
  if (v.sightings.empty()) return {};
  const auto cal = calibrations_.find(camera);
  if (unanchored_since_ && current_ >= *unanchored_since_ && cal != calibrations_.end() &&
      cal->second.submap < *unanchored_since_) {
    // The relocalisation: the robot's online poses in the unanchored submap, now. Provisional:
    // the same visit on smoothed poses follows.
    HeldVisit refine = v;
    v.relocalisation = true;
    auto out = process(std::move(v));
    bool placed = false;
    for (auto& o : out)
      if (o.kind == CameraOutput::Kind::kRevisit) {
        placed = true;
        o.covariance *= options_.relocalisation_covariance_scale;
      }
    if (placed) {
      unanchored_since_.reset();
      if (options_.smoothed_poses) {
        refine.refines_relocalisation = true;
        held_.push_back(std::move(refine));
      }
    }
    return out;
  }
  held_.push_back(std::move(v));
  return release(!options_.smoothed_poses);
}

bool CameraConstraintBuilder::placeOdometryShape(std::vector<CameraSighting>& sightings) const {
  std::vector<CameraSighting*> with;
  for (auto& s : sightings)
    if (s.odometry) with.push_back(&s);
  if (with.size() < 2) return false;
  const double span_s = 1e-9 * double(with.back()->stamp_ns - with.front()->stamp_ns);
  if (span_s > options_.odometry_shape_max_s) return false;
  // The rigid transform T minimising Σ |T(odometry_k) - slam_k|² over the robot positions; a
  // robot that hardly moved (under 0.1 m) gives no rotation from positions, so then its headings
  // give it.
  std::vector<Eigen::Vector2d> odometry, slam;
  for (const auto* s : with) {
    odometry.push_back(s->odometry->translation());
    slam.push_back(s->robot.translation());
  }
  Pose2 place = closedFormRigidFit(odometry, slam);
  double extent = 0, sin_sum = 0, cos_sum = 0;
  for (const auto* s : with) {
    extent = std::max(extent, (s->odometry->translation() - odometry.front()).norm());
    const double d = angleDiff(s->robot.theta, s->odometry->theta);
    sin_sum += std::sin(d);
    cos_sum += std::cos(d);
  }
  if (extent < 0.1) {
    // Rotate the odometry by the mean heading difference about its centroid onto the SLAM's.
    Eigen::Vector2d mo = Eigen::Vector2d::Zero(), ms = Eigen::Vector2d::Zero();
    for (std::size_t k = 0; k < slam.size(); ++k) {
      mo += odometry[k];
      ms += slam[k];
    }
    const double theta = std::atan2(sin_sum, cos_sum);
    place = Pose2(ms / double(slam.size()) - Eigen::Rotation2Dd(theta) * (mo / double(slam.size())),
                  theta);
  }
  for (auto* s : with) s->robot = place * *s->odometry;
  return true;
}

std::vector<CameraOutput> CameraConstraintBuilder::process(HeldVisit visit) {
  std::vector<CameraOutput> out;
  // The SLAM's poses of a visit whose whole path becomes the odometry's (visit_path).
  const bool refine_path = options_.odometry_shape && options_.visit_path.enabled;
  std::vector<Pose2> slam;
  if (refine_path)
    for (const auto& s : visit.sightings) slam.push_back(s.robot);
  bool shaped = false;
  if (options_.odometry_shape && placeOdometryShape(visit.sightings)) {
    ++odometry_shaped_;
    shaped = std::all_of(visit.sightings.begin(), visit.sightings.end(),
                         [](const CameraSighting& s) { return s.odometry.has_value(); });
  }
  const std::vector<Pose2>* shaped_from = shaped && refine_path ? &slam : nullptr;
  const int camera = visit.camera;
  const std::int64_t stamp_ns = visit.stamp_ns;
  const std::vector<CameraSighting>& sightings = visit.sightings;

  const auto cal = calibrations_.find(camera);
  if (cal == calibrations_.end()) {
    if (auto o = calibrate(camera, sightings, visit.submap, stamp_ns, shaped_from))
      out.push_back(std::move(*o));
    return out;
  }
  const CameraCalibration calibration = cal->second;
  const std::uint32_t i = visit.submap, j = calibration.submap;
  // Camera positions in j (pixel noise only: the calibration's error is shared by all sightings
  // and enters below), SLAM positions in i.
  FloorHomography pixel_only = calibration.homography;
  pixel_only.covariance.setZero();
  const double slam_var = options_.slam_position_std_m * options_.slam_position_std_m;
  std::vector<PointCorrespondence> points;
  std::vector<Eigen::Vector2d> pixels;
  std::vector<const CameraSighting*> used;
  for (const auto& s : sightings) {
    const auto fix = localizeMarker(pixel_only, s.pixel, s.pixel_std);
    if (!fix) continue;
    points.push_back({markerIn(i, s.robot), slam_var * Eigen::Matrix2d::Identity(), fix->position,
                      fix->covariance});
    used.push_back(&s);
  }
  CameraOutput o;
  o.camera = camera;
  o.stamp_ns = stamp_ns;
  o.from = i;
  o.to = j;
  o.sightings = static_cast<int>(points.size());
  o.relocalisation = visit.relocalisation;
  o.refines_relocalisation = visit.refines_relocalisation;
  if (i == j) {
    // Still in the calibration's submap: the positions must agree as they are.
    double sse = 0;
    for (const auto& p : points) sse += (p.parent - p.child).squaredNorm();
    o.kind = CameraOutput::Kind::kChecked;
    o.rms_m = points.empty() ? 0 : std::sqrt(sse / points.size());
    const bool disagrees = !points.empty() && o.rms_m > options_.revisit.max_rms_m;
    if (disagrees) o.reason = "calibration disagrees with the SLAM in its own submap";
    out.push_back(o);
    if (disagrees && ++strikes_[camera] >= options_.stale_visits) {
      calibrations_.erase(camera);
      if (auto c = calibrate(camera, sightings, visit.submap, stamp_ns, shaped_from))
        out.push_back(std::move(*c));
    } else if (!disagrees) {
      strikes_[camera] = 0;
    }
    return out;
  }
  const auto fit = fitMapTransform(points, options_.revisit);
  o.rms_m = fit.measured.rms_m;
  if (!fit.fit) {
    o.kind = CameraOutput::Kind::kRevisitRefused;
    o.reason = fit.refusal;
    out.push_back(o);
    const bool disagrees = fit.measured.points >= options_.revisit.min_points &&
                           fit.measured.extent_m >= options_.revisit.min_extent_m;
    if (disagrees && ++strikes_[camera] >= options_.stale_visits) {
      calibrations_.erase(camera);
      if (auto c = calibrate(camera, sightings, visit.submap, stamp_ns, shaped_from))
        out.push_back(std::move(*c));
    }
    return out;
  }
  strikes_[camera] = 0;
  // The calibration's uncertainty, shared by every sighting: refit with Hn moved along each of
  // its 8 parameters (central differences) and propagate.
  Eigen::Matrix<double, 3, 8> jh = Eigen::Matrix<double, 3, 8>::Zero();
  const auto& h = calibration.homography;
  for (int k = 0; k < 8; ++k) {
    const double step = 1e-5 * std::max(1.0, std::abs(h.hn(k / 3, k % 3)));
    Eigen::Vector3d side[2];
    bool ok = true;
    for (int sgn = 0; sgn < 2 && ok; ++sgn) {
      Eigen::Matrix<double, 8, 1> d = Eigen::Matrix<double, 8, 1>::Zero();
      d(k) = sgn == 0 ? step : -step;
      const FloorHomography moved = pixel_only.perturbed(d);
      std::vector<PointCorrespondence> pts = points;
      for (std::size_t n = 0; n < pts.size() && ok; ++n) {
        const auto p = moved.floorPoint(used[n]->pixel);
        if (!p)
          ok = false;
        else
          pts[n].child = *p;
      }
      if (!ok) break;
      const auto f = fitMapTransform(pts, options_.revisit);
      const Pose2& t = f.measured.transform;
      side[sgn] = Eigen::Vector3d(t.x, t.y, t.theta);
    }
    if (!ok) continue;
    Eigen::Vector3d diff = side[0] - side[1];
    diff(2) = angleDiff(side[0](2), side[1](2));
    jh.col(k) = diff / (2 * step);
  }
  o.kind = CameraOutput::Kind::kRevisit;
  o.relative = fit.fit->transform;
  o.covariance = fit.fit->covariance + jh * h.covariance * jh.transpose();
  // The SLAM's rigid error of the whole path in i: a turn φ about the path's centroid c and a
  // shift d move T to (R(φ)(t - c) + c + d, θ + φ).
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
  for (const auto& p : points) centroid += p.parent;
  centroid /= static_cast<double>(points.size());
  const Eigen::Vector2d arm =
      Eigen::Vector2d(fit.fit->transform.x, fit.fit->transform.y) - centroid;
  Eigen::Matrix3d ja = Eigen::Matrix3d::Identity();
  ja(0, 2) = -arm.y();
  ja(1, 2) = arm.x();
  const double sm = options_.slam_anchor_std_m, sr = options_.slam_anchor_std_rad;
  o.covariance += ja * Eigen::Vector3d(sm * sm, sm * sm, sr * sr).asDiagonal() * ja.transpose();
  o.covariance = 0.5 * (o.covariance + o.covariance.transpose()).eval();
  o.robot_in_to = o.relative.inverse() * (origins_.count(i) ? origins_.at(i).inverse() : Pose2()) *
                  used.back()->robot;
  out.push_back(o);
  return out;
}

}  // namespace tessera::camera_network

#include <tessera/camera_network/camera_calibration_file.hpp>
#include <tessera/camera_network/camera_network_slam_actor.hpp>
#include <tessera/messages/geometry.hpp>
#include <tessera/runtime/registry.hpp>

#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <stdexcept>
#include <vector>

namespace tessera::camera_network {

namespace {

void require(bool ok, const char* key, const std::string& rule) {
  if (!ok) throw ConfigError(std::string("camera_network_slam: ") + key + " " + rule);
}

/// The actor's own options, checked before anything is built from them.
CameraNetworkSlamOptions checked(CameraNetworkSlamOptions o) {
  require(o.detection_queue >= 1, "detection_queue", "must be >= 1");
  require(o.pose_queue >= 1, "pose_queue", "must be >= 1");
  require(o.pose_history >= 2, "pose_history", "must be >= 2");
  require(o.odom_queue >= 1, "odom_queue", "must be >= 1");
  require(o.odom_history >= 2, "odom_history", "must be >= 2");
  require(std::isfinite(o.max_pose_gap_s) && o.max_pose_gap_s > 0, "max_pose_gap_s",
          "must be finite and > 0");
  require(std::isfinite(o.truth_tolerance_linear) && o.truth_tolerance_linear > 0,
          "truth_tolerance_linear", "must be finite and > 0");
  require(std::isfinite(o.truth_tolerance_angular) && o.truth_tolerance_angular > 0,
          "truth_tolerance_angular", "must be finite and > 0");
  return o;
}

}  // namespace

CameraNetworkSlamActor::CameraNetworkSlamActor(CameraNetworkSlamOptions options)
    : options_(checked(std::move(options))),
      builder_([this] {
        try {
          return CameraConstraintBuilder(options_.builder);
        } catch (const std::invalid_argument& e) {
          throw ConfigError(std::string("camera_network_slam: builder: ") + e.what());
        }
      }()),
      pairing_(static_cast<std::size_t>(options_.detection_queue),
               static_cast<std::size_t>(options_.pose_history), options_.max_pose_gap_s),
      odom_(static_cast<std::size_t>(options_.odom_history), options_.max_pose_gap_s) {
  chained_origins_[0] = Pose2::identity();
}

void CameraNetworkSlamActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  constraint_pub_ = ctx.advertise<msg::SubmapConstraint>("camera_constraints");
  calibration_pub_ = ctx.advertise<msg::CameraCalibration>("camera_calibrations");
  ctx.subscribe<msg::CameraEvent>(
      "camera_events", MailboxPolicy::reliable(), [this](const Message<msg::CameraEvent>& m) {
        Item item;
        item.kind = m->getEntered() ? Item::Kind::kEnter : Item::Kind::kLeave;
        item.camera = m->getCameraId();
        const std::int64_t stamp = m->getHeader().getStampNs();
        pairing_.addItem({item, stamp}, stamp,
                         [this](const auto& it, const Pose2& p) { use(it.first, it.second, p); });
      });
  ctx.subscribe<msg::MarkerDetection>(
      "camera_detections",
      MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.detection_queue)),
      [this](const Message<msg::MarkerDetection>& m) {
        if (!m->getDetected()) {
          ++misses_;
          return;
        }
        Item item;
        item.camera = m->getCameraId();
        item.pixel = {m->getU(), m->getV()};
        item.pixel_std = m->getPixelStd();
        if (const auto c = m->getCorners(); c.size() == 8) {
          std::array<Eigen::Vector2d, 4> corners;
          for (unsigned k = 0; k < 4; ++k) corners[k] = {c[2 * k], c[2 * k + 1]};
          item.corners = corners;
        }
        const std::int64_t stamp = m->getHeader().getStampNs();
        pairing_.addItem({item, stamp}, stamp,
                         [this](const auto& it, const Pose2& p) { use(it.first, it.second, p); });
      });
  if (options_.builder.odometry_shape) {
    ctx.subscribe<msg::Odometry>(
        "odom", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.odom_queue)),
        [this](const Message<msg::Odometry>& m) {
          if (!odom_.add(m->getHeader().getStampNs(), toPose2(m->getPose()))) ++odom_ignored_;
        });
  }
  ctx.subscribe<msg::PoseStamped>(
      "chained_pose", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.pose_queue)),
      [this](const Message<msg::PoseStamped>& m) {
        const std::int64_t stamp = m->getHeader().getStampNs();
        if (!submap_start_.count(0)) {
          submap_start_[0] = stamp;
          Pose2 t;
          if (options_.score_ground_truth && truthAt(stamp, t)) start_truth_[0] = t;
        }
        last_stamp_ = std::max(last_stamp_, stamp);
        pairing_.addPose(stamp, toPose2(m->getPose()),
                         [this](const auto& it, const Pose2& p) { use(it.first, it.second, p); });
      });
  ctx.subscribe<msg::SubmapConstraint>(
      "constraints", MailboxPolicy::reliable(), [this](const Message<msg::SubmapConstraint>& m) {
        if (m->getKind() != msg::SubmapConstraint::Kind::HAND_OVER) return;
        const auto from = chained_origins_.find(m->getFromId());
        const Pose2 relative = toPose2(m->getRelative());
        if (from == chained_origins_.end() || !relative.isFinite()) return;
        const std::uint32_t to = m->getToId();
        const Pose2 origin = from->second * relative;
        chained_origins_[to] = origin;
        const bool anchored = !m->getLost();
        if (!anchored) {
          ++unanchored_handovers_;
          std::cerr << "[camera_network_slam] submap " << to
                    << " is unanchored (the submap builder was lost): the next calibrated camera "
                       "relocalises it\n";
        }
        builder_.addSubmap(to, origin, anchored);
        const std::int64_t stamp = m->getHeader().getStampNs();
        submap_start_[to] = stamp;
        Pose2 t;
        if (options_.score_ground_truth && truthAt(stamp, t)) start_truth_[to] = t;
      });
  ctx.subscribe<msg::Submap>(
      "submaps", MailboxPolicy::reliable(), [this](const Message<msg::Submap>& m) {
        if (!m->getFinished()) return;
        std::vector<std::pair<std::int64_t, Pose2>> poses;
        for (const auto p : m->getTrajectory())
          poses.emplace_back(p.getStampNs(), Pose2(p.getX(), p.getY(), p.getTheta()));
        handle(builder_.addTrajectory(m->getId(), poses));
      });
  if (options_.score_ground_truth)
    ctx.subscribe<msg::GroundTruthPose>("ground_truth", MailboxPolicy::keepLatest(1000),
                                        [this](const Message<msg::GroundTruthPose>& m) {
                                          truth_.add(m->getHeader().getStampNs(),
                                                     toPose2(m->getPose()));
                                        });
}

void CameraNetworkSlamActor::use(const Item& item, std::int64_t stamp, const Pose2& chained) {
  switch (item.kind) {
    case Item::Kind::kEnter:
      handle(builder_.enter(item.camera, stamp));
      return;
    case Item::Kind::kLeave:
      handle(builder_.leave(item.camera, stamp));
      return;
    case Item::Kind::kSighting:
      break;
  }
  CameraSighting s;
  s.stamp_ns = stamp;
  s.camera = item.camera;
  s.pixel = item.pixel;
  s.pixel_std = item.pixel_std;
  s.robot = chained;
  Pose2 odom;
  if (const auto r = odom_.at(stamp, odom);
      r == PoseHistory::Lookup::kExact || r == PoseHistory::Lookup::kInterpolated)
    s.odometry = odom;
  if (builder_.add(s)) {
    ++sightings_;
    if (s.odometry) ++sightings_with_odometry_;
  }
  if (options_.score_ground_truth) scoreSighting(s, item.corners);
}

void CameraNetworkSlamActor::scoreSighting(
    const CameraSighting& s, const std::optional<std::array<Eigen::Vector2d, 4>>& corners) {
  const auto cal = builder_.calibrations().find(s.camera);
  if (cal == builder_.calibrations().end()) return;
  const auto start = start_truth_.find(cal->second.submap);
  Pose2 now;
  if (start == start_truth_.end() || !truthAt(s.stamp_ns, now)) return;
  const auto fix = localizeMarker(cal->second.homography, s.pixel, s.pixel_std);
  if (!fix) return;
  const auto& m = options_.builder.marker;
  const Eigen::Vector2d truth = (start->second.inverse() * now) * Eigen::Vector2d(m[0], m[1]);
  const double e = (fix->position - truth).norm();
  loc_sq_ += e * e;
  loc_max_ = std::max(loc_max_, e);
  ++loc_count_;
  if (!corners) return;
  const auto pose = localizeMarkerPose(cal->second.homography, *corners, s.pixel_std);
  if (!pose) return;
  const Pose2 robot_truth = start->second.inverse() * now;
  const Eigen::Vector3d err(pose->pose.x - truth.x(), pose->pose.y - truth.y(),
                            angleDiff(pose->pose.theta, robot_truth.theta));
  heading_sq_ += err(2) * err(2);
  const Eigen::Matrix3d cov = pose->covariance;
  if (cov.allFinite() && cov.determinant() > 0) heading_nees_ += err.dot(cov.inverse() * err);
  ++heading_count_;
}

bool CameraNetworkSlamActor::truthAt(std::int64_t stamp, Pose2& out) const {
  const auto r = truth_.at(stamp, out);
  return r == PoseHistory::Lookup::kExact || r == PoseHistory::Lookup::kInterpolated;
}

void CameraNetworkSlamActor::handle(const std::vector<CameraOutput>& outputs) {
  for (const auto& o : outputs) {
    switch (o.kind) {
      case CameraOutput::Kind::kCalibrated:
        ++calibrations_;
        std::cerr << std::fixed << std::setprecision(2) << "[camera_network_slam] camera "
                  << o.camera << ": calibrated in submap " << o.calibration->submap << " from "
                  << o.sightings << " sightings, RMS " << o.calibration->homography.quality.rms_px
                  << " px, " << 100 * o.calibration->homography.quality.coverage
                  << " % of the image\n";
        publishCalibration(*o.calibration);
        break;
      case CameraOutput::Kind::kCalibrationRefused:
        ++calibrations_refused_;
        last_refusal_ = "camera " + std::to_string(o.camera) + ": " + o.reason;
        std::cerr << "[camera_network_slam] camera " << o.camera << ": calibration refused ("
                  << o.reason << "); waiting for more motion\n";
        break;
      case CameraOutput::Kind::kRevisit:
        publishRevisit(o);
        break;
      case CameraOutput::Kind::kRevisitRefused:
        ++revisits_refused_;
        last_refusal_ = "camera " + std::to_string(o.camera) + ": " + o.reason;
        std::cerr << "[camera_network_slam] camera " << o.camera << ": no revisit constraint "
                  << o.from << " -> " << o.to << " (" << o.reason << ")\n";
        break;
      case CameraOutput::Kind::kChecked:
        ++checks_;
        if (!o.reason.empty())
          last_refusal_ = "camera " + std::to_string(o.camera) + ": " + o.reason;
        break;
    }
  }
}

void CameraNetworkSlamActor::publishRevisit(const CameraOutput& o) {
  auto loan = constraint_pub_.loan();
  setHeader(loan->initHeader(), o.stamp_ns, "map", constraint_pub_.nextSeq());
  loan->setFromId(o.from);
  loan->setToId(o.to);
  writePose(loan->initRelative(), o.relative, &o.covariance);
  loan->setKind(msg::SubmapConstraint::Kind::REVISIT);
  constraint_pub_.publish(std::move(loan));
  ++revisits_;
  if (o.relocalisation) {
    ++relocalisations_;
    std::cerr << "[camera_network_slam] camera " << o.camera << ": relocalised the robot in submap "
              << o.to << " (unanchored submap " << o.from
              << ", online poses, provisional until its smoothed poses)\n";
  }
  if (o.refines_relocalisation) {
    ++relocalisations_refined_;
    std::cerr << "[camera_network_slam] camera " << o.camera << ": relocalisation " << o.from
              << " -> " << o.to << " refined on smoothed poses\n";
  }
  std::cerr << std::fixed << std::setprecision(3) << "[camera_network_slam] camera " << o.camera
            << ": revisit " << o.from << " -> " << o.to << " from " << o.sightings
            << " sightings, RMS " << o.rms_m << " m\n";
  if (!options_.score_ground_truth) return;
  const auto a = start_truth_.find(o.from), b = start_truth_.find(o.to);
  if (a == start_truth_.end() || b == start_truth_.end()) {
    ++revisits_unscored_;
    return;
  }
  const Pose2 truth = a->second.inverse() * b->second;
  const Eigen::Vector3d err(o.relative.x - truth.x, o.relative.y - truth.y,
                            angleDiff(o.relative.theta, truth.theta));
  const bool ok = err.head<2>().norm() <= options_.truth_tolerance_linear &&
                  std::abs(err(2)) <= options_.truth_tolerance_angular;
  ++(ok ? revisits_true_ : revisits_false_);
  std::cerr << std::fixed << std::setprecision(3) << "[camera_network_slam] camera " << o.camera
            << ": revisit " << o.from << " -> " << o.to << (ok ? "" : " is false:")
            << " off the truth by " << err.head<2>().norm() << " m, " << err(2) << " rad";
  // Consistency of the revisit's covariance with its error (3 on average when consistent).
  if (o.covariance.allFinite() && o.covariance.determinant() > 0) {
    const double nees = err.dot(o.covariance.inverse() * err);
    revisit_nees_ += nees;
    ++revisit_nees_count_;
    std::cerr << ", NEES " << nees;
  }
  std::cerr << "\n";
}

void CameraNetworkSlamActor::publishCalibration(const CameraCalibration& c) {
  auto loan = calibration_pub_.loan();
  setHeader(loan->initHeader(), c.stamp_ns, "submap_" + std::to_string(c.submap),
            calibration_pub_.nextSeq());
  loan->setCameraId(c.camera);
  loan->setSubmapId(c.submap);
  auto h = loan->initHomography(9);
  for (unsigned k = 0; k < 9; ++k) h.set(k, c.homography.h(k / 3, k % 3));
  const auto& q = c.homography.quality;
  loan->setRmsPx(q.rms_px);
  loan->setCoverage(q.coverage);
  loan->setCondition(q.condition);
  loan->setPairs(static_cast<std::uint32_t>(std::max(q.pairs, 0)));
  loan->setInliers(static_cast<std::uint32_t>(std::max(q.inliers, 0)));
  calibration_pub_.publish(std::move(loan));
}

void CameraNetworkSlamActor::stop() {
  pairing_.finish();
  handle(builder_.finish(last_stamp_));
  if (options_.calibrations_file.empty() || ctx_->outputDir().empty()) return;
  std::vector<CameraCalibrationRecord> records;
  for (const auto& [id, c] : builder_.calibrations()) records.push_back(calibrationRecord(c));
  const auto path = std::filesystem::path(ctx_->outputDir()) / options_.calibrations_file;
  try {
    writeCameraCalibrations(path, records);
  } catch (const CameraCalibrationFileError& e) {
    throw std::runtime_error(std::string("camera_network_slam: ") + e.what());
  }
}

void CameraNetworkSlamActor::summarize(Summary& out) const {
  out["calibrations"] = calibrations_;
  out["calibrations_refused"] = calibrations_refused_;
  out["revisits"] = revisits_;
  out["revisits_refused"] = revisits_refused_;
  out["relocalisations"] = relocalisations_;
  out["relocalisations_refined"] = relocalisations_refined_;
  out["unanchored_handovers"] = unanchored_handovers_;
  out["checks"] = checks_;
  out["sightings"] = sightings_;
  out["misses"] = misses_;
  if (options_.builder.odometry_shape) {
    out["sightings_with_odometry"] = sightings_with_odometry_;
    out["odometry_ignored"] = odom_ignored_;
    out["visits_odometry_shaped"] = static_cast<std::int64_t>(builder_.odometryShapedVisits());
    out["calibration_paths_refined"] = static_cast<std::int64_t>(builder_.refinedVisitPaths());
  }
  out["sightings_unpaired"] = static_cast<std::int64_t>(pairing_.unpaired());
  out["sightings_ignored"] = static_cast<std::int64_t>(builder_.ignoredSightings());
  out["cameras_calibrated"] = static_cast<std::int64_t>(builder_.calibrations().size());
  double rms = 0;
  for (const auto& [id, c] : builder_.calibrations()) rms += c.homography.quality.rms_px;
  if (!builder_.calibrations().empty())
    out["calibration_rms_px"] = rms / static_cast<double>(builder_.calibrations().size());
  if (!last_refusal_.empty()) out["last_refusal"] = last_refusal_;
  if (options_.score_ground_truth) {
    out["revisits_true"] = revisits_true_;
    out["revisits_false"] = revisits_false_;
    out["revisits_unscored"] = revisits_unscored_;
    if (loc_count_ > 0) {
      out["camera_localisation_rms_m"] = std::sqrt(loc_sq_ / static_cast<double>(loc_count_));
      out["camera_localisation_max_m"] = loc_max_;
      out["camera_localisation_sightings"] = loc_count_;
    }
    if (revisit_nees_count_ > 0)
      out["revisit_nees"] = revisit_nees_ / static_cast<double>(revisit_nees_count_);
    if (heading_count_ > 0) {
      out["camera_heading_rms_rad"] = std::sqrt(heading_sq_ / static_cast<double>(heading_count_));
      out["camera_pose_nees"] = heading_nees_ / static_cast<double>(heading_count_);
    }
  }
}

TESSERA_REGISTER_ACTOR("camera_network_slam", CameraNetworkSlamActor, CameraNetworkSlamOptions,
                       "environment cameras in the two-level laser SLAM (seed 000): calibration "
                       "from the robot's motion, camera localisation, revisit constraints");

}  // namespace tessera::camera_network

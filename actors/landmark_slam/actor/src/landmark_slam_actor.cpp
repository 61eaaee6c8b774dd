#include <tessera/landmark_slam/landmark_slam_actor.hpp>

#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/io/atomic_file.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <numbers>
#include <stdexcept>

namespace tessera::landmark_slam {
namespace {

[[noreturn]] void fail(const std::string& what) {
  throw ConfigError("landmark_slam: " + what);
}

std::unique_ptr<LandmarkFilter> makeFilter(const LandmarkSlamActorOptions& a) {
  if (a.landmark_publish_every < 0) fail("landmark_publish_every must be >= 0");
  if (a.frame_id.empty()) fail("frame_id must not be empty");
  try {  // the core validates its options; its messages start with the key
    switch (a.filter) {
      case FilterType::kEkf:
        return std::make_unique<EkfSlam>(a.estimator);
      case FilterType::kRbEkf:
        return std::make_unique<RbUkfSlam>(a.estimator);
    }
  } catch (const std::invalid_argument& e) {
    fail(std::string("estimator.") + e.what());
  }
  fail("unknown filter");
}

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

LandmarkSlamActor::LandmarkSlamActor(LandmarkSlamActorOptions options)
    : options_(std::move(options)), filter_(makeFilter(options_)) {}

void LandmarkSlamActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.subscribe<msg::DriveControl>("control", MailboxPolicy::reliable(),
                                   [this](const Message<msg::DriveControl>& m) { onControl(m); });
  ctx.subscribe<msg::LandmarkScan>("landmarks", MailboxPolicy::reliable(),
                                   [this](const Message<msg::LandmarkScan>& m) { onScan(m); });
  if (options_.ground_truth)
    ctx.subscribe<msg::GroundTruthPose>(
        "ground_truth", MailboxPolicy::reliable(), [this](const Message<msg::GroundTruthPose>& m) {
          const auto p = m->getPose();
          truth_.emplace_back(m->getHeader().getStampNs(),
                              tessera::Pose2(p.getX(), p.getY(), p.getTheta()));
        });
  if (options_.landmark_truth)
    ctx.subscribe<msg::LandmarkMap>(
        "landmark_truth", MailboxPolicy::reliable(), [this](const Message<msg::LandmarkMap>& m) {
          landmark_truth_.clear();
          for (const auto l : m->getLandmarks())
            landmark_truth_.emplace_back(l.getId(), Eigen::Vector2d(l.getX(), l.getY()));
        });
  pose_pub_ = ctx.advertise<msg::PoseStamped>("pose");
  map_pub_ = ctx.advertise<msg::LandmarkMap>("landmark_estimate");
}

void LandmarkSlamActor::onControl(const Message<msg::DriveControl>& m) {
  ++controls_;
  const Nanos stamp = m->getHeader().getStampNs();
  last_stamp_ = std::max(last_stamp_, stamp);
  const double dt = m->getDtS();
  if (!(std::isfinite(dt) && dt >= 0 && dt < 1e6)) {
    ++bad_controls_;
    return;
  }
  if (!have_time_) {
    state_time_ = stamp;
    have_time_ = true;
  }
  advanceTo(stamp);
  PendingControl c;
  c.start = stamp;
  c.end = dt > 0 ? stamp + secondsToNanos(dt) : -1;
  c.input.speed = m->getSpeed();
  c.input.wheelbase = m->getWheelbase();
  if (c.input.carLike())
    c.input.steer = m->getSteering();
  else
    c.input.turn_rate = m->getTurnRate();
  // An open-ended control before this one now ends here.
  if (!pending_.empty() && pending_.back().end < 0) pending_.back().end = stamp;
  pending_.push_back(c);
}

void LandmarkSlamActor::advanceTo(Nanos t) {
  while (!pending_.empty()) {
    PendingControl& c = pending_.front();
    const bool open = c.end < 0;
    const Nanos end = open ? t : c.end;
    const Nanos from = std::max(c.start, state_time_);
    const Nanos to = std::min(end, t);
    if (to > from) {
      predictFor(c.input, to - from);
      state_time_ = to;
    }
    if (open || end > t) break;
    pending_.pop_front();
  }
  // No control covers the rest: the robot is taken to stand still.
  if (t > state_time_) state_time_ = t;
}

void LandmarkSlamActor::predictFor(const tessera::landmark_slam::DriveInput& u, Nanos dt) {
  tessera::landmark_slam::DriveInput v = u;
  v.dt = nanosToSeconds(dt);
  const auto t0 = std::chrono::steady_clock::now();
  try {
    filter_->predict(v);
  } catch (const std::exception& e) {
    noteFilterError(e);
  }
  predict_s_ += secondsSince(t0);
  ++predicts_;
}

void LandmarkSlamActor::onScan(const Message<msg::LandmarkScan>& m) {
  const Nanos stamp = m->getHeader().getStampNs();
  last_stamp_ = std::max(last_stamp_, stamp);
  if (!have_time_) {
    state_time_ = stamp;
    have_time_ = true;
  }
  if (stamp < state_time_) ++late_scans_;
  advanceTo(stamp);
  ++scans_;
  std::vector<Observation> obs;
  obs.reserve(m->getObservations().size());
  for (const auto o : m->getObservations())
    obs.push_back({o.getId(), o.getRange(), o.getBearing(), o.getRangeStd(), o.getBearingStd()});
  observations_ += obs.size();
  const tessera::Pose2 mount(m->getMountX(), m->getMountY(), m->getMountTheta());
  const auto t0 = std::chrono::steady_clock::now();
  UpdateResult r;
  try {
    if (mount.isFinite()) r = filter_->update(obs, mount);
  } catch (const std::exception& e) {
    noteFilterError(e);
  }
  update_s_ += secondsSince(t0);
  if (!mount.isFinite()) ++bad_mounts_;
  corrections_ += r.corrected;
  publishPose(stamp);
  if (options_.landmark_publish_every > 0 &&
      scans_ % static_cast<std::uint64_t>(options_.landmark_publish_every) == 0)
    publishLandmarks(stamp);
}

void LandmarkSlamActor::noteFilterError(const std::exception& e) {
  // The cores validate their input; this is the last line of defence (numerical breakdown),
  // reported once and counted rather than ending the run.
  if (filter_errors_++ == 0) std::cerr << ctx_->name() << ": filter error: " << e.what() << "\n";
}

void LandmarkSlamActor::publishPose(Nanos stamp) {
  const Eigen::Vector3d p = filter_->pose();
  const Eigen::Matrix3d c = filter_->poseCovariance();
  auto loan = pose_pub_.loan();
  setHeader(loan->initHeader(), stamp, options_.frame_id, pose_pub_.nextSeq());
  writePose(loan->initPose(), tessera::Pose2{p[0], p[1], p[2]}, &c);
  pose_pub_.publish(std::move(loan));
  estimate_.emplace_back(stamp, tessera::Pose2(p[0], p[1], p[2]));
}

void LandmarkSlamActor::publishLandmarks(Nanos stamp) {
  const auto lms = filter_->landmarks();
  auto loan = map_pub_.loan(lms.size() * 96 + 128);
  setHeader(loan->initHeader(), stamp, options_.frame_id, map_pub_.nextSeq());
  auto list = loan->initLandmarks(static_cast<unsigned>(lms.size()));
  for (unsigned i = 0; i < lms.size(); ++i) {
    auto l = list[i];
    l.setId(lms[i].id);
    l.setX(lms[i].mean.x());
    l.setY(lms[i].mean.y());
    auto c = l.initCovariance(4);
    for (int k = 0; k < 4; ++k) c.set(k, lms[i].covariance(k / 2, k % 2));
  }
  map_pub_.publish(std::move(loan));
}

void LandmarkSlamActor::stop() {
  publishLandmarks(last_stamp_);
  if (options_.svg_file.empty() || ctx_->outputDir().empty()) return;
  // stop() must not throw: a failed drawing is reported in the summary.
  try {
    writeSvg((std::filesystem::path(ctx_->outputDir()) / options_.svg_file).string());
  } catch (const std::exception& e) {
    svg_error_ = e.what();
    std::cerr << ctx_->name() << ": " << svg_error_ << "\n";
  }
}

void LandmarkSlamActor::writeSvg(const std::string& path) const {
  const auto lms = filter_->landmarks();
  Eigen::AlignedBox2d box;
  for (const auto& [t, p] : estimate_) box.extend(Eigen::Vector2d(p.x, p.y));
  for (const auto& [t, p] : truth_) box.extend(Eigen::Vector2d(p.x, p.y));
  for (const auto& l : lms) box.extend(l.mean);
  for (const auto& [id, xy] : landmark_truth_) box.extend(xy);
  if (box.isEmpty()) box.extend(Eigen::Vector2d::Zero());
  const double margin = 0.05 * std::max(1.0, box.diagonal().maxCoeff());
  box.min().array() -= margin;
  box.max().array() += margin;
  const double scale = 1000.0 / std::max(box.sizes().x(), box.sizes().y());  // px per metre
  const auto X = [&](double x) { return (x - box.min().x()) * scale; };
  const auto Y = [&](double y) { return (box.max().y() - y) * scale; };  // y up
  io::AtomicFile file(path);  // the old file or the new one, whole; errors name the file
  std::ostream& out = file.stream();
  out << std::fixed << std::setprecision(2) << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\""
      << X(box.max().x()) << "\" height=\"" << Y(box.min().y())
      << "\">\n<rect width=\"100%\" height=\"100%\" "
      << "fill=\"white\"/>\n<!-- landmark_slam " << detail::enumName(options_.filter) << ": "
      << scale
      << " px/m; black = ground truth, blue = estimate, red = estimated landmarks with 2-sigma "
         "ellipses, green crosses = true landmarks -->\n";
  const auto polyline = [&](const auto& poses, const char* colour) {
    if (poses.empty()) return;
    out << "<polyline fill=\"none\" stroke=\"" << colour << "\" stroke-width=\"1\" points=\"";
    for (const auto& [t, p] : poses) out << X(p.x) << ',' << Y(p.y) << ' ';
    out << "\"/>\n";
  };
  polyline(truth_, "black");
  polyline(estimate_, "blue");
  for (const auto& [id, xy] : landmark_truth_)
    out << "<path stroke=\"green\" d=\"M" << X(xy.x()) - 4 << ',' << Y(xy.y()) << "h8M" << X(xy.x())
        << ',' << Y(xy.y()) - 4 << "v8\"/>\n";
  for (const auto& l : lms) {
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(l.covariance);
    const Eigen::Vector2d ax = 2.0 * eig.eigenvalues().cwiseMax(0).cwiseSqrt() * scale;
    const Eigen::Vector2d major = eig.eigenvectors().col(1);
    const double deg = -std::atan2(major.y(), major.x()) * 180 / std::numbers::pi;
    out << "<circle fill=\"red\" r=\"2\" cx=\"" << X(l.mean.x()) << "\" cy=\"" << Y(l.mean.y())
        << "\"/><ellipse fill=\"none\" stroke=\"red\" stroke-width=\"0.7\" cx=\"" << X(l.mean.x())
        << "\" cy=\"" << Y(l.mean.y()) << "\" rx=\"" << std::max(ax[1], 0.5) << "\" ry=\""
        << std::max(ax[0], 0.5) << "\" transform=\"rotate(" << deg << ' ' << X(l.mean.x()) << ' '
        << Y(l.mean.y()) << ")\"/>\n";
  }
  out << "</svg>\n";
  file.commit();
}

void LandmarkSlamActor::summarize(Summary& out) const {
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  const RejectionCounts& r = filter_->rejections();
  out["filter"] = detail::enumName(options_.filter);
  out["association"] = detail::enumName(options_.estimator.association);
  out["scans"] = i64(scans_);
  out["controls"] = i64(controls_);
  out["observations"] = i64(observations_);
  out["corrections"] = i64(corrections_);
  out["landmarks"] = i64(filter_->landmarkCount());
  out["rejected_non_finite"] = i64(r.non_finite);
  out["rejected_negative_range"] = i64(r.negative_range);
  out["rejected_unknown_id"] = i64(r.unknown_id);
  out["rejected_gate"] = i64(r.gate);
  out["rejected_ambiguous"] = i64(r.ambiguous);
  out["rejected_between_gates"] = i64(r.between_gates);
  out["rejected_duplicate"] = i64(r.duplicate);
  out["rejected_bad_control"] = i64(r.bad_control + bad_controls_);
  out["rejected_bad_mount_scans"] = i64(bad_mounts_);
  out["late_scans"] = i64(late_scans_);
  out["filter_errors"] = i64(filter_errors_);
  if (!svg_error_.empty()) out["svg_error"] = svg_error_;
  out["nis_count"] = i64(filter_->nisCount());
  out["mean_nis"] =
      filter_->nisCount() > 0 ? filter_->nisSum() / static_cast<double>(filter_->nisCount()) : 0.0;
  out["update_us_mean"] = scans_ > 0 ? 1e6 * update_s_ / static_cast<double>(scans_) : 0.0;
  out["predict_us_mean"] = predicts_ > 0 ? 1e6 * predict_s_ / static_cast<double>(predicts_) : 0.0;
  const Eigen::Vector3d p = filter_->pose();
  out["final_x"] = p[0];
  out["final_y"] = p[1];
  out["final_theta"] = p[2];

  if (options_.ground_truth && !estimate_.empty() && !truth_.empty()) {
    std::vector<tessera::mapping::TumPose> est, ref;
    for (const auto& [t, pose] : estimate_)
      est.push_back(tessera::mapping::TumPose::fromPlanar(t, pose));
    for (const auto& [t, pose] : truth_)
      ref.push_back(tessera::mapping::TumPose::fromPlanar(t, pose));
    try {
      const auto ate = tessera::evaluation::computeAte(est, ref);
      out["ate_rmse_m"] = ate.translation.rmse;
      out["ate_max_m"] = ate.translation.max;
      out["ate_pairs"] = static_cast<std::int64_t>(ate.pairs);
    } catch (const tessera::evaluation::MetricError& e) {
      out["ate_error"] = std::string(e.what());
    }
  }
  if (options_.landmark_truth && !landmark_truth_.empty() && filter_->landmarkCount() > 0) {
    std::vector<tessera::evaluation::Landmark> est, ref;
    for (const auto& l : filter_->landmarks()) est.push_back({l.id, l.mean});
    for (const auto& [id, xy] : landmark_truth_) ref.push_back({id, xy});
    try {
      const auto le = tessera::evaluation::computeLandmarkError(est, ref);
      out["landmark_rmse_m"] = le.error.rmse;
      out["landmark_mean_m"] = le.error.mean;
      out["landmark_max_m"] = le.error.max;
      out["landmark_pairs"] = static_cast<std::int64_t>(le.pairs);
    } catch (const tessera::evaluation::MetricError& e) {
      out["landmark_error"] = std::string(e.what());
    }
  }
}

TESSERA_REGISTER_ACTOR("landmark_slam", LandmarkSlamActor, LandmarkSlamActorOptions,
                       "point-landmark SLAM: EKF-SLAM or the Rao-Blackwellised UKF/EKF filter");

}  // namespace tessera::landmark_slam

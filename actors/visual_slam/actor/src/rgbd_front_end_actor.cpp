// rgbd_front_end actor: msg::RgbdFrame -> Tracker -> camera poses and keyframe messages.
#include <tessera/visual_slam/rgbd_front_end_actor.hpp>

#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/messages/keyframe_poses.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/visual_slam/keyframe_message.hpp>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <iostream>
#include <stdexcept>

namespace tessera::visual_slam {
namespace {

/// A summary key for a skip reason: its leading words (the numbers after them vary per frame).
std::string reasonKey(const std::string& reason) {
  std::string key;
  for (const char c : reason) {
    if (std::isalpha(static_cast<unsigned char>(c)))
      key += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    else if (c == ' ' || c == '_' || c == '-')
      key += '_';
    else
      break;
  }
  while (!key.empty() && key.back() == '_') key.pop_back();
  return key.empty() ? "other" : key;
}

/// The image of a message as a Mat over its bytes (no copy), or "" / why not in `error`.
cv::Mat wrap(msg::Image::Reader im, int type, std::size_t bytes_per_pixel, std::string& error,
             const char* what) {
  const std::size_t w = im.getWidth(), h = im.getHeight(), step = im.getStep();
  if (w == 0 || h == 0) {
    error = std::string(what) + "_empty";
    return {};
  }
  if (step < w * bytes_per_pixel || im.getData().size() < h * step) {
    error = std::string(what) + "_data_short";
    return {};
  }
  // The tracker only reads the pixels; the message stays alive for the whole call.
  auto* data = const_cast<std::uint8_t*>(im.getData().begin());
  return cv::Mat(static_cast<int>(h), static_cast<int>(w), type, data, step);
}

Eigen::Isometry3d isometry(msg::Pose3D::Reader p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(p.getQw(), p.getQx(), p.getQy(), p.getQz())
                   .normalized()
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(p.getX(), p.getY(), p.getZ());
  return T;
}

msg::PoseStamped3D::TrackingStatus status(TrackingState s) {
  switch (s) {
    case TrackingState::kInitialised:
      return msg::PoseStamped3D::TrackingStatus::INITIALISED;
    case TrackingState::kTrackingPrevious:
      return msg::PoseStamped3D::TrackingStatus::TRACKING_PREVIOUS;
    case TrackingState::kRelocalised:
      return msg::PoseStamped3D::TrackingStatus::RELOCALISED;
    default:
      return msg::PoseStamped3D::TrackingStatus::TRACKING;
  }
}

mapping::TumPose tum(std::int64_t stamp, const Eigen::Isometry3d& T) {
  return {stamp, T.translation(), Eigen::Quaterniond(T.rotation())};
}

}  // namespace

RgbdFrontEndActor::RgbdFrontEndActor(RgbdFrontEndOptions options) : options_(std::move(options)) {
  try {
    options_.tracker.validate();
  } catch (const std::invalid_argument& e) {
    throw ConfigError(std::string("rgbd_front_end: ") + e.what());
  }
  if (options_.keyframe_depth_step < 0)
    throw ConfigError("rgbd_front_end: keyframe_depth_step must be >= 0");
  if (options_.world_frame.empty() || options_.frame_id.empty())
    throw ConfigError("rgbd_front_end: world_frame and frame_id must not be empty");
}

RgbdFrontEndActor::~RgbdFrontEndActor() = default;

void RgbdFrontEndActor::configure(ActorContext& ctx) {
  ctx.subscribe<msg::RgbdFrame>("rgbd", MailboxPolicy::keepLatest(1),
                                [this](const Message<msg::RgbdFrame>& m) { onFrame(m); });
  if (options_.forget_trimmed)
    ctx.subscribe<msg::KeyframePoses>("keyframe_poses", MailboxPolicy::keepLatest(1),
                                      [this](const Message<msg::KeyframePoses>& m) { onPoses(m); });
  pose_pub_ = ctx.advertise<msg::PoseStamped3D>("camera_pose");
  keyframe_pub_ = ctx.advertise<msg::Keyframe>("keyframes");
}

void RgbdFrontEndActor::onPoses(const Message<msg::KeyframePoses>& m) {
  if (!tracker_) return;
  // Keyframe ids are the tracker's indices. Only the keyframes it still holds are walked; those
  // too recent to forget yet are refused now and released by a later message.
  const KeptKeyframes kept(*m);
  std::vector<std::size_t> gone;
  for (const std::size_t id : tracker_->heldKeyframes())
    if (kept.leftGraph(id)) gone.push_back(id);
  for (const std::size_t id : gone) tracker_->forgetKeyframe(id);
}

void RgbdFrontEndActor::skip(const std::string& reason) {
  ++skipped_[reasonKey(reason)];
}

std::string RgbdFrontEndActor::setUp(msg::RgbdFrame::Reader f) {
  const auto in = f.getIntrinsics();
  depth_camera_ = {in.getFx(),
                   in.getFy(),
                   in.getCx(),
                   in.getCy(),
                   static_cast<int>(in.getWidth()),
                   static_cast<int>(in.getHeight())};
  try {
    depth_camera_.validate();
    calibration_ = depthRegistration(f.getColorRegistered(), options_.tracker.register_depth);
    tracker_ = std::make_unique<Tracker>(options_.tracker,
                                         calibration_ ? calibration_->color : depth_camera_);
  } catch (const std::invalid_argument& e) {
    std::cerr << "[rgbd_front_end] frame " << f.getFrameIndex() << ": " << e.what() << "\n";
    return "bad_intrinsics";
  }
  return "";
}

void RgbdFrontEndActor::onFrame(const Message<msg::RgbdFrame>& m) {
  ++frames_;
  const auto f = *m;
  if (!tracker_) {
    if (const std::string why = setUp(f); !why.empty()) return skip(why);
  }
  // Colour: rgb8 / bgr8 / mono8; depth: 16UC1 or 32FC1 (metres).
  std::string error;
  const std::string color_enc = f.getColor().getEncoding().cStr();
  cv::Mat image;
  if (color_enc == "rgb8" || color_enc == "bgr8")
    image = wrap(f.getColor(), CV_8UC3, 3, error, "color");
  else if (color_enc == "mono8")
    image = wrap(f.getColor(), CV_8UC1, 1, error, "color");
  else
    error = "color_encoding";
  if (!error.empty()) return skip(error);
  if (color_enc == "bgr8") cv::cvtColor(image, image, cv::COLOR_BGR2RGB);

  const std::string depth_enc = f.getDepth().getEncoding().cStr();
  cv::Mat depth;
  double depth_scale = f.getDepthScale();
  if (depth_enc == "16UC1") {
    depth = wrap(f.getDepth(), CV_16UC1, 2, error, "depth");
  } else if (depth_enc == "32FC1") {
    const cv::Mat metres = wrap(f.getDepth(), CV_32FC1, 4, error, "depth");
    if (error.empty()) {
      // Millimetres, NaN and negative readings to 0 (no reading).
      cv::Mat clean = metres.clone();
      cv::patchNaNs(clean, 0.0);
      clean.setTo(0.0f, clean < 0);
      clean.convertTo(depth, CV_16UC1, 1000.0);
      depth_scale = 1000.0;
    }
  } else {
    error = "depth_encoding";
  }
  if (!error.empty()) return skip(error);
  if (depth.size() != cv::Size(depth_camera_.width, depth_camera_.height))
    return skip("depth_size");
  if (calibration_) {
    try {
      depth = registerDepth(depth, depth_camera_, *calibration_);
    } catch (const std::invalid_argument&) {
      return skip("depth_registration");
    }
  }

  const std::int64_t stamp = f.getHeader().getStampNs();
  const TrackResult r = tracker_->track({image, depth, depth_scale, f.getDatasetTimeS()});
  if (r.state == TrackingState::kSkipped) return skip(r.skip_reason);
  ms_.push_back(r.timing.total_ms);
  split_sum_.extraction_ms += r.timing.extraction_ms;
  split_sum_.local_map_ms += r.timing.local_map_ms;
  split_sum_.matching_ms += r.timing.matching_ms;
  split_sum_.pnp_ms += r.timing.pnp_ms;
  split_sum_.local_ba_ms += r.timing.local_ba_ms;
  if (!r.pose_valid) return;  // lost: counted by the tracker

  const Eigen::Isometry3d camera =
      calibration_ ? r.camera_to_world * calibration_->color_from_depth : r.camera_to_world;
  {
    auto loan = pose_pub_.loan();
    setHeader(loan->initHeader(), stamp, options_.world_frame, pose_pub_.nextSeq());
    writePose(loan->initPose(),
              Pose3{camera.translation(), Eigen::Quaterniond(camera.rotation()).normalized()});
    loan->setChildFrameId(options_.frame_id.c_str());
    loan->setFrameIndex(f.getFrameIndex());
    loan->setStatus(status(r.state));
    pose_pub_.publish(std::move(loan));
    ++published_;
  }
  if (options_.keep_trajectory) estimate_.push_back({stamp, camera});
  if (options_.keep_trajectory && f.getHasGroundTruth()) {
    const Eigen::Isometry3d gt = isometry(f.getGroundTruth());
    if (gt.matrix().allFinite()) truth_.push_back({stamp, gt});
  }

  if (r.keyframe && !tracker_->keyframes().empty()) {
    KeyframeContent k;
    k.keyframe = &tracker_->keyframes().back();
    k.camera = calibration_ ? calibration_->color : depth_camera_;
    if (options_.keyframe_depth_step > 0) k.depth = depth;
    k.depth_scale = depth_scale;
    k.depth_step = options_.keyframe_depth_step;
    k.tracking_inliers = r.inliers;
    auto loan = keyframe_pub_.loan(keyframeSizeHint(k));
    setHeader(loan->initHeader(), stamp, options_.world_frame, keyframe_pub_.nextSeq());
    writeKeyframe(*loan, k);
    keyframe_pub_.publish(std::move(loan));
    ++keyframes_;
  }
}

void RgbdFrontEndActor::summarize(Summary& out) const {
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  out["frames"] = i64(frames_);
  out["poses_published"] = i64(published_);
  out["keyframes"] = i64(keyframes_);
  std::uint64_t skipped = 0;
  for (const auto& [reason, n] : skipped_) {
    out["skipped_" + reason] = i64(n);
    skipped += n;
  }
  out["skipped"] = i64(skipped);
  if (tracker_) {
    const TrackerStats& s = tracker_->stats();
    out["tracked_local_map"] = i64(s.tracked_local_map);
    out["tracked_previous"] = i64(s.tracked_previous);
    out["lost"] = i64(s.lost);
    out["relocalised"] = i64(s.relocalised);
    out["forced_keyframes"] = i64(s.forced_keyframes);
    out["local_ba_runs"] = i64(s.local_ba_runs);
    if (options_.forget_trimmed) out["keyframes_forgotten"] = i64(tracker_->forgottenKeyframes());
    out["depth_registered"] = std::int64_t{calibration_ ? 1 : 0};
  }
  if (!ms_.empty()) {
    std::vector<double> sorted = ms_;
    std::sort(sorted.begin(), sorted.end());
    const double n = static_cast<double>(ms_.size());
    double sum = 0;
    for (const double v : ms_) sum += v;
    out["ms_per_frame_mean"] = sum / n;
    out["ms_per_frame_p50"] = sorted[sorted.size() / 2];
    out["ms_per_frame_p95"] =
        sorted[std::min(sorted.size() - 1, static_cast<std::size_t>(std::ceil(0.95 * n)) - 1)];
    out["ms_extraction_mean"] = split_sum_.extraction_ms / n;
    out["ms_local_map_mean"] = split_sum_.local_map_ms / n;
    out["ms_matching_mean"] = split_sum_.matching_ms / n;
    out["ms_pnp_mean"] = split_sum_.pnp_ms / n;
    out["ms_local_ba_mean"] = split_sum_.local_ba_ms / n;
  }
  if (!truth_.empty() && !estimate_.empty()) {
    std::vector<mapping::TumPose> est, ref;
    for (const auto& e : estimate_) est.push_back(tum(e.stamp_ns, e.pose));
    for (const auto& t : truth_) ref.push_back(tum(t.stamp_ns, t.pose));
    try {
      evaluation::AteOptions o;
      o.dimension = evaluation::Dimension::kSpatial;
      const auto ate = evaluation::computeAte(est, ref, o);
      out["ate_rmse_m"] = ate.translation.rmse;
      out["ate_max_m"] = ate.translation.max;
      out["ate_pairs"] = static_cast<std::int64_t>(ate.pairs);
    } catch (const evaluation::MetricError& e) {
      out["ate_error"] = std::string(e.what());
    }
  }
}

TESSERA_REGISTER_ACTOR("rgbd_front_end", RgbdFrontEndActor, RgbdFrontEndOptions,
                       "RGB-D visual odometry: camera pose per frame and keyframes (ORB + PnP)");

}  // namespace tessera::visual_slam

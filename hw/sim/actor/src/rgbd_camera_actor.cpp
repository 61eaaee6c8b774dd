// The simulated RGB-D camera actor (see rgbd_camera_actor.hpp): renders on the robot's true pose
// at its frame rate and publishes msg::RgbdFrame and the camera's 3D ground truth.
#include <tessera/sim/rgbd_camera_actor.hpp>

#include <tessera/messages/geometry.hpp>
#include <tessera/runtime/registry.hpp>

#include "option_checks.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace tessera::sim {

namespace {

using detail::str;

constexpr detail::OptionErrors kErrors("rgbd_camera");

void setImage(msg::Image::Builder b, Nanos stamp, const std::string& frame, std::uint64_t seq,
              const RgbdImage& im, const char* encoding, std::size_t bytes_per_pixel) {
  setHeader(b.initHeader(), stamp, frame, seq);
  b.setWidth(static_cast<std::uint32_t>(im.width));
  b.setHeight(static_cast<std::uint32_t>(im.height));
  b.setEncoding(encoding);
  b.setStep(static_cast<std::uint32_t>(static_cast<std::size_t>(im.width) * bytes_per_pixel));
}

Pose3 toPose3(const Eigen::Isometry3d& T) {
  return {T.translation(), Eigen::Quaterniond(T.rotation()).normalized()};
}

}  // namespace

RgbdCameraActor::RgbdCameraActor(RgbdCameraOptions options)
    : options_(std::move(options)),
      world_(kErrors.loadWorld(options_.world, options_.world_resolution)) {
  const auto& o = options_;
  if (!(o.rate_hz > 0) || !std::isfinite(o.rate_hz) || o.rate_hz > 1000)
    kErrors.fail("rate_hz", "must be in (0, 1000], got " + str(o.rate_hz));
  if (o.depth == "float")
    float_depth_ = true;
  else if (o.depth != "uint16")
    kErrors.fail("depth", "is '" + o.depth + "', expected uint16 or float");
  if (o.frame_id.empty()) kErrors.fail("frame_id", "must not be empty");
  if (o.world_frame.empty()) kErrors.fail("world_frame", "must not be empty");
  kErrors.check(o.camera.check(), "camera");
  try {
    renderer_.emplace(world_, o.wall_height, o.camera);
  } catch (const std::invalid_argument& e) {
    // What the config check cannot see: the wall height, and the mount against it.
    const std::string what = e.what();
    kErrors.fail(what.find("mount.z") != std::string::npos ? "camera.mount.z" : "wall_height",
                 what);
  }
  noise_seed_ = detail::seededStream(o.seed, detail::NoiseStream::kRgbdCamera)();
}

void RgbdCameraActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  rgbd_pub_ = ctx.advertise<msg::RgbdFrame>("rgbd");
  gt_pub_ = ctx.advertise<msg::GroundTruthPose3D>("ground_truth_3d");
  ctx.subscribe<msg::GroundTruthPose>("ground_truth", MailboxPolicy::reliable(),
                                      [this](const Message<msg::GroundTruthPose>& m) {
                                        onPose(m->getHeader().getStampNs(), toPose2(m->getPose()));
                                      });
}

void RgbdCameraActor::onPose(Nanos stamp, const Pose2& base) {
  if (!first_stamp_) first_stamp_ = stamp;
  const auto due = [&](std::int64_t k) {
    return *first_stamp_ +
           static_cast<Nanos>(std::llround(static_cast<double>(k) * 1e9 / options_.rate_hz));
  };
  if (stamp < due(next_frame_)) return;
  while (due(next_frame_) <= stamp) ++next_frame_;  // a gap in poses skips frames, never bunches
  if (!allFinite(base)) return;                     // nothing to render from
  publish(stamp, renderer_->cameraPose(base));
}

void RgbdCameraActor::publish(Nanos stamp, const Eigen::Isometry3d& camera_to_world) {
  const auto t0 = std::chrono::steady_clock::now();
  renderer_->render(camera_to_world, noise_seed_ + static_cast<std::uint64_t>(frames_), image_);
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  render_ms_total_ += ms;
  render_ms_max_ = std::max(render_ms_max_, ms);

  const RgbdCameraConfig& c = options_.camera;
  const std::size_t pixels = image_.depth.size();
  const std::size_t depth_bpp = float_depth_ ? sizeof(float) : sizeof(std::uint16_t);
  auto loan = rgbd_pub_.loan(pixels * (3 + depth_bpp) + 1024);
  auto b = loan.builder();
  const std::uint64_t seq = rgbd_pub_.nextSeq();
  setHeader(b.initHeader(), stamp, options_.frame_id, seq);
  auto k = b.initIntrinsics();
  k.setFx(c.fx);
  k.setFy(c.fy);
  k.setCx(c.cx);
  k.setCy(c.cy);
  k.setWidth(static_cast<std::uint32_t>(c.width));
  k.setHeight(static_cast<std::uint32_t>(c.height));
  b.setDepthScale(float_depth_ ? 1.0 : 1000.0);
  b.setColorRegistered(true);
  b.setHasGroundTruth(true);
  const Pose3 truth = toPose3(camera_to_world);
  writePose(b.initGroundTruth(), truth);
  b.setDatasetTimeS(nanosToSeconds(stamp));
  b.setFrameIndex(static_cast<std::uint32_t>(frames_));
  // Small fields first, then the two pixel arrays, so they sit at the end of the segment.
  auto color = b.initColor();
  auto depth = b.initDepth();
  setImage(color, stamp, options_.frame_id, seq, image_, "rgb8", 3);
  setImage(depth, stamp, options_.frame_id, seq, image_, float_depth_ ? "32FC1" : "16UC1",
           depth_bpp);
  auto color_data = color.initData(static_cast<unsigned>(pixels * 3));
  std::memcpy(color_data.begin(), image_.rgb.data(), pixels * 3);
  auto depth_data = depth.initData(static_cast<unsigned>(pixels * depth_bpp));
  std::size_t valid = 0;
  if (float_depth_) {
    auto* out = reinterpret_cast<float*>(depth_data.begin());
    for (std::size_t i = 0; i < pixels; ++i) {
      const float z = image_.depth[i];
      valid += z > 0 ? 1 : 0;
      const float v = z > 0 ? z : std::numeric_limits<float>::quiet_NaN();
      std::memcpy(out + i, &v, sizeof v);
    }
  } else {
    auto* out = depth_data.begin();
    for (std::size_t i = 0; i < pixels; ++i) {
      const float z = image_.depth[i];
      valid += z > 0 ? 1 : 0;
      // Millimetres; depths beyond 65.535 m are not representable and are no reading.
      const long mm = std::lround(static_cast<double>(z) * 1000.0);
      const auto v = static_cast<std::uint16_t>(mm > 0 && mm <= 65535 ? mm : 0);
      std::memcpy(out + i * 2, &v, sizeof v);
    }
  }
  rgbd_pub_.publish(std::move(loan));
  valid_fraction_total_ +=
      pixels > 0 ? static_cast<double>(valid) / static_cast<double>(pixels) : 0;

  auto gt = gt_pub_.loan();
  setHeader(gt->initHeader(), stamp, options_.world_frame, gt_pub_.nextSeq());
  writePose(gt->initPose(), truth);
  gt->setChildFrameId(options_.frame_id);
  gt_pub_.publish(std::move(gt));
  ++frames_;
}

void RgbdCameraActor::summarize(Summary& out) const {
  const double n = frames_ > 0 ? static_cast<double>(frames_) : 1.0;
  out["frames_published"] = frames_;
  out["render_ms_mean"] = render_ms_total_ / n;
  out["render_ms_max"] = render_ms_max_;
  out["valid_depth_fraction"] = valid_fraction_total_ / n;
}

TESSERA_REGISTER_ACTOR("rgbd_camera", RgbdCameraActor, RgbdCameraOptions,
                       "simulated RGB-D camera: renders colour + depth of the 3D world (walls "
                       "extruded, furniture, textures, noise) from the robot's true pose");

}  // namespace tessera::sim

#include <tessera/io/atomic_file.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/sim/camera_network_actor.hpp>
#include <tessera/sim/robot.hpp>
#include <tessera/sim/world.hpp>

#include "option_checks.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace tessera::sim {

namespace {

using detail::str;

constexpr detail::OptionErrors kErrors("camera_network");

std::vector<CameraSite> sitesOf(const CameraNetworkOptions& o) {
  if (o.camera_sites.empty()) {
    const World w = kErrors.loadWorld(o.world, o.world_resolution);
    if (w.cameraSites().empty())
      kErrors.fail("camera_sites", "world '" + w.name() + "' has no cameras; give camera_sites");
    return w.cameraSites();
  }
  std::vector<CameraSite> sites;
  for (std::size_t i = 0; i < o.camera_sites.size(); ++i) {
    CameraSite site;
    site.id = static_cast<int>(i);
    site.position = {o.camera_sites[i][0], o.camera_sites[i][1]};
    if (!site.position.allFinite())
      kErrors.fail("camera_sites", "site " + str(i) + " is not finite");
    sites.push_back(site);
  }
  return sites;
}

/// Distance [m] from `p` to the convex polygon `poly` (counter-clockwise); 0 inside.
double distanceToPolygon(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& p) {
  bool inside = true;
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < poly.size(); ++i) {
    const Eigen::Vector2d& a = poly[i];
    const Eigen::Vector2d& b = poly[(i + 1) % poly.size()];
    const Eigen::Vector2d ab = b - a, ap = p - a;
    if (ab.x() * ap.y() - ab.y() * ap.x() < 0) inside = false;  // right of a CCW edge
    const double len2 = ab.squaredNorm();
    const double t = len2 > 0 ? std::clamp(ap.dot(ab) / len2, 0.0, 1.0) : 0.0;
    best = std::min(best, (ap - t * ab).norm());
  }
  return inside ? 0.0 : best;
}

}  // namespace

CameraNetworkActor::CameraNetworkActor(CameraNetworkOptions options)
    : options_(std::move(options)),
      rng_(detail::seededStream(options_.seed, detail::NoiseStream::kCameras)),
      image_rng_(detail::seededStream(options_.seed, detail::NoiseStream::kCameraImages)) {
  const auto& o = options_;
  if (o.camera_hz <= 0) kErrors.fail("camera_hz", "must be positive, got " + str(o.camera_hz));
  period_ = kNanosPerSecond / o.camera_hz;
  if (o.marker.size() != 2)
    kErrors.fail("marker", "needs 2 values [x, y], got " + str(o.marker.size()));
  if (!std::isfinite(o.marker[0]) || !std::isfinite(o.marker[1]))
    kErrors.fail("marker", "not finite");
  if (!std::isfinite(o.footprint_period_s) || o.footprint_period_s < 0)
    kErrors.fail("footprint_period_s",
                 "must be finite and >= 0 (0 = only once), got " + str(o.footprint_period_s));
  kErrors.check(o.camera.check(), "camera");
  if (!std::isfinite(o.image_margin_m) || o.image_margin_m < 0)
    kErrors.fail("image_margin_m", "must be finite and >= 0, got " + str(o.image_margin_m));
  kErrors.check(o.image.check(), "image");
  try {
    network_.emplace(sitesOf(o), o.camera);
  } catch (const std::invalid_argument& e) {
    kErrors.fail("camera_sites", e.what());
  }
  if (o.render_images) {
    for (const EnvironmentCamera& cam : network_->cameras()) {
      renderers_.emplace_back(cam, o.image);  // the camera's floor, rendered once
      footprints_.push_back(
          cam.footprintPolygon(kFootprintRange * cam.intrinsics().ceiling_height));
    }
  }
}

void CameraNetworkActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  if (options_.publish_detections) {
    event_pub_ = ctx.advertise<msg::CameraEvent>("camera_events");
    detection_pub_ = ctx.advertise<msg::MarkerDetection>("camera_detections");
  }
  if (options_.render_images) image_pub_ = ctx.advertise<msg::Image>("camera_images");
  footprint_pub_ = ctx.advertise<msg::CameraFootprints>("camera_footprints");
  if (options_.footprint_period_s > 0) {
    // At most ~30 years: a huge period must not overflow the nanoseconds.
    const auto period =
        std::max<Nanos>(1, static_cast<Nanos>(std::min(options_.footprint_period_s, 1e9) * 1e9));
    ctx.addTimer(
        period,
        [this] {
          if (footprints_started_) publishFootprints();
        },
        period);
  }
  ctx.subscribe<msg::GroundTruthPose>(
      "ground_truth", MailboxPolicy::reliable(), [this](const Message<msg::GroundTruthPose>& m) {
        const auto p = m->getPose();
        onPose(m->getHeader().getStampNs(), p.getX(), p.getY(), p.getTheta());
      });
}

void CameraNetworkActor::start() {
  if (options_.cameras_file.empty() || ctx_->outputDir().empty()) return;
  const auto path = std::filesystem::path(ctx_->outputDir()) / options_.cameras_file;
  std::ostringstream out;
  out << std::setprecision(12)
      << "# true cameras: floor point below the camera [m], yaw/roll/pitch [rad], image size "
         "[px], floor->pixel homography (row-major, scaled so the site maps with w = 1)\n"
      << "# id x y yaw roll pitch width height h00 h01 h02 h10 h11 h12 h20 h21 h22\n";
  for (const auto& cam : network_->cameras()) {
    const auto& s = cam.site();
    out << s.id << ' ' << s.position.x() << ' ' << s.position.y() << ' ' << s.yaw << ' ' << s.roll
        << ' ' << s.pitch << ' ' << cam.intrinsics().width_px << ' ' << cam.intrinsics().height_px;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) out << ' ' << cam.homography()(r, c);
    out << '\n';
  }
  try {
    tessera::io::writeFileAtomically(path, out.str());  // the old file or the new one, whole
  } catch (const tessera::io::FileWriteError& e) {
    throw std::runtime_error(std::string("camera_network: ") + e.what());
  }
}

void CameraNetworkActor::onPose(Nanos stamp, double x, double y, double theta) {
  if (!next_frame_) next_frame_ = (stamp + period_ - 1) / period_ * period_;  // first multiple
  if (stamp < *next_frame_) return;
  while (*next_frame_ <= stamp) *next_frame_ += period_;

  if (!footprints_started_) {
    footprints_started_ = true;
    publishFootprints();
  }
  const Pose2 marker = compose({x, y, theta}, {options_.marker[0], options_.marker[1], 0});
  ++frames_;
  if (options_.publish_detections) publishDetections(stamp, marker);
  if (options_.render_images) publishImages(stamp, marker);
}

void CameraNetworkActor::publishDetections(Nanos stamp, const Pose2& marker) {
  const CameraNetwork::Frame frame = network_->observe(marker.translation(), rng_);
  for (const CameraTransition& t : frame.transitions) {
    auto loan = event_pub_.loan();
    auto b = loan.builder();
    setHeader(b.initHeader(), stamp, "camera_" + std::to_string(t.camera_id), event_pub_.nextSeq());
    b.setCameraId(t.camera_id);
    b.setEntered(t.entered);
    event_pub_.publish(std::move(loan));
    ++events_;
  }
  for (const MarkerReport& r : frame.reports) {
    auto loan = detection_pub_.loan();
    auto b = loan.builder();
    setHeader(b.initHeader(), stamp, "camera_" + std::to_string(r.camera_id),
              detection_pub_.nextSeq());
    b.setCameraId(r.camera_id);
    b.setDetected(r.detected);
    if (r.detected) {
      b.setU(r.pixel.x());
      b.setV(r.pixel.y());
      ++detections_;
    } else {
      ++misses_;
    }
    b.setPixelStd(options_.camera.pixel_noise);
    detection_pub_.publish(std::move(loan));
  }
}

void CameraNetworkActor::publishImages(Nanos stamp, const Pose2& marker) {
  if (!allFinite(marker)) return;  // nothing to render
  for (std::size_t i = 0; i < renderers_.size(); ++i) {
    if (distanceToPolygon(footprints_[i], marker.translation()) > options_.image_margin_m) continue;
    CameraImageRenderer& renderer = renderers_[i];
    const int w = renderer.camera().intrinsics().width_px;
    const int h = renderer.camera().intrinsics().height_px;
    const std::size_t bytes = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
    // The pixels go in a blob: the renderer writes every one, in place.
    auto loan = image_pub_.loanWithBlob(bytes, 256);
    auto b = loan.builder();
    setHeader(b.initHeader(), stamp, "camera_" + std::to_string(renderer.camera().id()),
              image_pub_.nextSeq());
    b.setWidth(static_cast<std::uint32_t>(w));
    b.setHeight(static_cast<std::uint32_t>(h));
    b.setEncoding("mono8");
    b.setStep(static_cast<std::uint32_t>(w));
    cv::Mat pixels(h, w, CV_8UC1, loan.blob().data());
    const auto t0 = std::chrono::steady_clock::now();
    renderer.render(marker, image_rng_, pixels);
    render_ms_total_ +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    b.adoptData(loan.blobData());
    image_pub_.publish(std::move(loan));
    ++images_;
  }
}

void CameraNetworkActor::publishFootprints() {
  const auto& cameras = network_->cameras();
  auto loan = footprint_pub_.loan(256 + 128 * cameras.size());
  auto b = loan.builder();
  setHeader(b.initHeader(), ctx_->now(), "map", footprint_pub_.nextSeq());
  auto list = b.initCameras(static_cast<unsigned>(cameras.size()));
  for (unsigned i = 0; i < cameras.size(); ++i) {
    const EnvironmentCamera& cam = cameras[i];
    const auto polygon = cam.footprintPolygon(kFootprintRange * cam.intrinsics().ceiling_height);
    list[i].setCameraId(cam.id());
    list[i].setCalibrated(false);  // the true cameras
    auto xy = list[i].initXy(static_cast<unsigned>(2 * polygon.size()));
    for (unsigned k = 0; k < polygon.size(); ++k) {
      xy.set(2 * k, polygon[k].x());
      xy.set(2 * k + 1, polygon[k].y());
    }
  }
  footprint_pub_.publish(std::move(loan));
  ++footprint_messages_;
}

void CameraNetworkActor::summarize(Summary& out) const {
  out["camera_count"] = static_cast<std::int64_t>(network_->cameras().size());
  out["frames"] = frames_;
  out["detections"] = detections_;
  out["misses"] = misses_;
  out["events"] = events_;
  out["footprint_messages"] = footprint_messages_;
  if (options_.render_images) {
    out["images"] = images_;
    out["image_render_ms_mean"] = images_ > 0 ? render_ms_total_ / static_cast<double>(images_) : 0;
  }
}

TESSERA_REGISTER_ACTOR("camera_network", CameraNetworkActor, CameraNetworkOptions,
                       "ceiling camera network (seed 000): marker pixels through floor "
                       "homographies, misses, enter/leave events, from ground-truth poses; "
                       "optionally each camera's rendered image of the robot's ArUco marker");

}  // namespace tessera::sim

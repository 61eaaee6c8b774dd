#include <tessera/players/rgbd_player.hpp>

#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <sstream>

namespace tessera::players {

namespace {

[[noreturn]] void fail(const std::string& key, const std::string& what) {
  throw ConfigError("rgbd_player: option '" + key + "': " + what);
}

template <typename T>
std::string str(const T& v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

datasets::RgbdSequence readSequence(const RgbdPlayerOptions& o) {
  if (o.path.empty()) fail("path", "is required: the dataset folder (e.g. --set player.path=DIR)");
  datasets::RgbdReadOptions read;
  if (o.layout != "auto") {
    try {
      read.layout = datasets::parseLayout(o.layout);
    } catch (const std::invalid_argument& e) {
      fail("layout", std::string(e.what()) + " (or auto)");
    }
  }
  read.tum.max_time_difference = o.max_time_difference;
  read.tum.use_associations_file = o.use_associations_file;
  read.tum.camera = o.camera;
  read.seven_scenes.fps = o.fps;
  try {
    return datasets::readRgbdSequence(o.path, read);
  } catch (const io::DatasetError& e) {
    fail("path", e.what());
  }
}

void writeIntrinsics(msg::CameraIntrinsics::Builder b, const datasets::CameraIntrinsics& k) {
  b.setFx(k.fx);
  b.setFy(k.fy);
  b.setCx(k.cx);
  b.setCy(k.cy);
  b.setWidth(static_cast<std::uint32_t>(k.width));
  b.setHeight(static_cast<std::uint32_t>(k.height));
  auto d = b.initDistortion(static_cast<unsigned>(k.distortion.size()));
  for (unsigned i = 0; i < k.distortion.size(); ++i) d.set(i, k.distortion[i]);
}

void writePose3D(msg::Pose3D::Builder b, const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond q(T.rotation());
  b.setX(T.translation().x());
  b.setY(T.translation().y());
  b.setZ(T.translation().z());
  b.setQx(q.x());
  b.setQy(q.y());
  b.setQz(q.z());
  b.setQw(q.w());
}

void initImage(msg::Image::Builder b, Nanos stamp, const std::string& frame, std::uint64_t seq,
               int width, int height, const char* encoding, std::size_t bytes_per_pixel) {
  setHeader(b.initHeader(), stamp, frame, seq);
  b.setWidth(static_cast<std::uint32_t>(width));
  b.setHeight(static_cast<std::uint32_t>(height));
  b.setEncoding(encoding);
  b.setStep(static_cast<std::uint32_t>(static_cast<std::size_t>(width) * bytes_per_pixel));
}

}  // namespace

RgbdPlayerActor::RgbdPlayerActor(RgbdPlayerOptions options)
    : options_(std::move(options)), sequence_(readSequence(options_)) {
  const auto& o = options_;
  if (!(o.rate > 0) || !std::isfinite(o.rate)) fail("rate", "must be > 0, got " + str(o.rate));
  if (o.depth == "float")
    float_depth_ = true;
  else if (o.depth != "uint16")
    fail("depth", "is '" + o.depth + "', expected uint16 or float");
  const auto n = static_cast<std::int64_t>(sequence_.frames.size());
  if (o.first_frame < 0 || o.first_frame >= n)
    fail("first_frame", str(o.first_frame) + " is outside the sequence's " + str(n) + " frames");
  const std::int64_t last = o.last_frame < 0 ? n - 1 : o.last_frame;
  if (o.last_frame < -1 || last >= n || last < o.first_frame)
    fail("last_frame", str(o.last_frame) + " must be -1 or in [first_frame " + str(o.first_frame) +
                           ", " + str(n - 1) + "]");
  begin_ = next_ = static_cast<std::size_t>(o.first_frame);
  end_ = static_cast<std::size_t>(last) + 1;
  if (o.frame_id.empty()) fail("frame_id", "must not be empty");
  if (o.world_frame.empty()) fail("world_frame", "must not be empty");
}

Nanos RgbdPlayerActor::timeOf(std::size_t frame) const {
  const double dt =
      (sequence_.frames[frame].timestamp - sequence_.frames[begin_].timestamp) / options_.rate;
  return start_ + static_cast<Nanos>(std::llround(dt * 1e9));
}

void RgbdPlayerActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.declareFiniteSource();
  rgbd_pub_ = ctx.advertise<msg::RgbdFrame>("rgbd");
  // Advertised even without ground truth, so a profile that records it still wires up.
  gt_pub_ = ctx.advertise<msg::GroundTruthPose3D>("ground_truth");
  gt2d_pub_ = ctx.advertise<msg::GroundTruthPose>("ground_truth_2d");
  start_ = ctx.now();
  ctx.callAt(timeOf(next_), [this] { playNext(); });
}

void RgbdPlayerActor::playNext() {
  const std::size_t i = next_;
  const auto& frame = sequence_.frames[i];
  const Nanos stamp = timeOf(i);

  datasets::RgbdImages images;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    images = datasets::loadRgbdImages(sequence_, i);
  } catch (const std::exception& e) {
    error_ = "frame " + std::to_string(i) + ": " + e.what();
    ctx_->requestStop(error_);
    return;  // no further frames: the run stops with this reason
  }
  const double load_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  load_ms_total_ += load_ms;
  load_ms_max_ = std::max(load_ms_max_, load_ms);

  const std::size_t pixels =
      static_cast<std::size_t>(images.width) * static_cast<std::size_t>(images.height);
  const std::size_t depth_bpp = float_depth_ ? sizeof(float) : sizeof(std::uint16_t);
  auto loan = rgbd_pub_.loan(pixels * (3 + depth_bpp) + 1024);
  auto b = loan.builder();
  const std::uint64_t seq = rgbd_pub_.nextSeq();
  setHeader(b.initHeader(), stamp, options_.frame_id, seq);
  writeIntrinsics(b.initIntrinsics(), sequence_.intrinsics);
  b.setDepthScale(float_depth_ ? 1.0 : images.depth_scale);
  b.setColorRegistered(sequence_.color_registered);
  b.setHasGroundTruth(frame.pose.has_value());
  if (frame.pose) writePose3D(b.initGroundTruth(), *frame.pose);
  b.setDatasetTimeS(frame.timestamp);
  b.setDepthTimeOffsetS(frame.depth_timestamp - frame.timestamp);
  b.setFrameIndex(static_cast<std::uint32_t>(frame.index));
  // Small fields first, then the two pixel arrays, so they sit at the end of the segment.
  auto color = b.initColor();
  auto depth = b.initDepth();
  initImage(color, stamp, options_.frame_id, seq, images.width, images.height, "rgb8", 3);
  initImage(depth, stamp, options_.frame_id, seq, images.width, images.height,
            float_depth_ ? "32FC1" : "16UC1", depth_bpp);
  auto color_data = color.initData(static_cast<unsigned>(pixels * 3));
  std::memcpy(color_data.begin(), images.color.data(), pixels * 3);
  auto depth_data = depth.initData(static_cast<unsigned>(pixels * depth_bpp));
  if (float_depth_) {
    const std::vector<float> metres = datasets::depthInMetres(images);
    std::memcpy(depth_data.begin(), metres.data(), pixels * sizeof(float));
  } else {
    std::memcpy(depth_data.begin(), images.depth.data(), pixels * sizeof(std::uint16_t));
  }
  rgbd_pub_.publish(std::move(loan));
  ++frames_published_;

  if (frame.pose) {
    auto gt = gt_pub_.loan();
    setHeader(gt->initHeader(), stamp, options_.world_frame, gt_pub_.nextSeq());
    writePose3D(gt->initPose(), *frame.pose);
    gt->setChildFrameId(options_.frame_id);
    gt_pub_.publish(std::move(gt));

    const Eigen::Vector3d axis = frame.pose->rotation().col(2);  // optical axis in the world
    auto gt2 = gt2d_pub_.loan();
    setHeader(gt2->initHeader(), stamp, options_.world_frame, gt2d_pub_.nextSeq());
    writePose(gt2->initPose(),
              tessera::Pose2{frame.pose->translation().x(), frame.pose->translation().y(),
                             std::atan2(axis.y(), axis.x())});
    gt2->setChildFrameId(options_.frame_id);
    gt2d_pub_.publish(std::move(gt2));
    ++gt_published_;
  }

  ++next_;
  ctx_->reportProgress(static_cast<double>(next_ - begin_) / static_cast<double>(end_ - begin_));
  if (next_ == end_) {
    ctx_->finished();
    return;
  }
  ctx_->callAt(timeOf(next_), [this] { playNext(); });
}

void RgbdPlayerActor::summarize(Summary& out) const {
  out["layout"] = std::string(datasets::layoutName(sequence_.layout));
  out["frames_in_dataset"] = static_cast<std::int64_t>(sequence_.frames.size());
  out["frames_published"] = frames_published_;
  out["ground_truth_published"] = gt_published_;
  out["load_ms_mean"] = frames_published_ > 0 ? load_ms_total_ / frames_published_ : 0.0;
  out["load_ms_max"] = load_ms_max_;
  out["dataset_duration_s"] =
      sequence_.frames[end_ - 1].timestamp - sequence_.frames[begin_].timestamp;
  out["intrinsics_source"] = sequence_.intrinsics_source;
  if (!error_.empty()) out["error"] = error_;
}

TESSERA_REGISTER_ACTOR("rgbd_player", RgbdPlayerActor, RgbdPlayerOptions,
                       "replays a TUM RGB-D or 7-Scenes folder as RGB-D frames and ground truth");

}  // namespace tessera::players

// rgbd_mapper actor: keyframe messages -> per-keyframe clouds -> CloudMap + OctoMapBuilder; pose
// messages move the clouds and start a background OctoMap rebuild.
#include <tessera/mapping3d/rgbd_mapper_actor.hpp>

#include <tessera/messages/geometry.hpp>
#include <tessera/messages/keyframe_poses.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <exception>
#include <filesystem>
#include <functional>
#include <iostream>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

namespace tessera::mapping3d {
namespace {

// make() with a core's std::invalid_argument turned into a ConfigError naming the option group.
template <class Make>
auto configured(const char* group, Make&& make) {
  try {
    return make();
  } catch (const std::invalid_argument& e) {
    throw ConfigError(std::string("rgbd_mapper: ") + group + "." + e.what());
  }
}

// The pose of a message as camera-to-world, or nullopt when a field is not finite or the
// quaternion has no length (toPose3 would normalise it into NaN).
std::optional<Eigen::Isometry3d> readPose(msg::Pose3D::Reader p) {
  const double v[] = {p.getX(), p.getY(), p.getZ(), p.getQx(), p.getQy(), p.getQz(), p.getQw()};
  double qn = 0;
  for (int i = 0; i < 7; ++i) {
    if (!std::isfinite(v[i])) return std::nullopt;
    if (i >= 3) qn += v[i] * v[i];
  }
  if (qn < 1e-12) return std::nullopt;
  const Pose3 pose = toPose3(p);
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = pose.q.toRotationMatrix();
  t.translation() = pose.t;
  return t;
}

// What a keyframe message gives the cloud: its downsampled depth as a frame and the camera of
// that depth (the intrinsics divided by the step: sample (i, j) is pixel (i step, j step)).
struct KeyframeDepth {
  visual_slam::PinholeCamera camera;
  visual_slam::RgbdFrame frame;
};

// "" and `out` filled, or the kind of fault (a summary key).
std::string readDepth(msg::Keyframe::Reader m, KeyframeDepth& out) {
  const std::size_t w = m.getDepthWidth(), h = m.getDepthHeight(), step = m.getDepthStep();
  if (w == 0 || h == 0 || m.getDepth().size() == 0) return "no_depth";
  if (m.getDepth().size() != 2 * w * h || step == 0) return "depth_size";
  const auto in = m.getIntrinsics();
  // The block must be the one the intrinsics' image gives at this step.
  if ((in.getWidth() + step - 1) / step != w || (in.getHeight() + step - 1) / step != h)
    return "depth_size";
  const double s = static_cast<double>(step);
  out.camera = {in.getFx() / s, in.getFy() / s,      in.getCx() / s,
                in.getCy() / s, static_cast<int>(w), static_cast<int>(h)};
  try {
    out.camera.validate();
  } catch (const std::invalid_argument&) {
    return "intrinsics";
  }
  out.frame.depth.create(static_cast<int>(h), static_cast<int>(w), CV_16UC1);
  const std::uint8_t* bytes = m.getDepth().begin();
  for (std::size_t j = 0; j < h; ++j) {
    auto* row = out.frame.depth.ptr<std::uint16_t>(static_cast<int>(j));
    for (std::size_t i = 0; i < w; ++i, bytes += 2)  // little-endian, whatever the host
      row[i] = static_cast<std::uint16_t>(bytes[0] | (bytes[1] << 8));
  }
  out.frame.depth_scale = m.getDepthScale();
  if (!std::isfinite(out.frame.depth_scale) || out.frame.depth_scale <= 0) return "depth_scale";
  return "";
}

}  // namespace

// Runs each task on one thread of its own while the caller waits. The map's long-lived memory
// (keyframe clouds, octree nodes) is allocated there, so it sits in that thread's malloc arena
// instead of the executor threads' ones. There, it made the front end's per-frame image buffers
// page-fault every frame (glibc apparently releasing and re-mapping them): the front end's
// handler took 2.3 times as long on 7-Scenes with the mapper (docs/algorithms.md#rgb-d-maps).
class RgbdMapperActor::MapThread {
 public:
  MapThread() : thread_([this] { loop(); }) {}
  ~MapThread() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    changed_.notify_all();
    thread_.join();
  }
  MapThread(const MapThread&) = delete;
  MapThread& operator=(const MapThread&) = delete;

  /// Runs `task` there and returns when it is done; its exception is rethrown here.
  void run(const std::function<void()>& task) {
    std::exception_ptr error;
    std::unique_lock lock(mutex_);
    task_ = [&] {
      try {
        task();
      } catch (...) {
        error = std::current_exception();
      }
    };
    changed_.notify_all();
    changed_.wait(lock, [&] { return !task_; });
    if (error) std::rethrow_exception(error);
  }

 private:
  void loop() {
    std::unique_lock lock(mutex_);
    for (;;) {
      changed_.wait(lock, [&] { return stop_ || task_; });
      if (stop_) return;
      task_();
      task_ = nullptr;
      changed_.notify_all();
    }
  }

  std::mutex mutex_;
  std::condition_variable changed_;
  std::function<void()> task_;
  bool stop_ = false;
  std::thread thread_;  // last: starts once the members above exist
};

namespace {

double rotationAngle(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle();
}

}  // namespace

RgbdMapperActor::RgbdMapperActor(RgbdMapperOptions options)
    : options_(std::move(options)),
      cloud_map_(configured("map", [&] { return CloudMap(options_.map); })),
      octomap_(configured("octomap",
                          [&] { return std::make_unique<OctoMapBuilder>(options_.octomap); })),
      map_thread_(std::make_unique<MapThread>()) {
  configured("cloud", [&] {
    options_.cloud.validate();
    return 0;
  });
  if (!(std::isfinite(options_.move_threshold_m) && options_.move_threshold_m >= 0))
    throw ConfigError("rgbd_mapper: move_threshold_m must be finite and >= 0");
  if (!(std::isfinite(options_.move_threshold_rad) && options_.move_threshold_rad >= 0))
    throw ConfigError("rgbd_mapper: move_threshold_rad must be finite and >= 0");
  if (!(std::isfinite(options_.save_period_s) && options_.save_period_s >= 0))
    throw ConfigError("rgbd_mapper: save_period_s must be finite and >= 0");
  if (!(std::isfinite(options_.preview_period_s) && options_.preview_period_s >= 0))
    throw ConfigError("rgbd_mapper: preview_period_s must be finite and >= 0 (0 = off), got " +
                      std::to_string(options_.preview_period_s));
  if (options_.preview_max_points < 1)
    throw ConfigError("rgbd_mapper: preview_max_points must be >= 1, got " +
                      std::to_string(options_.preview_max_points));
}

// Waits for a running rebuild (OctoMapBuilder's destructor).
RgbdMapperActor::~RgbdMapperActor() = default;

void RgbdMapperActor::configure(ActorContext& ctx) {
  output_dir_ = ctx.outputDir();
  ctx_ = &ctx;
  cloud_pub_ = ctx.advertise<msg::PointCloud>("map_cloud");
  ctx.subscribe<msg::Keyframe>("keyframes", MailboxPolicy::reliable(),
                               [this](const Message<msg::Keyframe>& m) { onKeyframe(m); });
  ctx.subscribe<msg::KeyframePoses>("keyframe_poses", MailboxPolicy::reliable(),
                                    [this](const Message<msg::KeyframePoses>& m) { onPoses(m); });
  if (options_.save_period_s > 0 && !output_dir_.empty()) {
    const auto period = static_cast<Nanos>(options_.save_period_s * 1e9);
    ctx.addTimer(
        period, [this] { writeOutputs(); }, period);
  }
  if (options_.preview_period_s > 0) {
    // At most ~30 years: a huge period must not overflow the nanoseconds.
    const auto period =
        std::max<Nanos>(1, static_cast<Nanos>(std::min(options_.preview_period_s, 1e9) * 1e9));
    ctx.addTimer(
        period, [this] { publishPreview(); }, period);
  }
}

void RgbdMapperActor::bad(std::map<std::string, std::uint64_t>& counts, const std::string& what,
                          const std::string& why) {
  ++counts[why];
  std::cerr << "[rgbd_mapper] " << what << ": " << why << "; skipped\n";
}

void RgbdMapperActor::onKeyframe(const Message<msg::Keyframe>& m) {
  ++keyframes_;
  const std::uint64_t id = m->getId();
  const std::string what = "keyframe " + std::to_string(id);
  const auto pose = readPose(m->getPose());
  if (!pose) return bad(keyframes_bad_, what, "pose");
  if (cloud_map_.contains(id)) return bad(keyframes_bad_, what, "duplicate_id");
  KeyframeDepth depth;
  if (const std::string why = readDepth(*m, depth); !why.empty())
    return bad(keyframes_bad_, what, why);
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  auto t1 = t0;
  try {
    map_thread_->run([&] {
      // Placed at the pose it arrives with: the graph's poses for it come after it.
      cloud_map_.setKeyframe(id, makeKeyframeCloud(depth.camera, depth.frame, options_.cloud),
                             *pose);
      t1 = Clock::now();
      octomap_->insert(*cloud_map_.keyframe(id).cloud, *pose);
    });
  } catch (const std::invalid_argument& e) {
    return bad(keyframes_bad_, what + " (" + e.what() + ")", "cloud");
  }
  const auto ms = [](Clock::duration d) {
    return std::chrono::duration<double, std::milli>(d).count();
  };
  cloud_ms_total_ += ms(t1 - t0);
  insert_ms_total_ += ms(Clock::now() - t1);
  insert_ms_max_ = std::max(insert_ms_max_, ms(Clock::now() - t0));
  ++mapped_;
  if (const auto frame = m->getHeader().getFrameId(); frame.size() > 0) world_frame_ = frame.cStr();
  // Kept in the map (its pose may still move) but counted: no reading in range.
  if (cloud_map_.keyframe(id).cloud->empty()) ++empty_clouds_;
}

void RgbdMapperActor::onPoses(const Message<msg::KeyframePoses>& m) {
  ++pose_messages_;
  std::vector<std::pair<std::uint64_t, Eigen::Isometry3d>> valid;
  bool moved = false;
  for (const auto entry : m->getPoses()) {
    const std::uint64_t id = entry.getId();
    const std::string what = "pose of keyframe " + std::to_string(id);
    const auto pose = readPose(entry.getPose());
    if (!pose) {
      bad(poses_bad_, what, "pose");
      continue;
    }
    if (!cloud_map_.contains(id)) {
      bad(poses_bad_, what, "unknown_id");
      continue;
    }
    const Eigen::Isometry3d& now = cloud_map_.keyframe(id).camera_to_world;
    moved = moved || (now.translation() - pose->translation()).norm() > options_.move_threshold_m ||
            rotationAngle(now, *pose) > options_.move_threshold_rad;
    valid.emplace_back(id, *pose);
  }
  // Keyframes the graph no longer holds (lifelong mode trimmed them, KeptKeyframes): the cloud
  // goes, and the OctoMap is rebuilt without it.
  const KeptKeyframes kept(*m);
  for (const std::uint64_t id : cloud_map_.ids()) {
    if (!kept.leftGraph(id)) continue;
    cloud_map_.removeKeyframe(id);
    ++keyframes_dropped_;
    moved = true;
  }
  // Below the threshold nothing changes (a rebuild re-inserts every keyframe); above it every
  // pose of the message is applied, so small corrections are not lost either.
  if (!moved) return;
  for (const auto& [id, pose] : valid) {
    const Eigen::Isometry3d& now = cloud_map_.keyframe(id).camera_to_world;
    if (!now.isApprox(pose, 1e-12)) ++keyframes_moved_;
    cloud_map_.setPose(id, pose);
  }
  octomap_->rebuild(cloud_map_.snapshot());
  ++rebuilds_;
}

void RgbdMapperActor::stop() {
  const auto t0 = std::chrono::steady_clock::now();
  octomap_->waitForRebuild();
  stop_wait_ms_ =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (!output_dir_.empty()) writeOutputs();
  if (options_.preview_period_s > 0) publishPreview();  // the map as it ends, if it changed
}

void RgbdMapperActor::publishPreview() {
  // Nothing inserted since the last preview (or at all): nothing to send.
  const std::uint64_t revision = octomap_->revision();
  if (revision == previewed_revision_) return;
  const auto t0 = std::chrono::steady_clock::now();
  const OccupiedVoxels voxels =
      octomap_->occupiedVoxels(static_cast<std::size_t>(options_.preview_max_points));
  previewed_revision_ = voxels.revision;
  const std::size_t n = voxels.centres.size();
  // x, y, z as little-endian float32 whatever the host, written once into the loan's blob.
  auto loan = n > 0 ? cloud_pub_.loanWithBlob(12 * n, 256) : cloud_pub_.loan(256);
  setHeader(loan->initHeader(), ctx_->now(), world_frame_, cloud_pub_.nextSeq());
  loan->setCount(static_cast<std::uint32_t>(n));
  loan->setVoxelSize(static_cast<float>(voxels.voxel_size));
  if (n > 0) {
    auto* out = reinterpret_cast<std::uint8_t*>(loan.blob().data());
    for (const Eigen::Vector3f& p : voxels.centres)
      for (int k = 0; k < 3; ++k) {
        const auto bits = std::bit_cast<std::uint32_t>(p[k]);
        for (int b = 0; b < 4; ++b) *out++ = static_cast<std::uint8_t>(bits >> (8 * b));
      }
    loan->adoptXyz(loan.blobData());
  }
  cloud_pub_.publish(std::move(loan));
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  ++previews_;
  preview_points_ = n;
  preview_voxel_m_ = voxels.voxel_size;
  preview_ms_total_ += ms;
  preview_ms_max_ = std::max(preview_ms_max_, ms);
}

void RgbdMapperActor::writeOutputs() {
  // Must not throw (stop(), timers): a failed write is logged and reported in the summary.
  if (cloud_map_.keyframeCount() == 0) return;
  const std::filesystem::path dir(output_dir_);
  const auto t0 = std::chrono::steady_clock::now();
  try {
    // Assembled (every keyframe moved and voxel-filtered) once for both files.
    PointCloud cloud;
    if (!options_.pcd_file.empty() || !options_.ply_file.empty())
      map_thread_->run([&] { cloud = cloud_map_.assemble(); });
    assembled_points_ = cloud.size();
    assemble_ms_ =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    if (!options_.pcd_file.empty()) {
      writePcd(cloud, dir / options_.pcd_file);
      pcd_path_ = (dir / options_.pcd_file).string();
    }
    if (!options_.ply_file.empty()) {
      writePly(cloud, dir / options_.ply_file);
      ply_path_ = (dir / options_.ply_file).string();
    }
    if (!options_.octomap_file.empty()) {
      octomap_->writeBinary(dir / options_.octomap_file);
      octomap_path_ = (dir / options_.octomap_file).string();
    }
    ++saves_;
    write_ms_ =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  } catch (const std::exception& e) {
    write_error_ = e.what();
    std::cerr << "[rgbd_mapper] " << write_error_ << "\n";
  }
}

void RgbdMapperActor::summarize(Summary& out) const {
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  out["keyframes_received"] = i64(keyframes_);
  out["keyframes_mapped"] = i64(mapped_);
  // `prefix` = the total, `prefix`_<kind> = each kind's count.
  const auto counts = [&](const std::string& prefix,
                          const std::map<std::string, std::uint64_t>& m) {
    std::uint64_t total = 0;
    for (const auto& [why, n] : m) {
      out[prefix + "_" + why] = i64(n);
      total += n;
    }
    out[prefix] = i64(total);
  };
  counts("keyframes_bad", keyframes_bad_);
  out["keyframes_empty"] = i64(empty_clouds_);
  if (keyframes_dropped_ > 0) out["keyframes_dropped"] = i64(keyframes_dropped_);
  out["keyframes_held"] = i64(cloud_map_.keyframeCount());
  out["points"] = i64(cloud_map_.pointCount());
  const OctoMapStats s = octomap_->stats();
  out["octomap_leaves"] = i64(s.leaves);
  out["octomap_occupied"] = i64(s.occupied_leaves);
  out["octomap_memory_mib"] = static_cast<double>(s.memory_bytes) / (1024.0 * 1024.0);
  out["pose_messages"] = i64(pose_messages_);
  counts("poses_bad", poses_bad_);
  out["keyframes_moved"] = i64(keyframes_moved_);
  out["rebuilds"] = i64(rebuilds_);
  out["rebuilds_completed"] = i64(s.rebuilds_completed);
  out["rebuilds_abandoned"] = i64(s.rebuilds_abandoned);  // at stop, for newer poses
  out["stop_rebuild_wait_ms"] = stop_wait_ms_;            // stop() waiting for the last rebuild
  // Per mapped keyframe: the cloud (back-projection, voxel filter) and the OctoMap
  // insertion; max is of both together.
  const double n = mapped_ > 0 ? static_cast<double>(mapped_) : 1.0;
  out["cloud_ms_mean"] = cloud_ms_total_ / n;
  out["octomap_insert_ms_mean"] = insert_ms_total_ / n;
  out["keyframe_ms_mean"] = (cloud_ms_total_ + insert_ms_total_) / n;
  out["keyframe_ms_max"] = insert_ms_max_;
  out["keyframe_ms_total"] = cloud_ms_total_ + insert_ms_total_;
  if (saves_ > 0) {
    out["saves"] = i64(saves_);
    out["assembled_points"] = i64(assembled_points_);
    out["write_ms"] = write_ms_;  // the last save
    out["assemble_ms"] = assemble_ms_;
  }
  if (previews_ > 0) {
    out["previews"] = i64(previews_);              // map_cloud messages
    out["preview_points"] = i64(preview_points_);  // the last one's
    out["preview_voxel_m"] = preview_voxel_m_;
    out["preview_ms_mean"] = preview_ms_total_ / static_cast<double>(previews_);
    out["preview_ms_max"] = preview_ms_max_;
  }
  if (!pcd_path_.empty()) out["pcd_path"] = pcd_path_;
  if (!ply_path_.empty()) out["ply_path"] = ply_path_;
  if (!octomap_path_.empty()) out["octomap_path"] = octomap_path_;
  if (!write_error_.empty()) out["write_error"] = write_error_;
}

TESSERA_REGISTER_ACTOR("rgbd_mapper", RgbdMapperActor, RgbdMapperOptions,
                       "RGB-D keyframes -> point-cloud map (PCD/PLY) and OctoMap (.bt)");

}  // namespace tessera::mapping3d

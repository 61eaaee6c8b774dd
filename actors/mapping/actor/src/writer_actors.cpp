#include <tessera/mapping/writer_actors.hpp>

#include <tessera/actor_common/pose_source.hpp>

#include <tessera/msg/image.capnp.h>
#include <tessera/actor_common/map_message.hpp>
#include <tessera/mapping/map_io.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>

#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>

namespace tessera::mapping {
namespace fs = std::filesystem;

// ---- map_writer ----

MapWriterActor::MapWriterActor(MapWriterOptions options) : options_(std::move(options)) {
  if (options_.basename.empty()) throw ConfigError("map_writer: basename must not be empty");
  if (!(0 <= options_.free_thresh && options_.free_thresh < options_.occupied_thresh &&
        options_.occupied_thresh <= 1))
    throw ConfigError(
        "map_writer: thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1");
}

void MapWriterActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.subscribe<msg::OccupancyGrid>("map", MailboxPolicy::keepLatest(1),
                                    [this](const Message<msg::OccupancyGrid>& m) {
                                      latest_ = m;  // shares the bytes, no copy
                                      ++maps_received_;
                                    });
}

void MapWriterActor::stop() {
  if (ctx_->outputDir().empty()) return;
  if (!latest_) {
    std::cerr << ctx_->name() << ": no map received, nothing written\n";
    return;
  }
  // stop() must not throw (the run still has to stop the other actors and write its summary):
  // report the failure instead.
  try {
    const tessera::grid::OccupancyMap map = toOccupancyMap(*latest_);
    if (map.empty()) {
      std::cerr << ctx_->name() << ": the last map is empty, nothing written\n";
      return;
    }
    tessera::mapping::MapSaveOptions save;
    save.occupied_thresh = options_.occupied_thresh;
    save.free_thresh = options_.free_thresh;
    save.write_png = options_.png;
    const auto saved =
        tessera::mapping::saveMap(map, fs::path(ctx_->outputDir()) / options_.basename, save);
    map_path_ = saved.yaml.string();
    std::cerr << "wrote map: " << map_path_ << " (" << map.width << "x" << map.height << " cells, "
              << map.resolution << " m)\n";
  } catch (const std::exception& e) {
    error_ = e.what();
    std::cerr << ctx_->name() << ": failed to write the map: " << error_ << "\n";
  }
}

void MapWriterActor::summarize(Summary& out) const {
  out["map_path"] = map_path_;
  out["maps_received"] = static_cast<std::int64_t>(maps_received_);
  if (!error_.empty()) out["error"] = error_;
}

TESSERA_REGISTER_ACTOR("map_writer", MapWriterActor, MapWriterOptions,
                       "writes the last occupancy grid as PGM + YAML (map_server) and PNG");

// ---- trajectory_writer ----

namespace {
// 3D poses (RGB-D ground truth, visual odometry's estimates) are written as they are; every other
// type goes through the planar pose subscriptions shared with the mapper.
constexpr const char* kGroundTruth3dMessage = "ground_truth_3d";
constexpr const char* kPose3dMessage = "pose_3d";

bool is3d(const std::string& message) {
  return message == kGroundTruth3dMessage || message == kPose3dMessage;
}

tessera::mapping::TumPose tumPose(std::int64_t stamp_ns, msg::Pose3D::Reader p) {
  tessera::mapping::TumPose pose;
  pose.stamp_ns = stamp_ns;
  pose.position = {p.getX(), p.getY(), p.getZ()};
  pose.orientation = Eigen::Quaterniond(p.getQw(), p.getQx(), p.getQy(), p.getQz()).normalized();
  return pose;
}
}  // namespace

TrajectoryWriterActor::TrajectoryWriterActor(TrajectoryWriterOptions options)
    : options_(std::move(options)) {
  if (!is3d(options_.message))
    (void)parsePoseMessage(options_.message, "trajectory_writer", "message");
  if (options_.file.empty()) throw ConfigError("trajectory_writer: file must not be empty");
}

TrajectoryWriterActor::~TrajectoryWriterActor() = default;

void TrajectoryWriterActor::write3d(const tessera::mapping::TumPose& pose) {
  if (!writer_) return;
  writer_->write(pose);
  if (++poses_written_ % 256 == 0) writer_->flush();
}

void TrajectoryWriterActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  if (options_.message == kGroundTruth3dMessage) {
    ctx.subscribe<msg::GroundTruthPose3D>(
        "poses", MailboxPolicy::reliable(), [this](const Message<msg::GroundTruthPose3D>& m) {
          write3d(tumPose(m->getHeader().getStampNs(), m->getPose()));
        });
    return;
  }
  if (options_.message == kPose3dMessage) {
    ctx.subscribe<msg::PoseStamped3D>("poses", MailboxPolicy::reliable(),
                                      [this](const Message<msg::PoseStamped3D>& m) {
                                        write3d(tumPose(m->getHeader().getStampNs(), m->getPose()));
                                      });
    return;
  }
  subscribePoses(ctx, "poses", MailboxPolicy::reliable(),
                 parsePoseMessage(options_.message, "trajectory_writer", "message"),
                 [this](Nanos stamp, const tessera::Pose2& pose) {
                   if (!writer_) return;
                   writer_->write(stamp, pose);
                   // The file is completed at stop(); flushing now and then as well bounds
                   // what a crash (rather than a clean Ctrl-C) could lose: the poses are then
                   // in the temporary file next to it.
                   if (++poses_written_ % 256 == 0) writer_->flush();
                 });
}

void TrajectoryWriterActor::start() {
  if (ctx_->outputDir().empty()) return;
  const fs::path path = fs::path(ctx_->outputDir()) / options_.file;
  writer_ = std::make_unique<tessera::mapping::TumWriter>(path);  // throws naming the path
  path_ = path.string();
}

void TrajectoryWriterActor::stop() {
  if (!writer_) return;
  // Until here the poses went to a temporary file; close() renames it over the trajectory file,
  // so that file is either the complete trajectory or (a failed write) the previous one.
  try {
    writer_->close();
  } catch (const std::exception& e) {
    error_ = e.what();
    std::cerr << ctx_->name() << ": " << error_ << "\n";
  }
  writer_.reset();
}

void TrajectoryWriterActor::summarize(Summary& out) const {
  out["trajectory_path"] = path_;
  out["poses_written"] = static_cast<std::int64_t>(poses_written_);
  if (!error_.empty()) out["error"] = error_;
}

TESSERA_REGISTER_ACTOR("trajectory_writer", TrajectoryWriterActor, TrajectoryWriterOptions,
                       "streams a pose topic to a TUM trajectory file");

}  // namespace tessera::mapping

#include <tessera/laser_slam/map_assembler_actor.hpp>

#include <tessera/messages/views.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/periodic.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iostream>
#include <stdexcept>

namespace tessera::laser_slam {
namespace {

MapAssembler checkedAssembler(const MapAssemblerOptions& o) {
  if (!(std::isfinite(o.publish_period_s) && o.publish_period_s >= 0))
    throw ConfigError("map_assembler: publish_period_s must be >= 0");
  if (o.frame_id.empty()) throw ConfigError("map_assembler: frame_id must not be empty");
  try {
    return MapAssembler(o.resolution);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(e.what());
  }
}

}  // namespace

MapAssemblerActor::MapAssemblerActor(MapAssemblerOptions options)
    : options_(std::move(options)), assembler_(checkedAssembler(options_)) {}

void MapAssemblerActor::configure(ActorContext& ctx) {
  ctx.subscribe<msg::Submap>("submaps", MailboxPolicy::reliable(),
                             [this](const Message<msg::Submap>& m) { onSubmap(m); });
  ctx.subscribe<msg::SubmapConstraint>(
      "constraints", MailboxPolicy::reliable(),
      [this](const Message<msg::SubmapConstraint>& m) { onConstraint(m); });
  if (options_.optimized_poses)
    ctx.subscribe<msg::SubmapPoses>(
        "submap_poses", MailboxPolicy::keepLatest(1),
        [this](const Message<msg::SubmapPoses>& m) { onOptimizedPoses(m); });
  map_pub_ = ctx.advertise<msg::OccupancyGrid>("map");
  addPeriodicTimer(ctx, options_.publish_period_s, [this] {
    if (dirty_) publishMap();
  });
}

void MapAssemblerActor::onSubmap(const Message<msg::Submap>& m) {
  const int id = static_cast<int>(m->getId());
  const auto g = m->getGrid();
  tessera::grid::OccupancyMap grid;
  grid.resolution = g.getResolution();
  grid.width = static_cast<int>(g.getWidth());
  grid.height = static_cast<int>(g.getHeight());
  grid.origin = toPose2(g.getOrigin());
  const auto cells = viewInt8(g.getCells());
  grid.cells.assign(cells.begin(), cells.end());
  const tessera::Pose2 global = toPose2(m->getGlobalPose());
  try {
    if (!global.isFinite())
      throw std::invalid_argument("map_assembler: submap " + std::to_string(id) +
                                  " has a non-finite global pose");
    assembler_.setSubmap(id, std::move(grid));
  } catch (const std::invalid_argument& e) {
    // A malformed submap is reported and left out; the rest of the map is still drawn.
    std::cerr << "[map_assembler] " << e.what() << "\n";
    ++submaps_rejected_;
    return;
  }
  message_pose_[id] = global;
  last_stamp_ = std::max(last_stamp_, m->getHeader().getStampNs());
  ++submaps_;
  placeChained();
  dirty_ = true;
}

void MapAssemblerActor::onConstraint(const Message<msg::SubmapConstraint>& m) {
  ++constraints_;
  if (m->getKind() != msg::SubmapConstraint::Kind::HAND_OVER) return;
  const tessera::Pose2 relative = toPose2(m->getRelative());
  if (!relative.isFinite()) {
    std::cerr << "[map_assembler] hand-over " << m->getFromId() << " -> " << m->getToId()
              << " has a non-finite pose; ignored\n";
    ++constraints_rejected_;
    return;
  }
  handover_[static_cast<int>(m->getToId())] = {static_cast<int>(m->getFromId()), relative};
  placeChained();
  dirty_ = true;
}

void MapAssemblerActor::onOptimizedPoses(const Message<msg::SubmapPoses>& m) {
  ++pose_updates_;
  for (const auto p : m->getPoses()) {
    const tessera::Pose2 pose = toPose2(p.getPose());
    if (pose.isFinite()) optimized_[static_cast<int>(p.getId())] = pose;
  }
  last_stamp_ = std::max(last_stamp_, m->getHeader().getStampNs());
  placeChained();
  dirty_ = true;
}

void MapAssemblerActor::placeChained() {
  // Submap poses follow the chain of hand-overs from the first submap; a submap whose chain is
  // broken falls back to the pose its own message carries.
  std::map<int, tessera::Pose2> placed;
  for (const auto& [id, msg_pose] : message_pose_) {
    tessera::Pose2 pose = msg_pose;
    const auto h = handover_.find(id);
    if (const auto o = optimized_.find(id); o != optimized_.end()) {
      pose = o->second;
    } else if (h != handover_.end()) {
      const auto from = placed.find(h->second.first);
      if (from != placed.end()) pose = from->second * h->second.second;
    }
    placed[id] = pose;
    assembler_.setPose(id, pose);
  }
}

void MapAssemblerActor::publishMap() {
  const tessera::grid::OccupancyMap map = assembler_.assemble();
  if (map.empty()) return;
  // The cells go in a blob: every one is copied in, so they need no zeroing first.
  auto loan = map_pub_.loanWithBlob(map.cells.size(), 512);
  setHeader(loan->initHeader(), last_stamp_, options_.frame_id, map_pub_.nextSeq());
  loan->setResolution(static_cast<float>(map.resolution));
  loan->setWidth(static_cast<std::uint32_t>(map.width));
  loan->setHeight(static_cast<std::uint32_t>(map.height));
  writePose(loan->initOrigin(), tessera::Pose2{map.origin.x, map.origin.y, map.origin.theta});
  std::memcpy(loan.blob().data(), map.cells.data(), map.cells.size());
  loan->adoptCells(loan.blobData());
  map_pub_.publish(std::move(loan));
  map_width_ = map.width;
  map_height_ = map.height;
  dirty_ = false;
  ++maps_published_;
}

void MapAssemblerActor::stop() {
  publishMap();
}

void MapAssemblerActor::summarize(Summary& out) const {
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  out["submaps_received"] = i64(submaps_);
  out["constraints_received"] = i64(constraints_);
  out["maps_published"] = i64(maps_published_);
  out["map_width"] = static_cast<std::int64_t>(map_width_);
  out["map_height"] = static_cast<std::int64_t>(map_height_);
  if (submaps_rejected_ > 0) out["submaps_rejected"] = i64(submaps_rejected_);
  if (constraints_rejected_ > 0) out["constraints_rejected"] = i64(constraints_rejected_);
  if (options_.optimized_poses) out["optimized_pose_updates"] = i64(pose_updates_);
}

TESSERA_REGISTER_ACTOR("map_assembler", MapAssemblerActor, MapAssemblerOptions,
                       "draws all submaps into one global occupancy grid at their poses");

}  // namespace tessera::laser_slam

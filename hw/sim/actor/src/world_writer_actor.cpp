#include <tessera/io/atomic_file.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/sim/collision.hpp>
#include <tessera/sim/world_writer_actor.hpp>

#include "option_checks.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <stdexcept>

namespace tessera::sim {

namespace {

constexpr detail::OptionErrors kErrors("world_writer");

/// The file is written aside and renamed into place by closeOut(): the old file or the new one,
/// whole. Errors name the file and the reason.
tessera::io::AtomicFile openOut(const std::filesystem::path& path) {
  try {
    tessera::io::AtomicFile out(path);
    out.stream() << std::setprecision(12);
    return out;
  } catch (const tessera::io::FileWriteError& e) {
    throw std::runtime_error(std::string("world_writer: ") + e.what());
  }
}

void closeOut(tessera::io::AtomicFile& out) {
  try {
    out.commit();
  } catch (const tessera::io::FileWriteError& e) {
    throw std::runtime_error(std::string("world_writer: ") + e.what());
  }
}

}  // namespace

WorldWriterActor::WorldWriterActor(WorldWriterOptions options)
    : options_(std::move(options)),
      world_(kErrors.loadWorld(options_.world, options_.world_resolution)) {
  const auto& o = options_;
  kErrors.check(ConfigCheck()
                    .nonNegative("walls_min_length", o.walls_min_length)
                    .positive("robot_height", o.robot_height));
  if (!(o.map_period_s > 0 && o.map_period_s <= 1e6))  // false for NaN
    kErrors.fail("map_period_s", "must be in (0, 1e6] s, got " + detail::str(o.map_period_s));
  if (o.publish_map) {
    wall_cells_ = wallOccupancy(world_);
    obstacle_cells_ = footprintOccupancy(world_, o.robot_height);
  }
}

void WorldWriterActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  if (!options_.publish_map) return;
  map_pub_ = ctx.advertise<msg::OccupancyGrid>("map");
  obstacle_pub_ = ctx.advertise<msg::OccupancyGrid>("obstacle_map");
  // Republished periodically: a consumer that starts late, or keeps only the latest message,
  // still gets the maps.
  ctx.addTimer(
      secondsToNanos(options_.map_period_s), [this] { publishMaps(); }, 0);
}

void WorldWriterActor::publishMaps() {
  publishGrid(map_pub_, wall_cells_);
  publishGrid(obstacle_pub_, obstacle_cells_);
  ++maps_published_;
}

void WorldWriterActor::publishGrid(const Publisher<msg::OccupancyGrid>& pub,
                                   const std::vector<std::int8_t>& cells) {
  // The cells go in a blob: every byte is copied in, so it needs no zeroing first.
  auto loan = pub.loanWithBlob(cells.size(), 512);
  setHeader(loan->initHeader(), ctx_->now(), "map", pub.nextSeq());
  loan->setResolution(static_cast<float>(world_.resolution()));
  loan->setWidth(static_cast<std::uint32_t>(world_.width()));
  loan->setHeight(static_cast<std::uint32_t>(world_.height()));
  writePose(loan->initOrigin(), tessera::Pose2{0.0, 0.0, 0.0});
  std::copy(cells.begin(), cells.end(), reinterpret_cast<std::int8_t*>(loan.blob().data()));
  loan->adoptCells(loan.blobData());
  pub.publish(std::move(loan));
}

void WorldWriterActor::start() {
  const std::string& dir = ctx_->outputDir();
  if (dir.empty()) return;
  if (!options_.walls_file.empty()) {
    const auto path = std::filesystem::path(dir) / options_.walls_file;
    auto file = openOut(path);
    std::ostream& out = file.stream();
    const auto segments = wallSegments(world_, options_.walls_min_length);
    out << "# true wall faces of world '" << world_.name() << "': " << segments.size()
        << " (map frame, metres; free space on the left of (x0,y0)->(x1,y1); faces shorter than "
        << options_.walls_min_length << " m omitted)\n# x0 y0 x1 y1\n";
    for (const auto& w : segments)
      out << w.a.x() << ' ' << w.a.y() << ' ' << w.b.x() << ' ' << w.b.y() << '\n';
    closeOut(file);
    walls_written_ = static_cast<std::int64_t>(segments.size());
  }
  if (!options_.landmarks_file.empty()) {
    const auto path = std::filesystem::path(dir) / options_.landmarks_file;
    auto file = openOut(path);
    std::ostream& out = file.stream();
    out << "# true landmarks of world '" << world_.name() << "': " << world_.landmarks().size()
        << " (map frame, metres)\n# id x y\n";
    for (const auto& lm : world_.landmarks())
      out << lm.id << ' ' << lm.position.x() << ' ' << lm.position.y() << '\n';
    closeOut(file);
    landmarks_written_ = static_cast<std::int64_t>(world_.landmarks().size());
  }
  if (!options_.image_file.empty())
    world_.saveImage((std::filesystem::path(dir) / options_.image_file).string());
}

void WorldWriterActor::summarize(Summary& out) const {
  out["wall_segments"] = walls_written_;
  out["landmarks"] = landmarks_written_;
  out["maps_published"] = maps_published_;
}

TESSERA_REGISTER_ACTOR("world_writer", WorldWriterActor, WorldWriterOptions,
                       "writes a simulated world's true walls, landmarks and bitmap to files; "
                       "publishes its true wall and obstacle maps");

}  // namespace tessera::sim

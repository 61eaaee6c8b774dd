#include <tessera/sim/world_writer_actor.hpp>

#include <tessera/runtime/registry.hpp>

#include "option_checks.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <stdexcept>

namespace tessera::sim {

namespace {

constexpr detail::OptionErrors kErrors("world_writer");

std::ofstream openOut(const std::filesystem::path& path) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error("world_writer: cannot write '" + path.string() + "'");
  out << std::setprecision(12);
  return out;
}

void closeOut(std::ofstream& out, const std::filesystem::path& path) {
  out.flush();
  if (!out) throw std::runtime_error("world_writer: failed writing '" + path.string() + "'");
}

}  // namespace

WorldWriterActor::WorldWriterActor(WorldWriterOptions options)
    : options_(std::move(options)),
      world_(kErrors.loadWorld(options_.world, options_.world_resolution)) {
  kErrors.check(ConfigCheck().nonNegative("walls_min_length", options_.walls_min_length));
}

void WorldWriterActor::start() {
  const std::string& dir = ctx_->outputDir();
  if (dir.empty()) return;
  if (!options_.walls_file.empty()) {
    const auto path = std::filesystem::path(dir) / options_.walls_file;
    auto out = openOut(path);
    const auto segments = wallSegments(world_, options_.walls_min_length);
    out << "# true wall faces of world '" << world_.name() << "': " << segments.size()
        << " (map frame, metres; free space on the left of (x0,y0)->(x1,y1); faces shorter than "
        << options_.walls_min_length << " m omitted)\n# x0 y0 x1 y1\n";
    for (const auto& w : segments)
      out << w.a.x() << ' ' << w.a.y() << ' ' << w.b.x() << ' ' << w.b.y() << '\n';
    closeOut(out, path);
    walls_written_ = static_cast<std::int64_t>(segments.size());
  }
  if (!options_.landmarks_file.empty()) {
    const auto path = std::filesystem::path(dir) / options_.landmarks_file;
    auto out = openOut(path);
    out << "# true landmarks of world '" << world_.name() << "': " << world_.landmarks().size()
        << " (map frame, metres)\n# id x y\n";
    for (const auto& lm : world_.landmarks())
      out << lm.id << ' ' << lm.position.x() << ' ' << lm.position.y() << '\n';
    closeOut(out, path);
    landmarks_written_ = static_cast<std::int64_t>(world_.landmarks().size());
  }
  if (!options_.image_file.empty())
    world_.saveImage((std::filesystem::path(dir) / options_.image_file).string());
}

void WorldWriterActor::summarize(Summary& out) const {
  out["wall_segments"] = walls_written_;
  out["landmarks"] = landmarks_written_;
}

TESSERA_REGISTER_ACTOR("world_writer", WorldWriterActor, WorldWriterOptions,
                       "writes a simulated world's true walls, landmarks and bitmap to files");

}  // namespace tessera::sim

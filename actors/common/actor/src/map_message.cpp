#include <tessera/actor_common/map_message.hpp>

#include <tessera/messages/views.hpp>

#include <array>
#include <charconv>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

namespace tessera {

namespace {

/// The double a Float32 field was meant to hold: 0.05f reads back as 0.05, not 0.0500000007,
/// so maps written from a message say what the user configured.
double intendedValue(float f) {
  std::array<char, 32> buf{};
  const auto end = std::to_chars(buf.data(), buf.data() + buf.size(), f).ptr;
  double d = f;
  std::from_chars(buf.data(), end, d);
  return d;
}

}  // namespace

grid::OccupancyMap toOccupancyMap(const msg::OccupancyGrid::Reader& m) {
  grid::OccupancyMap map;
  map.resolution = intendedValue(m.getResolution());
  map.width = static_cast<int>(m.getWidth());
  map.height = static_cast<int>(m.getHeight());
  map.origin = toPose2(m.getOrigin());
  if (!(std::isfinite(map.resolution) && map.resolution > 0))
    throw std::invalid_argument("resolution " + std::to_string(map.resolution) +
                                " (expected a positive number of metres per cell)");
  if (!map.origin.isFinite()) throw std::invalid_argument("origin is not finite");
  const auto cells = viewInt8(m.getCells());
  if (map.empty() ||
      cells.size() != static_cast<std::size_t>(map.width) * static_cast<std::size_t>(map.height))
    throw std::invalid_argument("the message holds " + std::to_string(cells.size()) +
                                " cells, its header says " + std::to_string(map.width) + "x" +
                                std::to_string(map.height));
  map.cells.assign(cells.begin(), cells.end());
  return map;
}

void publishOccupancyMap(const Publisher<msg::OccupancyGrid>& pub, const grid::OccupancyMap& map,
                         Nanos stamp, std::string_view frame_id) {
  const std::size_t cells = map.cells.size();
  auto loan = pub.loanWithBlob(cells, 512);
  setHeader(loan->initHeader(), stamp, frame_id, pub.nextSeq());
  loan->setResolution(static_cast<float>(map.resolution));
  loan->setWidth(static_cast<std::uint32_t>(map.width));
  loan->setHeight(static_cast<std::uint32_t>(map.height));
  writePose(loan->initOrigin(), map.origin);
  if (cells > 0) std::memcpy(loan.blob().data(), map.cells.data(), cells);
  loan->adoptCells(loan.blobData());
  pub.publish(std::move(loan));
}

}  // namespace tessera

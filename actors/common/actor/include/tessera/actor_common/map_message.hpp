// Occupancy maps as messages: msg::OccupancyGrid (int8 cells: 0 free … 100 occupied, −1 unknown,
// row-major from the origin row; origin = the pose of cell (0,0)'s outer corner in the header's
// frame) to and from grid::OccupancyMap. Shared by every actor that reads or publishes maps.
#pragma once

#include <tessera/grid/occupancy_map.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>

#include <string_view>

namespace tessera {

/// The map in a message. The resolution reads back as the value that was written (0.05f gives
/// 0.05). Throws std::invalid_argument naming what is wrong: a non-positive or non-finite
/// resolution, a non-finite origin, an empty map, or a cell count that does not match the size.
grid::OccupancyMap toOccupancyMap(const msg::OccupancyGrid::Reader& m);

/// Publishes `map` on `pub` stamped `stamp` in `frame_id` (the cells travel in a blob: no copy
/// through the builder).
void publishOccupancyMap(const Publisher<msg::OccupancyGrid>& pub, const grid::OccupancyMap& map,
                         Nanos stamp, std::string_view frame_id);

}  // namespace tessera

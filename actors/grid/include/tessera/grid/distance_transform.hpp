// distanceTransform: for every cell of a grid, the Euclidean distance to the nearest marked cell
// (docs/algorithms.md#costmaps). Exact, linear in the cell count (separable squared-distance
// transform: the lower envelope of parabolas along columns, then rows). Costmap inflation and the
// localiser's likelihood field both use it.
#pragma once

#include <cstdint>
#include <vector>

namespace tessera::grid {

/// `marked`: width*height flags, row-major. Returns distances in cells (centre to centre), +inf
/// everywhere when nothing is marked. Throws std::invalid_argument when sizes disagree.
std::vector<float> distanceTransform(const std::vector<std::uint8_t>& marked, int width,
                                     int height);

}  // namespace tessera::grid

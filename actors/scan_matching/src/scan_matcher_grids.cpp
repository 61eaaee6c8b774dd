// ScanMatcher's templates instantiated for the repository's grids (grid::OccupancyGrid and the
// copy-on-write grid::TiledGrid), so that their users, the RBPF among them, need only the public
// header. Compiled with the same flags as the rest of the library: the inner loops are the
// same code as when they were instantiated in the caller.
#include "scan_matcher_impl.hpp"

#include <tessera/grid/occupancy_grid.hpp>
#include <tessera/grid/tiled_grid.hpp>

namespace tessera::scan_matching {

TESSERA_SCAN_MATCHER_GRID(grid::OccupancyGrid, )
TESSERA_SCAN_MATCHER_GRID(grid::TiledGrid, )

}  // namespace tessera::scan_matching

#include <tessera/mapping/grid_mapper.hpp>

#include <cmath>
#include <stdexcept>
#include <string>

namespace tessera::mapping {
namespace {

tessera::grid::TiledGrid::Options gridOptions(const GridMapperCoreOptions& o) {
  tessera::grid::TiledGrid::Options g;
  g.resolution = o.resolution;
  g.log_odds.hit = static_cast<float>(o.l_occ);
  g.log_odds.miss = static_cast<float>(o.l_free);
  g.log_odds.min = static_cast<float>(o.l_min);
  g.log_odds.max = static_cast<float>(o.l_max);
  g.max_side_cells = o.max_side_cells;
  return g;
}

const GridMapperCoreOptions& validated(const GridMapperCoreOptions& o) {
  auto check = [](bool ok, const char* key, double value, const char* expected) {
    if (!ok)
      throw std::invalid_argument(std::string(key) + " must be " + expected + " (got " +
                                  std::to_string(value) + ")");
  };
  check(std::isfinite(o.resolution) && o.resolution > 0, "resolution", o.resolution, "> 0");
  check(std::isfinite(o.l_occ) && o.l_occ > 0, "l_occ", o.l_occ, "> 0");
  check(std::isfinite(o.l_free) && o.l_free < 0, "l_free", o.l_free, "< 0");
  check(std::isfinite(o.l_min) && o.l_min < 0, "l_min", o.l_min, "< 0");
  check(std::isfinite(o.l_max) && o.l_max > 0, "l_max", o.l_max, "> 0");
  check(o.max_range > 0, "max_range", o.max_range, "> 0");
  check(o.max_free_range >= 0, "max_free_range", o.max_free_range, ">= 0");
  check(o.max_side_cells > 0, "max_side_cells", o.max_side_cells, "> 0");
  return o;
}

}  // namespace

GridMapper::GridMapper(const GridMapperCoreOptions& options)
    : options_(validated(options)),
      insert_options_{options.max_range, options.max_free_range},
      grid_(gridOptions(options)) {}

bool GridMapper::insert(const tessera::grid::RangeScan& scan, const tessera::Pose2& robot_pose,
                        const tessera::Pose2& mount) {
  return insertFromSensorPose(scan, robot_pose * mount);
}

bool GridMapper::insertFromSensorPose(const tessera::grid::RangeScan& scan,
                                      const tessera::Pose2& sensor_pose) {
  const tessera::grid::ScanInsertResult r = grid_.insertScan(scan, sensor_pose, insert_options_);
  stats_.beams_hit += r.hits;
  stats_.beams_no_return += r.no_return;
  stats_.beams_beyond_range += r.beyond_range;
  stats_.beams_invalid += r.invalid;
  stats_.cells_clipped += r.clipped_cells;
  ++(r.used() ? stats_.scans_inserted : stats_.scans_skipped);
  return r.used();
}

}  // namespace tessera::mapping

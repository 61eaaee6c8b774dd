// Tests for the grid mapper core, the grid_mapper actor, and the map/trajectory writer actors.
#include <tessera/msg/image.capnp.h>
#include <tessera/mapping/grid_mapper.hpp>
#include <tessera/mapping/grid_mapper_actor.hpp>
#include <tessera/mapping/map_io.hpp>
#include <tessera/mapping/packed_range_scan.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/mapping/writer_actors.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>

#include <yaml-cpp/yaml.h>
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

namespace fs = std::filesystem;
using namespace tessera;
using mapping::GridMapper;
using mapping::GridMapperActor;
using mapping::GridMapperOptions;
using tessera::Pose2;

namespace {

constexpr Nanos kSec = kNanosPerSecond;

struct TempDir {
  fs::path path;
  TempDir() {
    std::random_device rd;
    path = fs::temp_directory_path() / ("tessera_mapping_test_" + std::to_string(rd()));
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

void pushPose(ActorHarness& h, const std::string& topic, Nanos stamp, const Pose2& p) {
  h.push<msg::GroundTruthPose>(topic, [&](auto& b) {
    setHeader(b.initHeader(), stamp, "map", 0);
    writePose(b.initPose(), tessera::Pose2{p.x, p.y, p.theta});
    b.setChildFrameId("base_link");
  });
}

struct ScanSpec {
  std::vector<float> ranges{1.0f};
  float angle_min = 0.0f, angle_increment = 0.0f;
  float mount_x = 0.0f, mount_y = 0.0f, mount_theta = 0.0f;
};

ScanSpec beams(std::vector<float> ranges, float angle_min = 0.0f, float angle_increment = 0.0f) {
  ScanSpec s;
  s.ranges = std::move(ranges);
  s.angle_min = angle_min;
  s.angle_increment = angle_increment;
  return s;
}

void pushScan(ActorHarness& h, Nanos stamp, const ScanSpec& s = {}) {
  h.push<msg::LaserScan>("scan", [&](auto& b) {
    setHeader(b.initHeader(), stamp, "laser", 0);
    b.setAngleMin(s.angle_min);
    b.setAngleIncrement(s.angle_increment);
    b.setRangeMin(0.05f);
    b.setRangeMax(20.0f);
    auto out = mutableView<float>(b.initRanges(static_cast<unsigned>(s.ranges.size())));
    std::copy(s.ranges.begin(), s.ranges.end(), out.begin());
    b.setMountX(s.mount_x);
    b.setMountY(s.mount_y);
    b.setMountTheta(s.mount_theta);
  });
}

std::int64_t summaryInt(const Actor& a, const std::string& key) {
  Summary s;
  a.summarize(s);
  REQUIRE(s.count(key) == 1);
  return std::get<std::int64_t>(s.at(key));
}

/// Value of the map message cell containing world point p (−2 when outside the map).
int mapValueAt(const Message<msg::OccupancyGrid>& m, double x, double y) {
  const double res = m->getResolution();
  const int col = static_cast<int>(std::floor((x - m->getOrigin().getX()) / res + 1e-6));
  const int row = static_cast<int>(std::floor((y - m->getOrigin().getY()) / res + 1e-6));
  if (col < 0 || row < 0 || col >= static_cast<int>(m->getWidth()) ||
      row >= static_cast<int>(m->getHeight()))
    return -2;
  return viewInt8(m->getCells())[static_cast<std::size_t>(row) * m->getWidth() + col];
}

}  // namespace

// ---- core ----

TEST_CASE("GridMapper places the laser with the robot pose and the mount", "[grid_mapper]") {
  GridMapper mapper;  // 5 cm cells
  const std::vector<float> r{1.0f};
  const tessera::grid::RangeScan scan{r, 0.0, 0.0, 0.05, 20.0};
  // Robot at (1, 0.01) facing +y; laser 0.2 m ahead of it: the beam starts at (1, 0.21).
  CHECK(mapper.insert(scan, Pose2(1.0, 0.01, std::numbers::pi / 2), Pose2(0.2, 0.0, 0.0)));
  const auto& grid = mapper.grid();
  CHECK(grid.probability(grid.worldToCell({1.0, 1.21})) > 0.5);
  CHECK(grid.probability(grid.worldToCell({1.0, 0.7})) < 0.5);
  CHECK_FALSE(grid.isKnown(grid.worldToCell({1.0, 0.1})));  // behind the laser
  CHECK(mapper.stats().scans_inserted == 1);
  CHECK(mapper.stats().beams_hit == 1);

  const std::vector<float> bad{std::numeric_limits<float>::quiet_NaN(), -2.0f};
  CHECK_FALSE(mapper.insert({bad, 0.0, 0.1, 0.05, 20.0}, Pose2()));
  CHECK_FALSE(mapper.insert({{}, 0.0, 0.1, 0.05, 20.0}, Pose2()));
  CHECK(mapper.stats().scans_skipped == 2);
  CHECK(mapper.stats().beams_invalid == 2);
  CHECK(mapper.map().width > 0);
}

TEST_CASE("GridMapper rejects bad options naming the key", "[grid_mapper]") {
  mapping::GridMapperCoreOptions o;
  o.l_free = 0.3;
  CHECK_THROWS_WITH(GridMapper(o), Catch::Matchers::Contains("l_free"));
  o = {};
  o.resolution = -1;
  CHECK_THROWS_WITH(GridMapper(o), Catch::Matchers::Contains("resolution"));
}

// ---- grid_mapper actor ----

TEST_CASE("grid_mapper pairs a scan with the pose of the same stamp", "[grid_mapper_actor]") {
  auto actor = std::make_unique<GridMapperActor>(GridMapperOptions{});
  auto* mapper = actor.get();
  ActorHarness h(std::move(actor));

  SECTION("pose first") {
    pushPose(h, "pose", 1 * kSec, Pose2(0.0, 0.01, 0.0));
    pushScan(h, 1 * kSec);
  }
  SECTION("scan first: it waits for its pose") {
    pushScan(h, 1 * kSec);
    h.runUntilIdle();
    CHECK(summaryInt(*mapper, "scans_inserted") == 0);
    pushPose(h, "pose", 1 * kSec, Pose2(0.0, 0.01, 0.0));
  }
  h.runUntilIdle();
  CHECK(summaryInt(*mapper, "scans_inserted") == 1);
  CHECK(summaryInt(*mapper, "scans_paired_exact") == 1);
  const auto& grid = mapper->mapper().grid();
  CHECK(grid.probability(grid.worldToCell({1.0, 0.01})) > 0.5);
  CHECK(grid.probability(grid.worldToCell({0.5, 0.01})) < 0.5);
}

TEST_CASE("grid_mapper interpolates between bracketing poses", "[grid_mapper_actor]") {
  GridMapperOptions opts;
  opts.max_pose_gap_s = 1.5;
  auto actor = std::make_unique<GridMapperActor>(opts);
  auto* mapper = actor.get();
  ActorHarness h(std::move(actor));
  pushPose(h, "pose", 1 * kSec, Pose2(0.0, 0.01, 0.0));
  h.runUntilIdle();
  pushScan(h, 1 * kSec + kSec / 2, beams({1.02f}));  // waits: no later pose yet
  h.runUntilIdle();
  CHECK(summaryInt(*mapper, "scans_inserted") == 0);
  pushPose(h, "pose", 2 * kSec, Pose2(2.0, 0.01, 0.0));
  h.runUntilIdle();
  CHECK(summaryInt(*mapper, "scans_interpolated") == 1);
  const auto& grid = mapper->mapper().grid();
  // Robot interpolated to x = 1.0, beam of 1.02 m → wall at x = 2.02.
  CHECK(grid.probability(grid.worldToCell({2.02, 0.01})) > 0.5);
  CHECK(grid.probability(grid.worldToCell({1.5, 0.01})) < 0.5);
  CHECK_FALSE(grid.isKnown(grid.worldToCell({0.5, 0.01})));
}

TEST_CASE("grid_mapper uses the mount fields of the scan", "[grid_mapper_actor]") {
  auto actor = std::make_unique<GridMapperActor>(GridMapperOptions{});
  auto* mapper = actor.get();
  ActorHarness h(std::move(actor));
  pushPose(h, "pose", kSec, Pose2(0.0, 0.01, 0.0));
  // Laser 0.5 m ahead, looking backwards (pi): the beam of 1 m hits at x = -0.5.
  ScanSpec spec = beams({1.0f});
  spec.mount_x = 0.5f;
  spec.mount_theta = static_cast<float>(std::numbers::pi);
  pushScan(h, kSec, spec);
  h.runUntilIdle();
  const auto& grid = mapper->mapper().grid();
  CHECK(grid.probability(grid.worldToCell({-0.5 + 1e-3, 0.01})) > 0.5);
  CHECK(grid.probability(grid.worldToCell({0.2, 0.01})) < 0.5);
}

TEST_CASE("grid_mapper drops scans it cannot pair and counts them", "[grid_mapper_actor]") {
  GridMapperOptions opts;
  opts.scan_buffer = 2;
  opts.max_pose_gap_s = 0.5;
  auto actor = std::make_unique<GridMapperActor>(opts);
  auto* mapper = actor.get();
  ActorHarness h(std::move(actor));
  pushPose(h, "pose", 10 * kSec, Pose2());
  pushPose(h, "pose", 12 * kSec, Pose2());
  h.runUntilIdle();
  pushScan(h, 5 * kSec);  // older than every pose
  h.runUntilIdle();
  pushScan(h, 11 * kSec);  // poses around it are 2 s apart: too far to interpolate
  h.runUntilIdle();
  CHECK(summaryInt(*mapper, "scans_dropped_no_pose") == 2);
  // Three scans newer than every pose: the buffer keeps two and drops the oldest.
  for (int k = 1; k <= 3; ++k) {
    pushScan(h, 20 * kSec + k);
    h.runUntilIdle();
  }
  CHECK(summaryInt(*mapper, "scans_dropped_no_pose") == 3);
  h.stop();  // the two still waiting can never be paired now
  CHECK(summaryInt(*mapper, "scans_dropped_no_pose") == 5);
  CHECK(summaryInt(*mapper, "scans_inserted") == 0);
  CHECK(h.publishedCount("map") == 0);  // nothing mapped: no map to publish
}

namespace {

/// A scan of 181 beams over 180 degrees whose ranges vary with k, with a few beams of no return
/// (+inf, beyond range_max) and invalid ones (NaN), as a real laser gives.
ScanSpec variedScan(int k) {
  std::vector<float> r(181);
  for (std::size_t i = 0; i < r.size(); ++i)
    r[i] = 2.0f + 0.013f * static_cast<float>((i * 7 + static_cast<std::size_t>(k) * 3) % 97);
  r[10] = std::numeric_limits<float>::infinity();
  r[20] = 25.0f;  // beyond the scan's range_max of 20 m: no return
  r[30] = std::numeric_limits<float>::quiet_NaN();
  return beams(std::move(r), static_cast<float>(-std::numbers::pi / 2),
               static_cast<float>(std::numbers::pi / 180));
}

Pose2 pathPose(int k) {
  return Pose2(0.1 * k, 0.02 * k, 0.01 * k);
}

}  // namespace

TEST_CASE("PackedRangeScan keeps every beam to within half its unit and the special ones exactly",
          "[grid_mapper]") {
  const std::vector<float> r{0.0f,
                             0.031f,
                             19.99f,
                             20.0f,
                             35.0f,
                             std::numeric_limits<float>::infinity(),
                             std::numeric_limits<float>::quiet_NaN(),
                             -1.0f};
  const tessera::grid::RangeScan scan{r, -1.0, 0.01, 0.05, 20.0};
  const mapping::PackedRangeScan packed(42, scan, Pose2(0.5, 0.1, 3.0));
  CHECK(packed.stampNs() == 42);
  CHECK(packed.mount().x == 0.5);
  CHECK(packed.beams() == r.size());
  std::vector<float> buffer;
  const tessera::grid::RangeScan back = packed.unpack(buffer);
  CHECK(back.angle_min == Approx(-1.0));
  CHECK(back.angle_increment == Approx(0.01));
  CHECK(back.range_min == Approx(0.05));
  CHECK(back.range_max == Approx(20.0));
  REQUIRE(back.ranges.size() == r.size());
  const double half_unit = 20.0 / 65000.0 / 2.0;
  for (std::size_t i = 0; i < 3; ++i) CHECK(std::abs(back.ranges[i] - r[i]) <= half_unit + 1e-6);
  for (std::size_t i = 3; i < 6; ++i) CHECK(std::isinf(back.ranges[i]));  // no return
  CHECK(std::isnan(back.ranges[6]));
  CHECK(std::isnan(back.ranges[7]));
  // An empty scan packs and unpacks; a scan without a usable range_max is refused.
  const std::vector<float> none;
  CHECK(mapping::PackedRangeScan(0, {none, 0, 0, 0, 10}, {}).unpack(buffer).ranges.empty());
  for (const double bad : {0.0, -1.0, std::numeric_limits<double>::infinity(),
                           std::numeric_limits<double>::quiet_NaN()})
    CHECK_THROWS_AS(mapping::PackedRangeScan(0, {r, 0, 0, 0, bad}, {}), std::invalid_argument);
}

TEST_CASE("grid_mapper with hold_scans draws scans whose poses come only at the end",
          "[grid_mapper_actor]") {
  constexpr int kScans = 60;
  // The reference: the same scans with their poses already known.
  GridMapperOptions live_opts;
  live_opts.pose_queue = 256;
  auto live_actor = std::make_unique<GridMapperActor>(live_opts);
  auto* live = live_actor.get();
  ActorHarness live_h(std::move(live_actor));
  for (int k = 0; k < kScans; ++k) {
    pushPose(live_h, "pose", (k + 1) * kSec, pathPose(k));
    live_h.runUntilIdle();
    pushScan(live_h, (k + 1) * kSec, variedScan(k));
    live_h.runUntilIdle();
  }
  REQUIRE(summaryInt(*live, "scans_inserted") == kScans);

  // Every scan first, then every pose (as a final trajectory comes at stop); the mapper's
  // summary after stop().
  const auto scansThenPoses = [&](const GridMapperOptions& opts, tessera::grid::OccupancyMap* map) {
    auto actor = std::make_unique<GridMapperActor>(opts);
    auto* mapper = actor.get();
    ActorHarness h(std::move(actor));
    for (int k = 0; k < kScans; ++k) {
      pushScan(h, (k + 1) * kSec, variedScan(k));
      h.runUntilIdle();  // the scan mailbox keeps the latest few: a real run keeps up too
    }
    CHECK(summaryInt(*mapper, "scans_inserted") == 0);
    for (int k = 0; k < kScans; ++k) pushPose(h, "pose", (k + 1) * kSec, pathPose(k));
    h.stop();
    if (map) *map = mapper->mapper().map();
    Summary out;
    mapper->summarize(out);
    return out;
  };
  const auto count = [](const Summary& s, const std::string& key) {
    REQUIRE(s.count(key) == 1);
    return std::get<std::int64_t>(s.at(key));
  };
  GridMapperOptions opts;
  opts.pose_queue = 8;  // the poses come in one burst: a reliable mailbox drops none
  SECTION("held, every scan") {
    opts.hold_scans = true;
    tessera::grid::OccupancyMap a;
    const Summary s = scansThenPoses(opts, &a);
    CHECK(count(s, "held_scans_peak") == kScans);
    CHECK(count(s, "scans_inserted") == kScans);
    CHECK(count(s, "scans_dropped_no_pose") == 0);
    // Packing moves a beam's end by at most 0.15 mm here: a cell can only change where a beam
    // ends that close to its border.
    const auto b = live->mapper().map();
    REQUIRE(a.width == b.width);
    REQUIRE(a.height == b.height);
    std::size_t differ = 0, known = 0;
    for (std::size_t i = 0; i < a.cells.size(); ++i) {
      known += b.cells[i] >= 0;
      differ += a.cells[i] != b.cells[i];
    }
    INFO(differ << " of " << known << " known cells differ");
    CHECK(known > 1000);
    CHECK(differ * 200 < known);
  }
  SECTION("held, one scan per 2.5 s: every third") {
    opts.hold_scans = true;
    opts.hold_period_s = 2.5;
    const Summary s = scansThenPoses(opts, nullptr);
    CHECK(count(s, "scans_inserted") == kScans / 3);
    CHECK(count(s, "scans_not_held") == kScans - kScans / 3);
  }
  SECTION("not held: the small buffer keeps only the newest") {
    opts.scan_buffer = 16;
    opts.pose_queue = 256;
    CHECK(count(scansThenPoses(opts, nullptr), "scans_inserted") == 16);
  }
}

TEST_CASE("grid_mapper holds scans older than every pose no longer than it must",
          "[grid_mapper_actor]") {
  GridMapperOptions opts;
  opts.hold_scans = true;
  opts.max_pose_gap_s = 3.0;
  auto actor = std::make_unique<GridMapperActor>(opts);
  auto* mapper = actor.get();
  ActorHarness h(std::move(actor));
  pushScan(h, 1 * kSec, variedScan(0));  // before the trajectory starts: never paired
  pushScan(h, 5 * kSec, variedScan(1));
  pushScan(h, 9 * kSec, variedScan(2));  // after its end: still waiting at stop
  pushPose(h, "pose", 4 * kSec, Pose2());
  pushPose(h, "pose", 6 * kSec, Pose2(0.2, 0, 0));
  h.runUntilIdle();
  CHECK(summaryInt(*mapper, "scans_inserted") == 1);
  CHECK(summaryInt(*mapper, "scans_interpolated") == 1);
  CHECK(summaryInt(*mapper, "scans_dropped_no_pose") == 1);
  h.stop();
  CHECK(summaryInt(*mapper, "scans_dropped_no_pose") == 2);
  CHECK(h.publishedCount("map") == 1);
}

TEST_CASE("grid_mapper counts a scan it cannot hold and goes on", "[grid_mapper_actor]") {
  GridMapperOptions opts;
  opts.hold_scans = true;
  opts.hold_period_s = 0.5;  // a refused scan does not start the period
  auto actor = std::make_unique<GridMapperActor>(opts);
  auto* mapper = actor.get();
  ActorHarness h(std::move(actor));
  for (const float bad :
       {std::numeric_limits<float>::quiet_NaN(), 0.0f, std::numeric_limits<float>::infinity()}) {
    h.push<msg::LaserScan>("scan", [&](auto& b) {
      setHeader(b.initHeader(), kSec, "laser", 0);
      b.setRangeMax(bad);  // the unit of the packed ranges needs a finite, positive range_max
      auto out = mutableView<float>(b.initRanges(3));
      std::fill(out.begin(), out.end(), 1.0f);
    });
    h.runUntilIdle();
  }
  pushScan(h, 2 * kSec, variedScan(0));  // the next good scan is held and drawn
  pushPose(h, "pose", 2 * kSec, Pose2());
  h.stop();
  CHECK(summaryInt(*mapper, "scans_unusable") == 3);
  CHECK(summaryInt(*mapper, "scans_inserted") == 1);
}

TEST_CASE("grid_mapper publishes the map on its timer when changed and at stop",
          "[grid_mapper_actor]") {
  GridMapperOptions opts;
  opts.publish_period_s = 1.0;
  auto actor = std::make_unique<GridMapperActor>(opts);
  auto* mapper = actor.get();
  ActorHarness h(std::move(actor));
  pushPose(h, "pose", 3 * kSec, Pose2(0.0, 0.01, 0.0));
  pushScan(h, 3 * kSec, beams({1.0f, 2.0f}, 0.0f, 1.5f));
  h.runUntilIdle();
  CHECK(h.publishedCount("map") == 0);
  h.advance(kSec);
  REQUIRE(h.publishedCount("map") == 1);
  h.advance(3 * kSec);  // nothing new: no republishing
  CHECK(h.publishedCount("map") == 1);
  h.stop();
  const auto maps = h.published<msg::OccupancyGrid>("map");
  REQUIRE(maps.size() == 2);
  const auto& m = maps.back();
  CHECK(std::string(m->getHeader().getFrameId().cStr()) == "map");
  CHECK(m->getHeader().getStampNs() == 3 * kSec);
  CHECK(m->getHeader().getSeq() == 1);
  CHECK(m->getResolution() == Approx(0.05));
  CHECK(m->getCells().size() == std::size_t{m->getWidth()} * m->getHeight());
  CHECK(mapValueAt(m, 1.0 + 1e-3, 0.01) > 65);
  CHECK(mapValueAt(m, 0.5, 0.01) >= 0);
  CHECK(mapValueAt(m, 0.5, 0.01) < 50);
  // Second beam at 1.5 rad, 2 m.
  CHECK(mapValueAt(m, 2.0 * std::cos(1.5), 0.01 + 2.0 * std::sin(1.5)) > 65);
  // Same content as the core's own export.
  const tessera::grid::OccupancyMap core = mapper->mapper().map();
  CHECK(static_cast<int>(m->getWidth()) == core.width);
  CHECK(static_cast<int>(m->getHeight()) == core.height);
  const auto cells = viewInt8(m->getCells());
  CHECK(std::equal(cells.begin(), cells.end(), core.cells.begin(), core.cells.end()));
  CHECK(summaryInt(*mapper, "known_cells") > 0);
  CHECK(summaryInt(*mapper, "map_width") == core.width);
}

TEST_CASE("grid_mapper rejects invalid options with ConfigError", "[grid_mapper_actor]") {
  GridMapperOptions o;
  o.pose_message = "twist";
  CHECK_THROWS_AS(GridMapperActor(o), ConfigError);
  o = {};
  o.grid.resolution = 0;
  CHECK_THROWS_WITH(GridMapperActor(o), Catch::Matchers::Contains("grid_mapper") &&
                                            Catch::Matchers::Contains("grid.resolution"));
  o = {};
  o.publish_period_s = -1;
  CHECK_THROWS_AS(GridMapperActor(o), ConfigError);
  o = {};
  for (const double bad : {-1.0, std::numeric_limits<double>::quiet_NaN()}) {
    o.hold_period_s = bad;
    CHECK_THROWS_WITH(GridMapperActor(o), Catch::Matchers::Contains("hold_period_s"));
  }
}

TEST_CASE("grid_mapper reads the core's options as the group grid", "[grid_mapper_actor]") {
  const auto load = [](const std::string& yaml) {
    return loadOptions<GridMapperOptions>(Params(YAML::Load(yaml), "test"));
  };
  const auto o = load("grid: {resolution: 0.1, max_range: 5.6}\npublish_period_s: 0\n");
  CHECK(o.grid.resolution == 0.1);
  CHECK(o.grid.max_range == 5.6);
  CHECK(o.grid.l_occ == mapping::GridMapperCoreOptions{}.l_occ);
  CHECK(o.publish_period_s == 0);
  CHECK_THROWS_WITH(load("resolution: 0.05\n"),
                    Catch::Matchers::Contains("moved to grid.resolution"));
}

TEST_CASE("mapping actors are registered", "[grid_mapper_actor]") {
  for (const char* type : {"grid_mapper", "map_writer", "trajectory_writer"}) {
    INFO(type);
    const auto* entry = ActorRegistry::instance().find(type);
    REQUIRE(entry != nullptr);
    CHECK_FALSE(entry->options().empty());
  }
}

// ---- writers ----

TEST_CASE("map_writer writes the last map into the output folder at stop", "[writers]") {
  TempDir dir;
  mapping::MapWriterOptions opts;
  opts.basename = "final";
  ActorHarness h(std::make_unique<mapping::MapWriterActor>(opts), dir.path.string());
  auto pushMap = [&](std::int8_t first) {
    h.push<msg::OccupancyGrid>("map", [&](auto& b) {
      setHeader(b.initHeader(), 0, "map", 0);
      b.setResolution(0.05f);
      b.setWidth(3);
      b.setHeight(2);
      writePose(b.initOrigin(), tessera::Pose2{-1.0, 2.0, 0.0});
      auto cells = mutableViewInt8(b.initCells(6));
      const std::int8_t values[6] = {first, 0, -1, 0, 0, 100};
      std::copy(values, values + 6, cells.begin());
    });
    h.runUntilIdle();
  };
  pushMap(0);
  pushMap(100);  // the writer keeps only the latest
  h.stop();
  const fs::path yaml = dir.path / "final.yaml";
  REQUIRE(fs::exists(yaml));
  CHECK(fs::exists(dir.path / "final.pgm"));
  CHECK(fs::exists(dir.path / "final.png"));
  const auto map = tessera::mapping::loadMap(yaml);
  CHECK(map.resolution == 0.05);  // not 0.0500000007 from the Float32 field
  CHECK(map.origin.x == -1.0);
  CHECK(map.origin.y == 2.0);
  CHECK(map.cells == std::vector<std::int8_t>{100, 0, -1, 0, 0, 100});
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::string>(s.at("map_path")) == yaml.string());
}

TEST_CASE("writers do nothing without an output folder", "[writers]") {
  {
    ActorHarness h(std::make_unique<mapping::MapWriterActor>(mapping::MapWriterOptions{}));
    h.push<msg::OccupancyGrid>("map", [&](auto& b) {
      b.setResolution(0.05f);
      b.setWidth(1);
      b.setHeight(1);
      b.initCells(1);
    });
    h.runUntilIdle();
    h.stop();
    Summary s;
    h.actor().summarize(s);
    CHECK(std::get<std::string>(s.at("map_path")).empty());
  }
  {
    ActorHarness h(
        std::make_unique<mapping::TrajectoryWriterActor>(mapping::TrajectoryWriterOptions{}));
    pushPose(h, "poses", 1, Pose2());
    h.runUntilIdle();
    h.stop();
    Summary s;
    h.actor().summarize(s);
    CHECK(std::get<std::int64_t>(s.at("poses_written")) == 0);
  }
}

TEST_CASE("trajectory_writer streams ground truth poses to a TUM file", "[writers]") {
  TempDir dir;
  ActorHarness h(
      std::make_unique<mapping::TrajectoryWriterActor>(mapping::TrajectoryWriterOptions{}),
      dir.path.string());
  const std::vector<Pose2> truth{Pose2(0, 0, 0), Pose2(0.1, 0.02, 0.1), Pose2(0.2, 0.05, -3.0)};
  for (std::size_t k = 0; k < truth.size(); ++k) {
    pushPose(h, "poses", static_cast<Nanos>(k) * kSec / 10 + 7, truth[k]);
    h.runUntilIdle();
  }
  h.stop();
  const auto poses = tessera::mapping::readTum(dir.path / "trajectory.tum");
  REQUIRE(poses.size() == truth.size());
  for (std::size_t k = 0; k < truth.size(); ++k) {
    CHECK(poses[k].stamp_ns == static_cast<Nanos>(k) * kSec / 10 + 7);
    CHECK(poses[k].planar().x == truth[k].x);
    CHECK(poses[k].planar().theta == Approx(truth[k].theta));
  }
}

TEST_CASE("trajectory_writer follows its message option", "[writers]") {
  TempDir dir;
  mapping::TrajectoryWriterOptions opts;
  opts.message = "odometry";
  opts.file = "odometry.tum";
  ActorHarness h(std::make_unique<mapping::TrajectoryWriterActor>(opts), dir.path.string());
  h.push<msg::Odometry>("poses", [&](auto& b) {
    setHeader(b.initHeader(), 5 * kSec, "odom", 0);
    writePose(b.initPose(), tessera::Pose2{1.5, -0.5, 0.25});
  });
  h.runUntilIdle();
  h.stop();
  const auto poses = tessera::mapping::readTum(dir.path / "odometry.tum");
  REQUIRE(poses.size() == 1);
  CHECK(poses[0].stamp_ns == 5 * kSec);
  CHECK(poses[0].planar().x == 1.5);

  // 3D estimates (PoseStamped3D, e.g. the RGB-D front end's camera_pose) in full 3D.
  mapping::TrajectoryWriterOptions o3;
  o3.message = "pose_3d";
  ActorHarness h3(std::make_unique<mapping::TrajectoryWriterActor>(o3), dir.path.string());
  h3.push<msg::PoseStamped3D>("poses", [&](msg::PoseStamped3D::Builder b) {
    setHeader(b.initHeader(), 6 * kSec, "world", 0);
    writePose(b.initPose(), Pose3{Eigen::Vector3d(1, 2, 3), Eigen::Quaterniond(Eigen::AngleAxisd(
                                                                0.5, Eigen::Vector3d::UnitX()))});
    b.setFrameIndex(12);
    b.setStatus(msg::PoseStamped3D::TrackingStatus::RELOCALISED);
  });
  h3.runUntilIdle();
  h3.stop();
  const auto poses3 = tessera::mapping::readTum(dir.path / "trajectory.tum");
  REQUIRE(poses3.size() == 1);
  CHECK(poses3[0].stamp_ns == 6 * kSec);
  CHECK(poses3[0].position.z() == 3);
  CHECK(Eigen::AngleAxisd(poses3[0].orientation).angle() == Approx(0.5));

  mapping::TrajectoryWriterOptions bad;
  bad.message = "imu";
  CHECK_THROWS_AS(mapping::TrajectoryWriterActor(bad), ConfigError);
  CHECK_THROWS_WITH(mapping::TrajectoryWriterActor(bad),
                    Catch::Matchers::Contains("'imu'") &&
                        Catch::Matchers::Contains("ground_truth | odometry | pose_stamped"));
}

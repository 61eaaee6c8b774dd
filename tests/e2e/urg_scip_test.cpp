// urg_scip_rbpf end to end: `tessera emulate scip` streams the shared URG log through SCIP 2.0
// on a pseudo-terminal, the hokuyo_scip driver reads it on the wall clock and the RBPF maps.
// The scans that reach the SLAM must be the log's scans, bit for bit, every one, on the log's
// timing; the SLAM must process them as urg_rbpf does from the player
// (docs/architecture.md#device-drivers).
#include "../apps/cli_child.hpp"
#include "../shared_data.hpp"
#include "run_profile.hpp"

#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/recording.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace urg_scip_e2e {

namespace fs = std::filesystem;
using namespace tessera;

struct Scan {
  Nanos stamp = 0;
  float angle_min = 0, angle_increment = 0, range_min = 0, range_max = 0;
  std::vector<float> ranges;
};

/// A profile file: `name` from apps/profiles with a recorder of the `scan` topic added.
fs::path withScanRecorder(const std::string& name, const fs::path& dir) {
  std::ifstream in(test::sourceDir() / "apps/profiles" / (name + ".yaml"));
  std::ostringstream text;
  text << in.rdbuf()
       << "  scan_recorder:\n    type: recorder\n    params: {path: scans.trec, topics: [scan], "
          "compression: none}\n";
  const fs::path out = dir / (name + ".yaml");
  std::ofstream(out) << text.str();
  return out;
}

RunReport run(const fs::path& profile_file, const fs::path& out,
              const std::vector<std::string>& overrides) {
  auto profile = loadProfile(profile_file.string(), overrides);
  RuntimeOptions options;
  options.show_progress = false;
  options.output_dir = out.string();
  options.threads = 2;
  return buildRuntime(profile, options)->run();
}

std::vector<Scan> recordedScans(const fs::path& file) {
  RecordingReader reader(file.string());
  std::vector<Scan> scans;
  RecordedMessage m;
  while (reader.next(m)) {
    const Message<msg::LaserScan> scan(m.message);
    Scan s;
    s.stamp = scan->getHeader().getStampNs();
    s.angle_min = scan->getAngleMin();
    s.angle_increment = scan->getAngleIncrement();
    s.range_min = scan->getRangeMin();
    s.range_max = scan->getRangeMax();
    const auto r = view<float>(scan->getRanges());
    s.ranges.assign(r.begin(), r.end());
    scans.push_back(std::move(s));
  }
  return scans;
}

bool sameBits(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t k = 0; k < a.size(); ++k)
    if (!(a[k] == b[k] || (std::isnan(a[k]) && std::isnan(b[k])))) return false;
  return true;
}

TEST_CASE("urg_scip_rbpf maps from the URG log streamed through SCIP by an emulated URG-04LX",
          "[e2e][drivers][urg_scip][wall_clock]") {
  TESSERA_SHARED_DATA(log, "mines-paristech-urg04lx-odometry/exp2.dat.gz");
  const auto dir = test::scratchDir("urg_scip");
  const double seconds = 15;
  const std::string end = std::to_string(seconds);

  // The reference: the player's own scans, with the angles the URG-04LX's steps give.
  const auto ref_report = run(withScanRecorder("urg_rbpf", dir), dir / "ref",
                              {"player.path=" + log.string(), "player.end_time=" + end,
                               "player.urg04lx_steps=true", "player.relative_stamps=true"});
  const auto ref = recordedScans(dir / "ref/scans.trec");

  // The same log through the emulated laser and the driver, on the wall clock.
  const fs::path device = dir / "urg";
  test::CliChild emulator(
      "emulate scip --log " + log.string() + " --link " + device.string() + " --end-time " + end,
      dir / "emulator.txt");
  for (int i = 0; i < 100 && !fs::exists(device); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  REQUIRE(fs::exists(device));
  const auto report = run(
      withScanRecorder("urg_scip_rbpf", dir), dir / "driver",
      {"laser.device=" + device.string(), "player.path=" + log.string(), "player.end_time=" + end});
  CHECK(emulator.interrupt() == 0);
  const auto scans = recordedScans(dir / "driver/scans.trec");

  // Every scan of the log arrived, none corrupt, none twice: the stream ends when the
  // odometry does, so the last one or two may come after the run stopped.
  REQUIRE(ref.size() >= 140);
  REQUIRE(scans.size() + 2 >= ref.size());
  REQUIRE(scans.size() <= ref.size());
  // The two runs' clocks differ by when each started: the median offset between them.
  std::vector<double> offsets;
  for (std::size_t k = 0; k < scans.size(); ++k)
    offsets.push_back(nanosToSeconds(scans[k].stamp - ref[k].stamp));
  std::nth_element(offsets.begin(), offsets.begin() + offsets.size() / 2, offsets.end());
  const double offset_s = offsets[offsets.size() / 2];
  for (std::size_t k = 0; k < scans.size(); ++k) {
    INFO("scan " << k);
    CHECK(sameBits(scans[k].ranges, ref[k].ranges));
    CHECK(scans[k].angle_min == ref[k].angle_min);
    CHECK(scans[k].angle_increment == ref[k].angle_increment);
    CHECK(scans[k].range_min == ref[k].range_min);
    CHECK(scans[k].range_max == ref[k].range_max);
    // On the log's timing, to the SCIP clock's millisecond once the sensor clock's offset has
    // seen a fast transfer (the first scans may come late on a busy machine).
    const double dt = nanosToSeconds(scans[k].stamp - ref[k].stamp) - offset_s;
    CHECK(std::abs(dt) < (k < 5 ? 0.025 : 0.0025));
  }
  CHECK(test::summaryInt(report, "laser", "bad_replies") == 0);
  CHECK(test::summaryInt(report, "laser", "reconnects") == 0);
  // The SLAM took them as it takes the player's: every scan paired with odometry.
  CHECK(test::summaryInt(report, "slam", "scans_read") == static_cast<std::int64_t>(scans.size()));
  CHECK(test::summaryInt(report, "slam", "scans_unpaired") <= 1);
  CHECK(test::summaryInt(report, "slam", "particle_updates") >=
        test::summaryInt(ref_report, "slam", "particle_updates") - 2);
  CHECK(fs::file_size(dir / "driver/map.pgm") > 1000);
  fs::remove_all(dir);
}

}  // namespace urg_scip_e2e

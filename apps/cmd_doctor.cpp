// `tessera doctor`: checks what a run, a launch or a benchmark needs from this machine and says
// what to fix: /dev/shm (a tmpfs, its free space against the iceoryx pool budget, that segments
// can be created), a RouDi already running, shared memory and sockets a crashed run left
// (`--fix` removes them), the CPU frequency governor and transparent huge pages (benchmarks),
// and the public datasets the tests and benchmarks read (`--data DIR`, default ../shared/data).
//
// Exit code 0 when nothing failed (warnings allowed), 1 when a check failed: a deployment over
// shared memory cannot run here as it is.
#include "commands.hpp"

#include <tessera/shm/deployment.hpp>
#include <tessera/shm/roudi_host.hpp>

#include <sys/stat.h>
#include <sys/statfs.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace tessera::app {

namespace fs = std::filesystem;

namespace doctor {

enum class Level { kOk, kWarn, kFail, kFixed };

struct Finding {
  Level level = Level::kOk;
  std::string what;  ///< the check and its result
  std::string fix;   ///< what to do about it (empty when nothing)
};

std::string gib(double bytes) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(1) << bytes / double(1u << 30) << " GiB";
  return s.str();
}

std::string joined(const std::vector<std::string>& items) {
  std::string out;
  for (const auto& item : items) out += (out.empty() ? "" : ", ") + item;
  return out;
}

std::string readFirstLine(const fs::path& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  return line;
}

/// Space of the shared-memory filesystem; iceoryx's pools take up to 1 GiB (memPoolsFor's
/// default budget) plus its management segment.
void checkShmSpace(const fs::path& shm_dir, std::vector<Finding>& out) {
  struct statvfs vfs {};
  if (::statvfs(shm_dir.c_str(), &vfs) != 0) {
    out.push_back(
        {Level::kFail, shm_dir.string() + ": " + std::strerror(errno),
         "mount a tmpfs there: sudo mount -t tmpfs -o size=2g tmpfs " + shm_dir.string()});
    return;
  }
  const double total = double(vfs.f_blocks) * double(vfs.f_frsize);
  const double free = double(vfs.f_bavail) * double(vfs.f_frsize);
  struct statfs fsinfo {};
  constexpr long kTmpfsMagic = 0x01021994;
  const bool tmpfs = ::statfs(shm_dir.c_str(), &fsinfo) == 0 && fsinfo.f_type == kTmpfsMagic;
  const std::string what = shm_dir.string() + ": " + (tmpfs ? "tmpfs, " : "not a tmpfs, ") +
                           gib(free) + " free of " + gib(total);
  constexpr double kNeed = double(std::size_t{1} << 30) + double(std::size_t{64} << 20);
  if (free < kNeed) {
    out.push_back({Level::kWarn, what,
                   "tessera launch sizes iceoryx's pools up to 1 GiB: a large deployment will not "
                   "start; sudo mount -o remount,size=2g " +
                       shm_dir.string() + " (Docker: --shm-size=2g)"});
  } else if (!tmpfs) {
    out.push_back({Level::kWarn, what,
                   "shared memory on a disk-backed filesystem is slow: mount a tmpfs there"});
  } else {
    out.push_back({Level::kOk, what, ""});
  }
  struct stat st {};
  if (::stat(shm_dir.c_str(), &st) == 0 && (st.st_mode & 01777) != 01777) {
    std::ostringstream mode;
    mode << std::oct << (st.st_mode & 07777);
    out.push_back({Level::kWarn, shm_dir.string() + " has mode " + mode.str() + ", not 1777",
                   "sudo chmod 1777 " + shm_dir.string()});
  }
}

/// Creates, maps and removes a segment through the deployments' own control-block code.
void checkShmAccess(std::vector<Finding>& out) {
  try {
    SyncMemory probe("/tessera_doctor_" + std::to_string(::getpid()), true);
    out.push_back({Level::kOk, "shared memory: a segment was created, mapped and removed", ""});
  } catch (const std::exception& e) {
    out.push_back({Level::kFail, std::string("creating ") + e.what(),
                   "check that /dev/shm is a writable tmpfs (mode 1777), not full, and within "
                   "this user's memory limits"});
  }
}

void checkLeftovers(bool fix, std::vector<Finding>& out) {
  if (rouDiRunning()) {
    out.push_back({Level::kWarn,
                   "an iceoryx RouDi is running (a deployment, a benchmark or iox-roudi)",
                   "iceoryx 2.0 allows one per machine: tessera launch and bench ipc refuse to "
                   "start until it stops"});
  }
  const std::vector<std::string> stale = findStaleShm();
  if (stale.empty()) {
    out.push_back({Level::kOk, "no shared memory or sockets left by a crashed run", ""});
    return;
  }
  if (!fix) {
    out.push_back({Level::kWarn, "left by a crashed run: " + joined(stale),
                   "tessera doctor --fix removes them (the next tessera launch does as well)"});
    return;
  }
  try {
    const std::vector<std::string> removed = removeStaleShm();
    out.push_back({Level::kFixed,
                   "removed " + (removed.empty() ? std::string("nothing") : joined(removed)), ""});
  } catch (const std::exception& e) {
    out.push_back({Level::kFail, std::string("could not remove leftovers: ") + e.what(), ""});
  }
}

void checkCpu(std::vector<Finding>& out) {
  std::set<std::string> governors;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator("/sys/devices/system/cpu", ec)) {
    const auto name = entry.path().filename().string();
    if (name.rfind("cpu", 0) != 0 || name.size() < 4 ||
        name.find_first_not_of("0123456789", 3) != std::string::npos)
      continue;
    const std::string g = readFirstLine(entry.path() / "cpufreq" / "scaling_governor");
    if (!g.empty()) governors.insert(g);
  }
  const std::string cores = std::to_string(std::thread::hardware_concurrency()) + " cores";
  if (governors.empty()) {
    out.push_back(
        {Level::kOk, cores + "; CPU frequency governor not exposed (a VM or a fixed clock)", ""});
  } else if (governors.size() == 1 && *governors.begin() == "performance") {
    out.push_back({Level::kOk, cores + "; CPU frequency governor: performance", ""});
  } else {
    out.push_back(
        {Level::kWarn,
         cores + "; CPU frequency governor: " + joined({governors.begin(), governors.end()}),
         "benchmark figures vary with frequency scaling: sudo cpupower frequency-set "
         "-g performance"});
  }
  const std::string thp = readFirstLine("/sys/kernel/mm/transparent_hugepage/enabled");
  if (thp.empty()) {
    out.push_back({Level::kOk, "transparent huge pages: not available", ""});
  } else if (thp.find("[never]") != std::string::npos) {
    out.push_back({Level::kWarn, "transparent huge pages: never",
                   "the global planner's search arrays ask for huge pages and run slower "
                   "without: echo madvise | sudo tee /sys/kernel/mm/transparent_hugepage/enabled"});
  } else {
    const auto a = thp.find('['), b = thp.find(']');
    out.push_back({Level::kOk,
                   "transparent huge pages: " +
                       (a != std::string::npos && b > a ? thp.substr(a + 1, b - a - 1) : thp),
                   ""});
  }
}

/// The public datasets that the profiles' examples, the benchmarks and the tests read.
void checkData(const fs::path& data, std::vector<Finding>& out) {
  struct Dataset {
    const char* path;
    const char* used_by;
  };
  static const Dataset kDatasets[] = {
      {"intel-lab-mrpt/intel.clf.gz", "carmen_global, carmen_mcl, bench rbpf"},
      {"intel-lab-mrpt/frame_times.txt", "carmen_global, carmen_mcl, bench rbpf"},
      {"intel-lab-mrpt/intel.relations", "eval relations, bench rbpf"},
      {"mines-paristech-urg04lx-odometry/exp2.dat.gz", "urg profiles"},
      {"posegraphs/M3500.g2o", "graph optimize, bench graph"},
      {"posegraph-g2o/intel.g2o", "bench graph"},
      {"posegraph-toro/input_INTEL_g2o.graph", "bench graph"},
      {"victoria-park-gtsam/victoria_park.txt", "landmark SLAM profiles, bench landmarks"},
      {"utias-mrclam-dataset1", "landmark SLAM profiles"},
      {"7scenes-redkitchen-rgbd", "RGB-D profiles, bench rgbd, bench octomap"},
      {"tum-rgbd-fr1-desk-9frames", "RGB-D tests"},
      {"orb-vocabulary-dbow3-small", "visual loop closure"},
  };
  std::error_code ec;
  if (!fs::is_directory(data, ec)) {
    out.push_back({Level::kWarn, "no dataset folder at " + data.string(),
                   "pass --data DIR; without it the tests that read data skip (and fail under "
                   "CI=true) and the benchmarks on real logs cannot run"});
    return;
  }
  int found = 0;
  for (const auto& d : kDatasets) {
    if (fs::exists(data / d.path, ec)) {
      ++found;
    } else {
      out.push_back({Level::kWarn, "missing " + (data / d.path).string(),
                     std::string("used by ") + d.used_by});
    }
  }
  out.push_back({found == static_cast<int>(std::size(kDatasets)) ? Level::kOk : Level::kWarn,
                 "datasets in " + data.string() + ": " + std::to_string(found) + " of " +
                     std::to_string(std::size(kDatasets)) + " found",
                 ""});
}

}  // namespace doctor

void addDoctorCommand(CLI::App& app, int& result) {
  auto* cmd = app.add_subcommand(
      "doctor",
      "check this machine for runs, launches and benchmarks (/dev/shm, leftovers of crashed "
      "runs, CPU governor, huge pages, datasets) and say what to fix");
  auto data = std::make_shared<std::string>("../shared/data");
  auto fix = std::make_shared<bool>(false);
  cmd->add_option("--data", *data, "folder of the public datasets")->capture_default_str();
  cmd->add_flag("--fix", *fix, "remove shared memory and sockets left by a crashed run");
  cmd->callback([data, fix, &result] {
    using doctor::Level;
    std::vector<doctor::Finding> findings;
    doctor::checkShmSpace("/dev/shm", findings);
    doctor::checkShmAccess(findings);
    doctor::checkLeftovers(*fix, findings);
    doctor::checkCpu(findings);
    doctor::checkData(*data, findings);
    int failed = 0, warned = 0;
    for (const auto& f : findings) {
      const char* tag = f.level == Level::kOk      ? "[ok]   "
                        : f.level == Level::kWarn  ? "[warn] "
                        : f.level == Level::kFixed ? "[fixed]"
                                                   : "[FAIL] ";
      std::cout << tag << " " << f.what << "\n";
      if (!f.fix.empty()) std::cout << "        fix: " << f.fix << "\n";
      failed += f.level == Level::kFail ? 1 : 0;
      warned += f.level == Level::kWarn ? 1 : 0;
    }
    std::cout << (failed > 0 ? "not ready: " : "ready: ") << failed << " failed, " << warned
              << " warning" << (warned == 1 ? "" : "s") << "\n";
    result = failed > 0 ? 1 : 0;
  });
}

}  // namespace tessera::app

#include <tessera/shm/orphaned_lock.hpp>
#include <tessera/shm/roudi_host.hpp>

#include <iceoryx_hoofs/log/logmanager.hpp>
#include <iceoryx_hoofs/posix_wrapper/posix_access_rights.hpp>
#include <iceoryx_posh/iceoryx_posh_config.hpp>
#include <iceoryx_posh/iceoryx_posh_types.hpp>
#include <iceoryx_posh/internal/popo/building_blocks/locking_policy.hpp>
#include <iceoryx_posh/internal/roudi/roudi.hpp>
#include <iceoryx_posh/roudi/iceoryx_roudi_components.hpp>

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>

namespace tessera {

namespace {

std::string lockPath() {
  return std::string("/tmp/") + iox::roudi::ROUDI_LOCK_NAME + ".lock";
}

std::string groupName() {
  return iox::posix::PosixGroup::getGroupOfCurrentProcess().getName().c_str();
}

}  // namespace

void setIceoryxLogLevel(const std::string& level) {
  static const std::map<std::string, iox::log::LogLevel> levels{
      {"off", iox::log::LogLevel::kOff},     {"fatal", iox::log::LogLevel::kFatal},
      {"error", iox::log::LogLevel::kError}, {"warn", iox::log::LogLevel::kWarn},
      {"info", iox::log::LogLevel::kInfo},   {"debug", iox::log::LogLevel::kDebug}};
  auto it = levels.find(level);
  if (it == levels.end()) {
    throw std::invalid_argument("iceoryx log level '" + level +
                                "' unknown; expected off, fatal, error, warn, info or debug");
  }
  iox::log::LogManager::GetLogManager().SetDefaultLogLevel(it->second,
                                                           iox::log::LogLevelOutput::kHideLogLevel);
}

bool rouDiRunning() {
  const int fd = ::open(lockPath().c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;  // never started on this machine since boot
  const bool held = ::flock(fd, LOCK_EX | LOCK_NB) != 0;
  ::close(fd);  // closing drops our lock if we took it
  return held;
}

std::vector<std::string> findStaleShm(const std::filesystem::path& shm_dir,
                                      const std::filesystem::path& tmp_dir) {
  namespace fs = std::filesystem;
  std::vector<std::string> found;
  std::error_code ec;
  const bool roudi = rouDiRunning();
  if (!roudi) {
    for (const auto& path :
         {shm_dir / iox::roudi::SHM_NAME, shm_dir / groupName(), tmp_dir / "roudi"}) {
      if (fs::exists(fs::symlink_status(path, ec))) found.push_back(path.string());
    }
  }
  // Control blocks of launchers that no longer run (named /tessera_sync_<pid>).
  for (const auto& entry : fs::directory_iterator(shm_dir, ec)) {
    const auto name = entry.path().filename().string();
    if (name.rfind("tessera_sync_", 0) != 0) continue;
    const long pid = std::strtol(name.c_str() + 13, nullptr, 10);
    if (pid > 0 && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH)
      found.push_back(entry.path().string());
  }
  // Sockets of Tessera processes of a dead run (a running deployment has a RouDi).
  if (!roudi) {
    for (const auto& entry : fs::directory_iterator(tmp_dir, ec)) {
      const auto name = entry.path().filename().string();
      if (name.rfind("tessera_", 0) == 0 && entry.is_socket(ec))
        found.push_back(entry.path().string());
    }
  }
  std::sort(found.begin(), found.end());
  return found;
}

std::vector<std::string> removeStaleShm() {
  if (rouDiRunning()) {
    throw std::runtime_error(
        "an iceoryx RouDi is already running on this machine (" + lockPath() +
        " is locked): another deployment, benchmark or iox-roudi; iceoryx 2.0 allows one per "
        "machine, stop it first");
  }
  std::vector<std::string> removed;
  std::error_code ec;
  for (const auto& path : findStaleShm())
    if (std::filesystem::remove(path, ec)) removed.push_back(path);
  return removed;
}

std::vector<MemPool> memPoolsFor(const std::vector<ChunkDemand>& demands,
                                 std::size_t budget_bytes) {
  std::map<std::size_t, std::uint64_t> classes;  // chunk bytes -> count
  // Small messages of every kind (headers, poses, control) always have room.
  classes[std::size_t{1} << 10] += 512;
  classes[std::size_t{1} << 14] += 256;
  for (const auto& d : demands) {
    std::size_t size = std::size_t{1} << 10;
    while (size < d.max_bytes) size <<= 1;
    classes[size] += d.alive + d.alive / 2 + 8;
  }
  // Largest classes first give up count until the sum fits the budget (at least 4 each).
  auto total = [&] {
    std::size_t t = 0;
    for (auto& [size, count] : classes) t += size * count;
    return t;
  };
  for (auto it = classes.rbegin(); it != classes.rend() && total() > budget_bytes; ++it) {
    const std::size_t others = total() - it->first * it->second;
    const std::size_t room = budget_bytes > others ? (budget_bytes - others) / it->first : 0;
    it->second = std::max<std::uint64_t>(4, std::min<std::uint64_t>(it->second, room));
  }
  std::vector<MemPool> pools;
  for (auto& [size, count] : classes) {
    pools.push_back({size, static_cast<std::uint32_t>(std::min<std::uint64_t>(count, 1u << 20))});
  }
  return pools;
}

namespace {

/// When the process started (clock ticks since boot, /proc/<pid>/stat field 22), or nothing when
/// it no longer runs: gone, or a zombie waiting for its parent. A stopped process runs.
std::optional<unsigned long long> processStart(std::uint32_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string text;
  if (!std::getline(in, text)) return std::nullopt;
  const auto close = text.rfind(')');  // the command name may hold spaces and parentheses
  if (close == std::string::npos) return std::nullopt;
  std::istringstream rest(text.substr(close + 1));
  std::string state;
  rest >> state;
  if (state == "Z" || state == "X") return std::nullopt;
  std::string skip;
  for (int field = 4; field < 22; ++field) rest >> skip;
  unsigned long long start = 0;
  if (!(rest >> start)) return std::nullopt;
  return start;
}

}  // namespace

// Named (not anonymous): RouDiHost::Impl holds one.
namespace detail {

/// The processes that registered with RouDi: runtime name -> pid and start time.
struct RegisteredProcesses {
  struct Entry {
    std::uint32_t pid = 0;
    unsigned long long start = 0;
  };
  std::mutex mutex;
  std::map<std::string, Entry> by_name;
};

/// RouDi whose process monitor takes a process for dead when it no longer exists, not when its
/// heartbeats stop: iceoryx 2.0 drops a process that sent none for 1.5 s, and with it the ports
/// of one that is only stopped (SIGSTOP, a debugger, swapping). The reliable messages waiting
/// in its queues were lost, and the deployment could not stop once it ran again
/// (docs/architecture.md#processes-that-stall). Each monitor cycle (0.1 s) renews the heartbeat
/// of every registered process that still runs, so RouDi's own clean-up reaches only the dead.
///
/// The registry is a base constructed before RouDi's, whose constructor starts the monitor
/// thread that calls cyclicUpdateHook().
class HostedRouDi : private RegisteredProcesses, public iox::roudi::RouDi {
 public:
  HostedRouDi(iox::roudi::IceOryxRouDiComponents& components, bool monitor)
      : RouDi(components.rouDiMemoryManager, components.portManager,
              RoudiStartupParameters{
                  monitor ? iox::roudi::MonitoringMode::ON : iox::roudi::MonitoringMode::OFF,
                  // Processes are stopped by their owner (the launcher), not by RouDi.
                  false,
                  // processMessage() below must not run before this object is complete.
                  RuntimeMessagesThreadStart::DEFER_START}) {
    startProcessRuntimeMessagesThread();
  }
  ~HostedRouDi() override {
    shutdown();  // joins RouDi's threads while the overrides below can still run
  }
  HostedRouDi(const HostedRouDi&) = delete;
  HostedRouDi& operator=(const HostedRouDi&) = delete;

 protected:
  void processMessage(const iox::runtime::IpcMessage& message,
                      const iox::runtime::IpcMessageType& cmd,
                      const iox::RuntimeName_t& name) noexcept override {
    if (cmd == iox::runtime::IpcMessageType::REG && message.getNumberOfElements() == 6) {
      std::uint32_t pid = 0;
      uid_t user = 0;
      std::int64_t sent_at = 0;
      static_cast<void>(parseRegisterMessage(message, pid, user, sent_at));
      const auto start = processStart(pid);
      std::lock_guard lock(mutex);
      if (start) by_name[name.c_str()] = {pid, *start};
    } else if (cmd == iox::runtime::IpcMessageType::TERMINATION) {
      std::lock_guard lock(mutex);
      by_name.erase(name.c_str());
    }
    RouDi::processMessage(message, cmd, name);
  }

  void cyclicUpdateHook() noexcept override {
    std::vector<std::string> running;
    {
      std::lock_guard lock(mutex);
      for (auto it = by_name.begin(); it != by_name.end();) {
        const auto start = processStart(it->second.pid);
        if (start && *start == it->second.start) {  // the same process, not a reused pid
          running.push_back(it->first);
          ++it;
        } else {
          it = by_name.erase(it);
        }
      }
    }
    for (const auto& name : running) {
      m_prcMgr->updateLivelinessOfProcess(iox::RuntimeName_t(iox::cxx::TruncateToCapacity, name));
    }
  }
};

}  // namespace detail

struct RouDiHost::Impl {
  std::vector<std::string> removed;
  std::size_t max_chunk = 0;
  std::optional<iox::roudi::IceOryxRouDiComponents> components;
  std::optional<detail::HostedRouDi> roudi;
};

RouDiHost::RouDiHost(RouDiHostOptions options) : impl_(std::make_unique<Impl>()) {
  setIceoryxLogLevel(options.log_level);
  impl_->removed = removeStaleShm();
  if (options.pools.empty()) throw std::invalid_argument("RouDiHost: no memory pools");
  if (options.pools.size() > iox::MAX_NUMBER_OF_MEMPOOLS) {
    throw std::invalid_argument("RouDiHost: " + std::to_string(options.pools.size()) +
                                " memory pools, iceoryx allows " +
                                std::to_string(iox::MAX_NUMBER_OF_MEMPOOLS));
  }
  std::sort(options.pools.begin(), options.pools.end(),
            [](const MemPool& a, const MemPool& b) { return a.chunk_bytes < b.chunk_bytes; });
  iox::mepoo::MePooConfig mepoo;
  for (const auto& p : options.pools) {
    mepoo.addMemPool({static_cast<std::uint32_t>(p.chunk_bytes), p.count});
    impl_->max_chunk = std::max(impl_->max_chunk, p.chunk_bytes);
  }
  iox::RouDiConfig_t config;
  const auto group = iox::posix::PosixGroup::getGroupOfCurrentProcess().getName();
  config.m_sharedMemorySegments.push_back({group, group, mepoo});
  config.optimize();
  impl_->components.emplace(config);
  impl_->roudi.emplace(*impl_->components, options.monitor_processes);
  // iceoryx 2.0 creates its segments for the user's group (plus ACL entries); a deployment is
  // one user's processes, so narrow them to the owner. Processes open them after this.
  namespace fs = std::filesystem;
  for (const auto& path :
       {fs::path("/dev/shm") / iox::roudi::SHM_NAME, fs::path("/dev/shm") / groupName()}) {
    std::error_code ec;
    fs::permissions(path, fs::perms::owner_read | fs::perms::owner_write, fs::perm_options::replace,
                    ec);
    if (ec) {
      throw std::runtime_error("cannot limit shared memory " + path.string() +
                               " to its owner: " + ec.message());
    }
  }
}

RouDiHost::~RouDiHost() {
  impl_->roudi.reset();
  impl_->components.reset();
}

std::size_t RouDiHost::maxChunkBytes() const {
  return impl_->max_chunk;
}

const std::vector<std::string>& RouDiHost::removedStale() const {
  return impl_->removed;
}

namespace {
/// The pthread mutex of a port's ThreadSafePolicy: its only member is iox::posix::mutex, whose
/// only member is the native handle.
pthread_mutex_t& nativeLock(const iox::popo::ThreadSafePolicy& policy) {
  static_assert(sizeof(iox::popo::ThreadSafePolicy) == sizeof(pthread_mutex_t));
  return *reinterpret_cast<pthread_mutex_t*>(const_cast<iox::popo::ThreadSafePolicy*>(&policy));
}

std::string describePort(const char* what, const iox::popo::BasePortData& port) {
  return std::string(what) + " '" + port.m_serviceDescription.getInstanceIDString().c_str() +
         "' of " + port.m_runtimeName.c_str();
}
}  // namespace

std::vector<std::string> RouDiHost::releaseOrphanedPortLocks() {
  // RouDi's threads may create or destroy ports meanwhile. Port slots stay mapped, and a lock is
  // written only when its owner is dead, which no slot being built or torn down has.
  std::vector<std::string> released;
  auto pool = impl_->components->rouDiMemoryManager.portPool();
  if (!pool.has_value()) return released;
  for (auto* port : (*pool)->getPublisherPortDataList()) {
    const iox::popo::ThreadSafePolicy& lock = port->m_chunkSenderData;
    if (releaseIfOwnerDied(nativeLock(lock))) released.push_back(describePort("publisher", *port));
  }
  for (auto* port : (*pool)->getSubscriberPortDataList()) {
    const iox::popo::ThreadSafePolicy& lock = port->m_chunkReceiverData;
    if (releaseIfOwnerDied(nativeLock(lock))) {
      released.push_back(describePort("subscriber", *port));
    }
  }
  return released;
}

}  // namespace tessera

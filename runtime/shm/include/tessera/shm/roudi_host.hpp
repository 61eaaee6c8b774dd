// RouDiHost: the iceoryx daemon (RouDi) embedded in the process that owns a deployment (the
// launcher, a benchmark), so nobody starts one by hand. It lives exactly as long as this object.
//
// Start-up first checks for a RouDi already running on this machine (iceoryx 2.0 allows one per
// machine: its lock file is taken) and fails with a clear error if so; otherwise it removes the
// shared memory and sockets a crashed earlier run left behind and reports what it removed.
// Shared memory is readable and writable only by the current user: iceoryx creates its segments
// for the user's group, and start-up narrows them to the owner before any process opens them.
//
// Memory pools: iceoryx hands out fixed-size chunks from pools; memPoolsFor() sizes them from
// what the deployment declares: for each topic, its largest message and how many messages can
// be alive at once (subscriber queues, loans, readers still holding one).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace tessera {

struct MemPool {
  std::size_t chunk_bytes = 0;  // user payload bytes per chunk
  std::uint32_t count = 0;
};

/// One topic's demand: largest message (payload bytes) and messages alive at once.
struct ChunkDemand {
  std::size_t max_bytes = 0;
  std::uint32_t alive = 0;
};

/// Pools on a power-of-two ladder covering every demand; counts add up per size class, with
/// headroom, and large classes are capped so the total stays under `budget_bytes`. The whole
/// segment takes memory: iceoryx 2.0 zeroes it when RouDi starts (4 GiB took 6.7 s here).
std::vector<MemPool> memPoolsFor(const std::vector<ChunkDemand>& demands,
                                 std::size_t budget_bytes = std::size_t{1} << 30);

struct RouDiHostOptions {
  std::vector<MemPool> pools;
  /// Free the ports of processes that died without deregistering, within about 1.5 s of their
  /// death. A process that still exists is alive, even when stopped (SIGSTOP, a debugger).
  bool monitor_processes = true;
  /// Print iceoryx's own log at this level and above: "off", "error", "warn", "info".
  std::string log_level = "error";
};

class RouDiHost {
 public:
  explicit RouDiHost(RouDiHostOptions options);
  ~RouDiHost();
  RouDiHost(const RouDiHost&) = delete;
  RouDiHost& operator=(const RouDiHost&) = delete;

  /// Largest chunk payload in the pools.
  std::size_t maxChunkBytes() const;
  /// Files of an earlier crashed run that start-up removed (empty when there were none).
  const std::vector<std::string>& removedStale() const;
  /// Hands back the publisher and subscriber port locks that threads of a dead process still
  /// hold (see orphaned_lock.hpp), so RouDi's clean-up of it and its peers do not block for
  /// ever. Call after reaping a process that did not exit cleanly; returns the ports, e.g.
  /// "publisher 'scan' of tessera_robot_0".
  std::vector<std::string> releaseOrphanedPortLocks();

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

/// True when some RouDi runs on this machine (it holds iceoryx's lock file).
bool rouDiRunning();
/// What a crashed run left behind, without touching it: iceoryx's segments, /tmp/roudi and
/// Tessera's sockets (tmp_dir/tessera_*) while no RouDi runs, and launcher control blocks
/// (shm_dir/tessera_sync_<pid>) whose process is gone. Paths as found.
std::vector<std::string> findStaleShm(const std::filesystem::path& shm_dir = "/dev/shm",
                                      const std::filesystem::path& tmp_dir = "/tmp");
/// Removes what findStaleShm() lists and returns the paths removed. Throws std::runtime_error
/// when a RouDi is running.
std::vector<std::string> removeStaleShm();
/// Sets iceoryx's log level in this process ("off", "error", "warn", "info", "debug").
void setIceoryxLogLevel(const std::string& level);

}  // namespace tessera
